"""Traffic conflicts between pairs of vehicles, with SSAM's surrogate safety measures: pure
numpy, no I/O.

FHWA's Surrogate Safety Assessment Model (SSAM; user manual FHWA-HRT-08-050 and final report
FHWA-HRT-08-051, 2008) finds, in vehicle trajectories, *conflicts*: two vehicles on a collision
course (time to collision at most ``max_ttc_s``, 1.5 s by default) whose post-encroachment time
is at most ``max_pet_s`` (5 s). This module does the same on the site frame (x east, y north,
metres) and writes SSAM's conflict table (:data:`SSAM_COLUMNS`, :func:`ssam_csv`).

Method
------
*Candidates.* Points are grouped by capture time (a *step*: every point of one tracker cycle or
truth frame). Per step, only pairs nearer than ``search_radius_m`` are examined: the points are
hashed to a grid of that cell size and each is joined with the points of its own and the eight
neighbouring cells (sort and ``searchsorted``), so the work grows with the pairs near each other,
not with the square of the vehicles.

*Time to collision.* Each vehicle is an oriented rectangle (``length_m`` along ``heading_rad``,
``width_m`` across; a car's 4.5 m x 1.8 m where unknown) moving at its constant velocity
``(vx, vy)`` without turning. By the separating axis theorem two rectangles overlap exactly when
their projections overlap on all four axes (each rectangle's two sides); on an axis ``a`` the
gap closes linearly, so the overlap is the interval of ``t`` with

.. math:: |d_a + w_a t| \\le r_a, \\quad d_a = (c_2 - c_1) \\cdot a, \\;
          w_a = (v_2 - v_1) \\cdot a, \\; r_a = \\sum_k \\tfrac{L_k}{2} |u_k \\cdot a|
          + \\tfrac{W_k}{2} |n_k \\cdot a|

and the rectangles first touch at the latest entry over the axes, if it comes before the
earliest exit and the exit is not past: ``TTC = max(entry, 0)`` (0 when they overlap now),
infinite otherwise. This is exact for rectangles at constant velocity and heading. Two cars in
one lane 15 m apart bumper to bumper, closing at 10 m/s, have ``TTC = 1.5 s``.

*Events.* A pair's steps with ``TTC <= max_ttc_s`` form one event while they follow each other
within ``event_gap_s``. Per event:

- ``DRAC`` (not an SSAM column; in the JSON): the largest deceleration rate to avoid the crash,
  ``|v_2 - v_1| / (2 TTC)`` over the event (the relative motion stopped within the distance
  left; for two cars in line, ``dv^2 / (2 gap)``).
- *Conflict point* of a step: where the two paths cross (the intersection of the lines along
  the two headings) when the headings differ by ``rear_end_angle_deg`` or more; otherwise the
  leader's rear at the predicted collision (as SUMO's SSM device does for a following pair).
- *PET* at that point: along each vehicle's recorded trajectory, the times its front reaches
  the point and its rear leaves it (linear interpolation between points; the point must pass
  within half a width plus ``lateral_margin_m`` of the centreline). The *first* vehicle is the
  one that leaves first; ``PET = t_enter(second) - t_leave(first)``, 0 if they overlap there.
  PET is None where a trajectory in the data ends before it passes the point.
- A pair that overlaps already at the first step the two are examined together, or that
  overlaps while the two move alike (velocities within ``twin_speed_difference_mps``), is one
  vehicle tracked twice (a semitrailer's trailer split from its cab), not two: it has no
  events (``drop_twins``). Two real vehicles come together from apart, and a crash closes at
  speed.
- An event is a conflict when its minimum TTC is at most ``max_ttc_s`` and its minimum PET at
  most ``max_pet_s`` (or unknown). ``tMinTTC`` and ``xMinPET``/``yMinPET`` are the time of the
  minimum TTC and the conflict point of the minimum PET.

SSAM's measures, as its manual defines them: ``MaxS`` the highest speed of either vehicle over
the event; ``DeltaS`` ``|v_1 - v_2|`` at ``tMinTTC`` (vectors); ``DR`` the second vehicle's
first negative acceleration over the event (its lowest if it never brakes); ``MaxD`` its lowest
acceleration (negative: braking); ``MaxDeltaV`` the larger velocity change of the two in a
hypothetical perfectly inelastic collision at ``tMinTTC``, masses in proportion to ``L W``
(``PostCrashV``/``PostCrashHeading`` the common velocity after it). Headings (``FirstHeading``,
``SecondHeading``, degrees counter-clockwise from +x in [0, 360)) are those of the displacement
from the conflict start point (``CSP``: centre at the event's first step) to its end point
(``CEP``: at its last step), or ``heading_rad`` when a vehicle did not move; the conflict angle
is ``SecondHeading - FirstHeading`` in (-180, 180], the clock angle ``6 - angle / 30`` hours
(``h:mm``). Type by angle: ``rear end`` below ``rear_end_angle_deg`` (30), ``crossing`` above
``crossing_angle_deg`` (85), ``lane change`` in between; with ``use_lanes`` and a known lane of
both vehicles at the start and end, SSAM's lane rules come first (same lane, neither changed:
rear end; one changed lane into or out of the other's: lane change).
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, ConfigDict

#: SSAM's conflict table, its columns in order: ``Conflict::MEASURE_LABEL`` of the open-source
#: SSAM 3 (``Conflict.cpp``, (c) 2016-2017 New Global Systems for Intelligent Transportation
#: Management Corp., AGPL-3.0, released by FHWA), the table of the SSAM user manual
#: (FHWA-HRT-08-050, "Conflicts" tab) with SSAM 3's additions. Values written here where tracks
#: cannot give SSAM's:
#: ``trjFile`` the trajectories' source (the site and window, or ``truth``/``tracks``);
#: ``zMinPET`` 0 (a plane); ``FirstLink``/``SecondLink`` 1 (the site's road is one link) when
#: lanes were used and both are known, else 0 (SSAM's "no link": type by angle alone); ``FirstLane``/``SecondLane``
#: the lane index at ``tMinTTC`` (0: the rightmost; -1: between lanes); ``P(UEA)``, ``mTTC``,
#: ``mPET`` (SSAM 3's optional evasive-action model) empty.
SSAM_COLUMNS: tuple[str, ...] = (
    "trjFile",
    "tMinTTC",
    "xMinPET",
    "yMinPET",
    "zMinPET",
    "TTC",
    "PET",
    "MaxS",
    "DeltaS",
    "DR",
    "MaxD",
    "MaxDeltaV",
    "ConflictAngle",
    "ClockAngle",
    "ConflictType",
    "PostCrashV",
    "PostCrashHeading",
    "FirstVID",
    "FirstLink",
    "FirstLane",
    "FirstLength",
    "FirstWidth",
    "FirstHeading",
    "FirstVMinTTC",
    "FirstDeltaV",
    "xFirstCSP",
    "yFirstCSP",
    "xFirstCEP",
    "yFirstCEP",
    "SecondVID",
    "SecondLink",
    "SecondLane",
    "SecondLength",
    "SecondWidth",
    "SecondHeading",
    "SecondVMinTTC",
    "SecondDeltaV",
    "xSecondCSP",
    "ySecondCSP",
    "xSecondCEP",
    "ySecondCEP",
    "P(UEA)",
    "mTTC",
    "mPET",
)

ConflictType = Literal["rear end", "lane change", "crossing"]
CONFLICT_TYPES: tuple[ConflictType, ...] = ("rear end", "lane change", "crossing")

#: A passenger car, for a vehicle whose size is unknown [m].
DEFAULT_LENGTH_M = 4.5
DEFAULT_WIDTH_M = 1.8

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
#: Values that may be missing: an array (NaN) or a sequence (None).
MaybeFloats = npt.ArrayLike | Sequence[float | None]


@dataclass(frozen=True)
class ConflictSettings:
    """SSAM's thresholds (defaults: its own) and this module's search parameters."""

    max_ttc_s: float = 1.5
    max_pet_s: float = 5.0
    rear_end_angle_deg: float = 30.0
    crossing_angle_deg: float = 85.0
    #: Pairs farther apart than this at a step are not examined [m]: 1.5 s at a 40 m/s closing
    #: speed, plus two truck lengths.
    search_radius_m: float = 90.0
    #: Steps of one pair further apart than this are separate events [s].
    event_gap_s: float = 1.0
    #: A conflict point this far beyond half a vehicle's width is off its path [m].
    lateral_margin_m: float = 0.5
    use_lanes: bool = True
    #: Leave out pairs that are one vehicle tracked twice (:func:`_seen_twice`): they overlap
    #: from the first step they are seen together, or overlap while their velocities differ
    #: by less than ``twin_speed_difference_mps``. False keeps them (a truth replay has none).
    drop_twins: bool = True
    #: Overlapping at a closing speed below this is a split track, not a crash [m/s].
    twin_speed_difference_mps: float = 2.0
    default_length_m: float = DEFAULT_LENGTH_M
    default_width_m: float = DEFAULT_WIDTH_M


@dataclass(frozen=True)
class Trajectories:
    """Time-stamped states of vehicles (or tracks), arrays of one length N, any order.

    ``length_m``/``width_m`` NaN where unknown; ``lane_index`` -1 where unknown or between
    lanes; ``accel_mps2`` NaN to have it from the speeds (finite differences per vehicle).
    """

    vehicle_id: Sequence[str]
    stamp_s: FloatArray
    x_m: FloatArray
    y_m: FloatArray
    vx_mps: FloatArray
    vy_mps: FloatArray
    heading_rad: FloatArray
    length_m: FloatArray
    width_m: FloatArray
    lane_index: IntArray
    accel_mps2: FloatArray

    def __post_init__(self) -> None:
        n = len(self.vehicle_id)
        for name in ("stamp_s", "x_m", "y_m", "vx_mps", "vy_mps", "heading_rad"):
            if np.shape(getattr(self, name)) != (n,):
                raise ValueError(f"{name}: need {n} values, one per vehicle id")


class Conflict(BaseModel):
    """One conflict between two vehicles (module docstring): SSAM's measures, units in names."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    first_id: str
    second_id: str
    conflict_type: ConflictType
    start_stamp: float
    end_stamp: float
    ttc_s: float
    min_ttc_stamp: float
    pet_s: float | None
    min_pet_stamp: float | None  # when the second vehicle reached the point of the minimum PET
    min_pet_x_m: float
    min_pet_y_m: float
    drac_mps2: float | None  # None: they touched at every step
    max_speed_mps: float
    delta_speed_mps: float
    dr_mps2: float
    max_d_mps2: float
    max_delta_v_mps: float
    conflict_angle_deg: float
    clock_angle: str
    post_crash_speed_mps: float
    post_crash_heading_deg: float
    first_lane: int
    second_lane: int
    first_length_m: float
    first_width_m: float
    second_length_m: float
    second_width_m: float
    first_heading_deg: float
    second_heading_deg: float
    first_speed_mps: float  # at tMinTTC
    second_speed_mps: float
    first_delta_v_mps: float
    second_delta_v_mps: float
    first_start_x_m: float
    first_start_y_m: float
    first_end_x_m: float
    first_end_y_m: float
    second_start_x_m: float
    second_start_y_m: float
    second_end_x_m: float
    second_end_y_m: float


