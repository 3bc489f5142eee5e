"""The tracker's update step: its measurement models, their gates and the batched Kalman
update of the matched tracks (as Stone Soup separates a measurement model from its updater).

Two measurement models, each updated for every matched track of a batch at once:

- **Position** (every sensor): ``z = H x + v``, ``v ~ N(0, R)`` with the detection's own
  covariance. A measurement captured ``delta`` after its batch's stamp (a spinning LiDAR's
  column time) sees ``p + delta v``: ``H = [I  delta I]`` (:func:`position_matrices`);
  otherwise ``H = [I 0]``. The association's Huber widening of an outlier's ``R`` and the
  re-centring of a box seen from one end (:func:`reference_points`) come before it.
- **Radar speed along the road** (where a detection has one and the road's heading ``h`` is
  known at the updated track): ``z = s``, ``H = [0, 0, cos h, sin h]``,
  ``R = speed_std_mps^2``, gated by ``y^2 / S <= speed_gate_chi2`` (``y = s - H x``,
  ``S = H P H^T + R``): a radar speed paired with the wrong echo (the car in the next lane)
  would drag the velocity by metres per second in one update (:func:`update_speeds`).

:func:`update_matched` runs both and returns what it did (:class:`UpdateOutcome`); the
tracker adds that to its counters and does the bookkeeping (hits, class votes, history).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from wz_fusion_tracker.imm import IMMStateBank
from wz_fusion_tracker.kalman import TrackStateBank
from wz_fusion_tracker.settings import TrackerSettings
from wz_fusion_tracker.track_table import TrackTable
from wz_fusion_tracker.types import Measurement
from wz_shared.arrays import F64, IntP
from wz_shared.motion import STATE_DIM

#: The road's heading [rad] at each of some site positions (K, 2); NaN where there is no road.
RoadHeadings = Callable[[F64], F64]


@dataclass(frozen=True)
class UpdateOutcome:
    """What one batch's update did: tracks updated with a position, radar speeds taken and
    refused by the speed gate, and the road's heading at each updated track (NaN: no road;
    None: no road prior)."""

    updated: int
    speeds_used: int = 0
    speeds_rejected: int = 0
    road_heading_rad: F64 | None = field(default=None, compare=False)


def position_matrices(time_offset_s: F64) -> F64:
    """The position model's ``H = [I  delta I]`` for each capture offset ``delta`` (M,):
    shape (M, 2, 4)."""
    H = np.zeros((len(time_offset_s), 2, STATE_DIM))
    H[:, 0, 0] = H[:, 1, 1] = 1.0
    H[:, 0, 2] = H[:, 1, 3] = time_offset_s
    return H


def update_speeds(
    bank: TrackStateBank | IMMStateBank,
    settings: TrackerSettings,
    slots: IntP,
    road_heading_rad: F64,
    speeds_mps: F64,
) -> tuple[int, int]:
    """The radar-speed update of ``slots`` (K,) with ``speeds_mps`` (K,; NaN: none) along the
    road's heading there (NaN: no road): the speeds used and those the gate refused."""
    rows = np.flatnonzero(np.isfinite(speeds_mps) & np.isfinite(road_heading_rad))
    if not len(rows):
        return 0, 0
    h = road_heading_rad[rows]
    H = np.zeros((len(rows), 1, STATE_DIM))
    H[:, 0, 2], H[:, 0, 3] = np.cos(h), np.sin(h)
    measured = speeds_mps[rows][:, None]
    R = np.full((len(rows), 1, 1), settings.speed_std_mps**2)
    speed_slots = slots[rows]
    x, P = bank.states(speed_slots), bank.covariances(speed_slots)
    y = measured[:, 0] - np.einsum("mj,mj->m", H[:, 0, :], x)
    S = np.einsum("mi,mij,mj->m", H[:, 0, :], P, H[:, 0, :]) + R[:, 0, 0]
    keep = y * y <= settings.speed_gate_chi2 * S
    if keep.any():
        bank.update(speed_slots[keep], measured[keep], R[keep], H[keep])
    used = int(np.count_nonzero(keep))
    return used, len(rows) - used


def update_matched(
    bank: TrackStateBank | IMMStateBank,
    settings: TrackerSettings,
    slots: IntP,
    z: F64,
    R: F64,
    time_offset_s: F64 | None,
    road_headings: RoadHeadings | None,
    speeds_mps: F64,
) -> UpdateOutcome:
    """Update ``slots`` (K,), their priors already committed, with positions ``z`` (K, 2) and
    covariances ``R`` (K, 2, 2) captured ``time_offset_s`` (K,; None: at the stamp) after it;
    then, with the road's heading at each updated track (``road_headings`` of the updated
    positions; None: no road prior) and ``use_speed_measurements``, the radar speeds (K,; NaN:
    none)."""
    if time_offset_s is None:
        bank.update(slots, z, R)
    else:
        bank.update(slots, z, R, position_matrices(time_offset_s))
    if road_headings is None:
        return UpdateOutcome(updated=len(slots))
    road = road_headings(bank.states(slots)[:, :2])
    if not settings.use_speed_measurements:
        return UpdateOutcome(updated=len(slots), road_heading_rad=road)
    used, rejected = update_speeds(bank, settings, slots, road, speeds_mps)
    return UpdateOutcome(len(slots), used, rejected, road)


def reference_points(
    table: TrackTable,
    threshold_m: float,
    sensor_xy: tuple[float, float] | None,
    slots: IntP,
    rows: IntP,
    columns: IntP,
    z: F64,
    measurements: Sequence[Measurement],
) -> F64:
    """Matched positions re-centred with the track's length where a sensor saw one end.

    A LiDAR sees the face of a vehicle turned to it and completes the box away from the
    sensor with the length of the class it can tell (a semitrailer seen end-on at 130 m shows
    a car's height: completed as a 4.5 m car, its centre 6 m short). The track knows better:
    its length ``L_t`` (the upper quartile of the measured lengths, since a partial view only
    shortens) against the box's ``L_d`` moves the centre by ``(L_t - L_d) / 2`` along the
    track's direction, away from the sensor; towards it for a box completed from its far end
    (``Measurement.completed_from_far_end``: the near end cut by the field of view, the far
    face seen). Differences below ``threshold_m``
    (``reference_point_min_m``) are left alone (a car's own spread); ``sensor_xy`` None (the
    sensor's place unknown) or a threshold of 0 leaves every position.
    """
    if sensor_xy is None or threshold_m <= 0.0:
        return z
    measured = np.fromiter(
        [
            math.nan if (length := measurements[c].length_m) is None else length
            for c in columns.tolist()
        ],
        np.float64,
        len(columns),
    )
    matched_slots = slots[rows]
    difference = table.sizes(matched_slots)[:, 2] - measured  # NaN: either unknown
    heading = table.heading_rad[matched_slots]
    moved = (np.abs(difference) >= threshold_m) & np.isfinite(heading)  # False for NaN
    if not moved.any():
        return z
    axis = np.stack([np.cos(heading[moved]), np.sin(heading[moved])], axis=1)
    at = columns[moved]
    away = np.where(np.einsum("ki,ki->k", z[at] - np.asarray(sensor_xy), axis) >= 0.0, 1.0, -1.0)
    from_far_end = np.fromiter(
        (measurements[c].completed_from_far_end for c in at.tolist()), bool, len(at)
    )
    away = np.where(from_far_end, -away, away)
    z_used = z.copy()
    z_used[at] = z[at] + (0.5 * difference[moved] * away)[:, None] * axis
    return z_used