def trajectories(
    vehicle_id: Sequence[str],
    stamp_s: npt.ArrayLike,
    x_m: npt.ArrayLike,
    y_m: npt.ArrayLike,
    vx_mps: npt.ArrayLike,
    vy_mps: npt.ArrayLike,
    heading_rad: npt.ArrayLike,
    length_m: MaybeFloats | None = None,
    width_m: MaybeFloats | None = None,
    lane_index: npt.ArrayLike | None = None,
    accel_mps2: MaybeFloats | None = None,
) -> Trajectories:
    """:class:`Trajectories` from columns, None (or a None value) for what is unknown."""
    n = len(vehicle_id)

    def floats(values: MaybeFloats | None) -> FloatArray:
        if values is None:
            return np.full(n, np.nan)
        return np.array(
            [np.nan if v is None else v for v in np.asarray(values, dtype=object)], float
        )

    return Trajectories(
        vehicle_id=[str(v) for v in vehicle_id],
        stamp_s=np.asarray(stamp_s, dtype=np.float64),
        x_m=np.asarray(x_m, dtype=np.float64),
        y_m=np.asarray(y_m, dtype=np.float64),
        vx_mps=np.asarray(vx_mps, dtype=np.float64),
        vy_mps=np.asarray(vy_mps, dtype=np.float64),
        heading_rad=np.asarray(heading_rad, dtype=np.float64),
        length_m=floats(length_m),
        width_m=floats(width_m),
        lane_index=np.full(n, -1, np.int64)
        if lane_index is None
        else np.asarray(lane_index, dtype=np.int64),
        accel_mps2=floats(accel_mps2),
    )


# --- time to collision ----------------------------------------------------------------------


def time_to_collision(first: tuple[FloatArray, ...], second: tuple[FloatArray, ...]) -> FloatArray:
    """TTC [s] of pairs of oriented rectangles at constant velocity (separating axes).

    Parameters
    ----------
    first, second
        ``(x_m, y_m, vx_mps, vy_mps, heading_rad, length_m, width_m)``, arrays of shape (M,).

    Returns
    -------
    (M,) the time until the rectangles first touch; 0 if they overlap now; ``inf`` if never.
    """
    x1, y1, vx1, vy1, h1, l1, w1 = first
    x2, y2, vx2, vy2, h2, l2, w2 = second
    sides = [(np.cos(h1), np.sin(h1)), (np.cos(h2), np.sin(h2))]
    axes = [(c, s) for c, s in sides] + [(-s, c) for c, s in sides]
    entry = np.full(np.shape(x1), -np.inf)
    leave = np.full(np.shape(x1), np.inf)
    for ax, ay in axes:
        reach = np.zeros(np.shape(x1))
        for (cos_h, sin_h), length, width in zip(sides, (l1, l2), (w1, w2), strict=True):
            along = np.abs(cos_h * ax + sin_h * ay)
            across = np.abs(-sin_h * ax + cos_h * ay)
            reach = reach + 0.5 * length * along + 0.5 * width * across
        gap = (x2 - x1) * ax + (y2 - y1) * ay
        closing = (vx2 - vx1) * ax + (vy2 - vy1) * ay
        still = np.abs(closing) < 1e-9
        with np.errstate(divide="ignore", invalid="ignore"):
            t_a = (-reach - gap) / closing
            t_b = (reach - gap) / closing
        inside = np.abs(gap) <= reach
        low = np.where(still, np.where(inside, -np.inf, np.inf), np.minimum(t_a, t_b))
        high = np.where(still, np.where(inside, np.inf, -np.inf), np.maximum(t_a, t_b))
        entry = np.maximum(entry, low)
        leave = np.minimum(leave, high)
    hit = (entry <= leave) & (leave >= 0.0)
    return np.where(hit, np.maximum(entry, 0.0), np.inf)


# --- candidate pairs ------------------------------------------------------------------------

_CELL_SPAN = 1 << 21  # cells per axis in a key (an x or y of +-94,000 km at 90 m)


def near_pairs(
    step: IntArray, x_m: FloatArray, y_m: FloatArray, vehicle: IntArray, radius_m: float
) -> tuple[IntArray, IntArray]:
    """Index pairs ``(i, j)`` of points of one step within ``radius_m``, ``vehicle[i] <
    vehicle[j]``, each pair once: a grid of ``radius_m`` cells, each point joined with its own
    and the eight neighbouring cells (no loop over points)."""
    cx = np.floor(x_m / radius_m).astype(np.int64) + _CELL_SPAN // 2
    cy = np.floor(y_m / radius_m).astype(np.int64) + _CELL_SPAN // 2
    key = (step * _CELL_SPAN + cx) * _CELL_SPAN + cy
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    found_i: list[IntArray] = []
    found_j: list[IntArray] = []
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            target = key + dx * _CELL_SPAN + dy
            low = np.searchsorted(sorted_key, target, side="left")
            count = np.searchsorted(sorted_key, target, side="right") - low
            total = int(count.sum())
            if total == 0:
                continue
            i = np.repeat(np.arange(len(key)), count)
            within = np.arange(total) - np.repeat(np.cumsum(count) - count, count)
            j = order[np.repeat(low, count) + within]
            keep = vehicle[i] < vehicle[j]
            found_i.append(i[keep])
            found_j.append(j[keep])
    if not found_i:
        empty = np.zeros(0, np.int64)
        return empty, empty
    i, j = np.concatenate(found_i), np.concatenate(found_j)
    near = np.hypot(x_m[i] - x_m[j], y_m[i] - y_m[j]) <= radius_m
    return i[near], j[near]


# --- the pass over the trajectories ---------------------------------------------------------


@dataclass(frozen=True)
class _Sorted:
    """The trajectories sorted by vehicle then time, sizes and accelerations filled in."""

    names: list[str]
    vehicle: IntArray
    stamp: FloatArray
    x: FloatArray
    y: FloatArray
    vx: FloatArray
    vy: FloatArray
    heading: FloatArray
    length: FloatArray
    width: FloatArray
    lane: IntArray
    accel: FloatArray
    bounds: IntArray  # vehicle k's points: bounds[k]:bounds[k + 1]

    def state(self, rows: IntArray | int) -> tuple[FloatArray, ...]:
        return (
            self.x[rows],
            self.y[rows],
            self.vx[rows],
            self.vy[rows],
            self.heading[rows],
            self.length[rows],
            self.width[rows],
        )

    def points_of(self, k: int) -> slice:
        return slice(int(self.bounds[k]), int(self.bounds[k + 1]))


def _sorted(data: Trajectories, settings: ConflictSettings) -> _Sorted:
    names, vehicle = np.unique(np.asarray(data.vehicle_id, dtype=str), return_inverse=True)
    order = np.lexsort((data.stamp_s, vehicle))
    vehicle = vehicle[order].astype(np.int64)
    stamp = data.stamp_s[order]
    speed = np.hypot(data.vx_mps[order], data.vy_mps[order])
    accel = np.asarray(data.accel_mps2, dtype=np.float64)[order]
    bounds = np.searchsorted(vehicle, np.arange(len(names) + 1)).astype(np.int64)
    # finite differences per vehicle where no acceleration was given
    slope = np.full(len(stamp), np.nan)
    if len(stamp) > 1:
        same = vehicle[1:] == vehicle[:-1]
        with np.errstate(divide="ignore", invalid="ignore"):
            forward = np.where(same, np.diff(speed) / np.diff(stamp), np.nan)
        ahead = np.append(forward, np.nan)  # (v[i+1] - v[i]) / dt, within the vehicle
        behind = np.insert(forward, 0, np.nan)  # (v[i] - v[i-1]) / dt
        slope = np.where(
            np.isnan(ahead), behind, np.where(np.isnan(behind), ahead, 0.5 * (ahead + behind))
        )
    accel = np.where(np.isfinite(accel), accel, np.nan_to_num(slope, nan=0.0))
    length = data.length_m[order]
    width = data.width_m[order]
    return _Sorted(
        names=[str(n) for n in names],
        vehicle=vehicle,
        stamp=stamp,
        x=data.x_m[order],
        y=data.y_m[order],
        vx=data.vx_mps[order],
        vy=data.vy_mps[order],
        heading=data.heading_rad[order],
        length=np.where(np.isfinite(length) & (length > 0), length, settings.default_length_m),
        width=np.where(np.isfinite(width) & (width > 0), width, settings.default_width_m),
        lane=data.lane_index[order],
        accel=accel,
        bounds=bounds,
    )


def find_conflicts(data: Trajectories, settings: ConflictSettings | None = None) -> list[Conflict]:
    """Every conflict in the trajectories (module docstring), ordered by ``tMinTTC``."""
    settings = settings or ConflictSettings()
    if len(data.vehicle_id) == 0:
        return []
    s = _sorted(data, settings)
    _, step = np.unique(np.round(s.stamp, 6), return_inverse=True)
    i, j = near_pairs(step.astype(np.int64), s.x, s.y, s.vehicle, settings.search_radius_m)
    if len(i) == 0:  # one vehicle, or none ever near another
        return []
    ttc = time_to_collision(s.state(i), s.state(j))
    close = ttc <= settings.max_ttc_s
    pair = s.vehicle[i] * len(s.names) + s.vehicle[j]
    if settings.drop_twins:
        dv = np.hypot(s.vx[j] - s.vx[i], s.vy[j] - s.vy[i])
        twin = (ttc <= 0.0) & (dv < settings.twin_speed_difference_mps)
        close &= ~_seen_twice(pair, s.stamp[i], ttc, twin)
    i, j, ttc, pair = i[close], j[close], ttc[close], pair[close]
    order = np.lexsort((s.stamp[i], pair))
    i, j, ttc, pair = i[order], j[order], ttc[order], pair[order]
    if len(i) == 0:
        return []
    t = s.stamp[i]
    new_event = np.ones(len(i), dtype=bool)
    new_event[1:] = (pair[1:] != pair[:-1]) | (np.diff(t) > settings.event_gap_s)
    starts = np.flatnonzero(new_event)
    ends = np.append(starts[1:], len(i))
    found = []
    for a, b in zip(starts, ends, strict=True):
        conflict = _event(s, i[a:b], j[a:b], ttc[a:b], settings)
        if conflict is not None:
            found.append(conflict)
    found.sort(key=lambda c: (c.min_ttc_stamp, c.first_id, c.second_id))
    return found


def _seen_twice(
    pair: IntArray, stamp: FloatArray, ttc: FloatArray, twin: npt.NDArray[np.bool_]
) -> npt.NDArray[np.bool_]:
    """Which examined points belong to a pair that is one vehicle tracked twice (a
    semitrailer's trailer split from its cab): two vehicles cannot fill the same road, so a
    pair that already overlaps (``TTC`` 0) at the first step the two are examined together,
    or that ever overlaps while moving alike (``twin``: a crash closes at speed), is one."""
    order = np.lexsort((stamp, pair))
    first = order[np.r_[True, pair[order][1:] != pair[order][:-1]]]
    ones = np.union1d(pair[first][ttc[first] <= 0.0], pair[twin])
    twice: npt.NDArray[np.bool_] = np.isin(pair, ones)
    return twice


# --- one event ------------------------------------------------------------------------------


def _unit(heading: float) -> tuple[float, float]:
    return math.cos(heading), math.sin(heading)


def _conflict_point(
    s: _Sorted, p: int, q: int, ttc: float, settings: ConflictSettings
) -> tuple[float, float]:
    """Where the paths of the vehicles at rows ``p`` and ``q`` meet (module docstring)."""
    up, uq = _unit(float(s.heading[p])), _unit(float(s.heading[q]))
    cross = up[0] * uq[1] - up[1] * uq[0]
    if abs(cross) >= math.sin(math.radians(settings.rear_end_angle_deg)):
        dx, dy = float(s.x[q] - s.x[p]), float(s.y[q] - s.y[p])
        along_p = (dx * uq[1] - dy * uq[0]) / cross
        return float(s.x[p]) + along_p * up[0], float(s.y[p]) + along_p * up[1]
    # in line: the leader is the one ahead along the follower's heading
    ahead = (s.x[q] - s.x[p]) * up[0] + (s.y[q] - s.y[p]) * up[1] > 0.0
    lead = q if ahead else p
    u = uq if ahead else up
    half = 0.5 * float(s.length[lead])
    return (
        float(s.x[lead] + s.vx[lead] * ttc) - half * u[0],
        float(s.y[lead] + s.vy[lead] * ttc) - half * u[1],
    )


def _passage(
    s: _Sorted, k: int, px: float, py: float, settings: ConflictSettings
) -> tuple[float, float]:
    """When vehicle ``k``'s front reaches ``(px, py)`` and its rear leaves it [s] (NaN: not in
    its recorded trajectory, or the point is off its path)."""
    rows = s.points_of(k)
    dx, dy = px - s.x[rows], py - s.y[rows]
    cos_h, sin_h = np.cos(s.heading[rows]), np.sin(s.heading[rows])
    along = dx * cos_h + dy * sin_h  # the point ahead of the centre [m]
    across = np.abs(-dx * sin_h + dy * cos_h)
    half_length = 0.5 * s.length[rows]
    on_path = across <= 0.5 * s.width[rows] + settings.lateral_margin_m
    stamp = s.stamp[rows]

    def crossing(level: FloatArray) -> float:
        over = along - level  # > 0 until the level passes the point
        down = np.flatnonzero((over[:-1] > 0.0) & (over[1:] <= 0.0) & on_path[1:])
        if len(down) == 0:
            return math.nan
        n = int(down[0])
        share = over[n] / (over[n] - over[n + 1])
        return float(stamp[n] + share * (stamp[n + 1] - stamp[n]))

    return crossing(half_length), crossing(-half_length)


def _pet(
    s: _Sorted, a: int, b: int, px: float, py: float, settings: ConflictSettings
) -> tuple[float | None, bool, float | None]:
    """``(PET, a is first, when the second arrived)`` at the point, vehicles ``a`` and ``b``."""
    enter_a, leave_a = _passage(s, a, px, py, settings)
    enter_b, leave_b = _passage(s, b, px, py, settings)
    if math.isnan(leave_a) and math.isnan(leave_b):
        return None, True, None
    a_first = math.isnan(leave_b) or (not math.isnan(leave_a) and leave_a <= leave_b)
    arrive = enter_b if a_first else enter_a
    leave = leave_a if a_first else leave_b
    if math.isnan(arrive):
        return None, a_first, None
    return max(arrive - leave, 0.0), a_first, arrive


def _angle_type(angle_deg: float, settings: ConflictSettings) -> ConflictType:
    if abs(angle_deg) < settings.rear_end_angle_deg:
        return "rear end"
    if abs(angle_deg) > settings.crossing_angle_deg:
        return "crossing"
    return "lane change"


def classify(
    angle_deg: float,
    lanes: tuple[int, int, int, int] | None,
    settings: ConflictSettings,
) -> ConflictType:
    """SSAM's type: by lanes ``(first start, second start, first end, second end)`` where all
    four are known and ``use_lanes``, else by the conflict angle [deg]."""
    if lanes is None or not settings.use_lanes or min(lanes) < 0:
        return _angle_type(angle_deg, settings)
    first0, second0, first1, second1 = lanes
    changed = first0 != first1 or second0 != second1
    if first0 == second0:
        if not changed:
            return "rear end"
        return "lane change"
    if first1 == second1 and changed:
        return "lane change"
    return _angle_type(angle_deg, settings)


def _heading_deg(dx: float, dy: float, fallback_rad: float) -> float:
    angle = math.atan2(dy, dx) if math.hypot(dx, dy) > 1e-6 else fallback_rad
    return math.degrees(angle) % 360.0


def clock_angle(angle_deg: float) -> str:
    """SSAM's clock angle ``h:mm`` of a conflict angle: ``6 - angle / 30`` hours, 1 to 12."""
    hours = 6.0 - angle_deg / 30.0
    if hours < 1.0:
        hours += 12.0
    whole = math.floor(hours)
    minutes = min(round(60.0 * (hours - whole)), 59)
    return f"{whole}:{minutes:02d}"


def _event(
    s: _Sorted, rows_i: IntArray, rows_j: IntArray, ttc: FloatArray, settings: ConflictSettings
) -> Conflict | None:
    a, b = int(s.vehicle[rows_i[0]]), int(s.vehicle[rows_j[0]])
    best_pet: float | None = None
    best: tuple[float, float, float | None] = (math.nan, math.nan, None)
    votes = 0
    for p, q, time_s in zip(rows_i, rows_j, ttc, strict=True):
        px, py = _conflict_point(s, int(p), int(q), float(time_s), settings)
        pet, a_first, arrive = _pet(s, a, b, px, py, settings)
        votes += 1 if a_first else -1
        if pet is not None and (best_pet is None or pet < best_pet):
            best_pet, best = pet, (px, py, arrive)
        elif best_pet is None and math.isnan(best[0]):
            best = (px, py, None)
    if best_pet is not None and best_pet > settings.max_pet_s:
        return None
    k = int(np.argmin(ttc))
    rows = {a: rows_i, b: rows_j}
    first, second = (a, b) if votes >= 0 else (b, a)
    at_min = {a: int(rows_i[k]), b: int(rows_j[k])}
    start_s, end_s = float(s.stamp[rows_i[0]]), float(s.stamp[rows_i[-1]])

    def over_event(v: int) -> slice:
        span = s.points_of(v)
        stamp = s.stamp[span]
        low = span.start + int(np.searchsorted(stamp, start_s - 1e-9, side="left"))
        high = span.start + int(np.searchsorted(stamp, end_s + 1e-9, side="right"))
        return slice(low, high)

    max_speed = max(
        float(np.max(np.hypot(s.vx[over_event(v)], s.vy[over_event(v)]))) for v in (a, b)
    )
    accel = s.accel[over_event(second)]
    braking = np.flatnonzero(accel < 0.0)
    dr = float(accel[braking[0]]) if len(braking) else float(np.min(accel))
    max_d = float(np.min(accel))
    rel_speed = np.hypot(s.vx[rows_j] - s.vx[rows_i], s.vy[rows_j] - s.vy[rows_i])
    moving = ttc > 0.0  # at TTC 0 they touch: no deceleration avoids it
    drac = float(np.max(rel_speed[moving] / (2.0 * ttc[moving]))) if moving.any() else None

    heading: dict[int, float] = {}
    velocity: dict[int, tuple[float, float]] = {}
    mass: dict[int, float] = {}
    for v in (a, b):
        r0, r1, rk = int(rows[v][0]), int(rows[v][-1]), at_min[v]
        heading[v] = _heading_deg(
            float(s.x[r1] - s.x[r0]), float(s.y[r1] - s.y[r0]), float(s.heading[rk])
        )
        speed = float(math.hypot(s.vx[rk], s.vy[rk]))
        u = _unit(math.radians(heading[v]))
        velocity[v] = (speed * u[0], speed * u[1])
        mass[v] = float(s.length[rk] * s.width[rk])
    total = mass[a] + mass[b]
    post = tuple((mass[a] * velocity[a][n] + mass[b] * velocity[b][n]) / total for n in range(2))
    delta_v = {v: math.hypot(post[0] - velocity[v][0], post[1] - velocity[v][1]) for v in (a, b)}
    angle = (heading[second] - heading[first] + 180.0) % 360.0 - 180.0
    if angle == -180.0:
        angle = 180.0
    lanes = (
        int(s.lane[rows[first][0]]),
        int(s.lane[rows[second][0]]),
        int(s.lane[rows[first][-1]]),
        int(s.lane[rows[second][-1]]),
    )

    def side(v: int, name: str) -> dict[str, float | int]:
        r0, r1, rk = int(rows[v][0]), int(rows[v][-1]), at_min[v]
        return {
            f"{name}_lane": int(s.lane[rk]),
            f"{name}_length_m": float(s.length[rk]),
            f"{name}_width_m": float(s.width[rk]),
            f"{name}_heading_deg": heading[v],
            f"{name}_speed_mps": float(math.hypot(s.vx[rk], s.vy[rk])),
            f"{name}_delta_v_mps": delta_v[v],
            f"{name}_start_x_m": float(s.x[r0]),
            f"{name}_start_y_m": float(s.y[r0]),
            f"{name}_end_x_m": float(s.x[r1]),
            f"{name}_end_y_m": float(s.y[r1]),
        }

    return Conflict(
        first_id=s.names[first],
        second_id=s.names[second],
        conflict_type=classify(angle, lanes, settings),
        start_stamp=start_s,
        end_stamp=end_s,
        ttc_s=float(ttc[k]),
        min_ttc_stamp=float(s.stamp[rows_i[k]]),
        pet_s=best_pet,
        min_pet_stamp=best[2],
        min_pet_x_m=best[0],
        min_pet_y_m=best[1],
        drac_mps2=drac,
        max_speed_mps=max_speed,
        delta_speed_mps=math.hypot(
            velocity[a][0] - velocity[b][0], velocity[a][1] - velocity[b][1]
        ),
        dr_mps2=dr,
        max_d_mps2=max_d,
        max_delta_v_mps=max(delta_v.values()),
        conflict_angle_deg=angle,
        clock_angle=clock_angle(angle),
        post_crash_speed_mps=math.hypot(*post),
        post_crash_heading_deg=math.degrees(math.atan2(post[1], post[0])) % 360.0,
        **side(first, "first"),
        **side(second, "second"),
    )


# --- SSAM's table ---------------------------------------------------------------------------


def _number(value: float | None, digits: int = 3) -> str:
    if value is None or not math.isfinite(value):
        return ""
    return f"{value:.{digits}f}"


#: A vehicle's SSAM columns after its id and link: the :class:`Conflict` field (less the
#: ``first_``/``second_`` prefix) and its decimals (None: an integer).
_SIDE_FIELDS: tuple[tuple[str, int | None], ...] = (
    ("lane", None),
    ("length_m", 2),
    ("width_m", 2),
    ("heading_deg", 1),
    ("speed_mps", 3),
    ("delta_v_mps", 3),
    ("start_x_m", 3),
    ("start_y_m", 3),
    ("end_x_m", 3),
    ("end_y_m", 3),
)


def ssam_row(conflict: Conflict, trj_file: str, *, lanes_used: bool = True) -> list[str]:
    """One conflict as a row of :data:`SSAM_COLUMNS` (their order)."""
    c = conflict
    link = "1" if lanes_used and min(c.first_lane, c.second_lane) >= 0 else "0"
    n = _number

    def side(prefix: str) -> list[str]:
        cells = []
        for name, digits in _SIDE_FIELDS:
            value = getattr(c, f"{prefix}_{name}")
            cells.append(str(value) if digits is None else n(value, digits))
        return [getattr(c, f"{prefix}_id"), link, *cells]

    return [
        trj_file,
        n(c.min_ttc_stamp),
        n(c.min_pet_x_m),
        n(c.min_pet_y_m),
        "0",
        n(c.ttc_s),
        n(c.pet_s),
        n(c.max_speed_mps),
        n(c.delta_speed_mps),
        n(c.dr_mps2),
        n(c.max_d_mps2),
        n(c.max_delta_v_mps),
        n(c.conflict_angle_deg, 1),
        c.clock_angle,
        c.conflict_type,
        n(c.post_crash_speed_mps),
        n(c.post_crash_heading_deg, 1),
        *side("first"),
        *side("second"),
        "",  # P(UEA), mTTC, mPET: SSAM 3's evasive-action model, not computed
        "",
        "",
    ]


def ssam_csv(conflicts: Sequence[Conflict], trj_file: str, *, lanes_used: bool = True) -> str:
    """SSAM's conflict table as CSV: a header of :data:`SSAM_COLUMNS`, a row per conflict
    (metres, seconds, m/s, degrees; an empty cell for a value there is none of)."""
    out = io.StringIO()
    writer = csv.writer(out)
    writer.writerow(SSAM_COLUMNS)
    for conflict in conflicts:
        writer.writerow(ssam_row(conflict, trj_file, lanes_used=lanes_used))
    return out.getvalue()


def count_by_type(conflicts: Sequence[Conflict]) -> dict[str, int]:
    """Conflicts per SSAM type (every type, zeros included)."""
    counts: dict[str, int] = dict.fromkeys(CONFLICT_TYPES, 0)
    for conflict in conflicts:
        counts[conflict.conflict_type] += 1
    return counts
