"""Loop-detector style traffic counts from fused trajectories: pure numpy, no I/O.

The WZDx traffic sensor reports, per collection interval and lane, a volume, an average speed
and an occupancy, as an inductive loop would. Here the loop is virtual: a detection zone of
``zone_length_m`` at ``detector_station_m`` across the road. A track *crosses* it between two
consecutive points with ``s_k < s_0 <= s_{k+1}``; the crossing's time and speed are linear
interpolations between the two, its lane that of the point nearer ``s_0``. Each track crosses
once (its first crossing).

As a loop does, the lane counts *presences*, not tracks: the zone is occupied from a vehicle's
front reaching it, ``t - L / (2 v)``, to its rear leaving it, ``t + (L / 2 + L_zone) / v`` (``t``
the centre's crossing); a crossing whose front arrives while the zone is still occupied in its
lane is the same presence. A vehicle cannot overlap the one ahead, so two tracks that do are one
vehicle seen twice (a truck's trailer split from its cab); two vehicles following each other
never merge, however close, as long as their tracks keep them apart. Counting the truth the
same way leaves every vehicle counted.

Per lane, over an interval of ``T`` seconds with ``n`` crossings at speeds ``v_i`` by vehicles
of length ``L_i``:

.. math::

    q = 3600 \\, n / T  \\quad \\text{[veh/h]}, \\qquad
    \\bar v = \\frac{1}{n} \\sum v_i  \\quad \\text{(time-mean speed, as a loop reports)}

    o = \\frac{100}{T} \\sum \\frac{L_i + L_{zone}}{\\max(v_i, v_{min})}  \\quad \\text{[\\%]}

(a vehicle covers the zone for the time it takes to travel its own length plus the zone's; the
sum is over the presences' union, clipped to the interval), at most 100 %. Station-wide: the volumes add up, the speed is the mean over every crossing
and the occupancy is the mean of the lanes'.

A lane's count is only as good as the sensors' view of it: where other vehicles hid its loop
spot for more than :data:`HIDDEN_SHARE_LIMIT` of the interval (measured by
:mod:`wz_gateway.lane_sight`), its volume is marked unreliable.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

#: A standard 6 ft (1.83 m) inductive loop.
DEFAULT_ZONE_LENGTH_M = 1.83
#: Length assumed for a vehicle the tracker gave none [m]: a passenger car.
DEFAULT_VEHICLE_LENGTH_M = 4.5
#: Speeds below this count as this for occupancy [m/s]: a stopped vehicle on the loop holds
#: it for the rest of the interval, not forever.
MIN_OCCUPANCY_SPEED_MPS = 0.5
#: A lane's volume is unreliable when its loop spot was hidden from the sensors for more than
#: this share of the interval: about that share of its vehicles passed unseen, and the lane
#: volume's target is 5 % (:mod:`wz_gateway.lane_sight`).
HIDDEN_SHARE_LIMIT = 0.05


@dataclass(frozen=True)
class Crossings:
    """Tracks crossing the detection zone, arrays of one length N."""

    track_id: npt.NDArray[np.int64]
    stamp: npt.NDArray[np.float64]  # interpolated crossing time [s]
    lane_index: npt.NDArray[np.int64]
    speed_mps: npt.NDArray[np.float64]  # interpolated speed at the crossing [m/s]
    length_m: npt.NDArray[np.float64]  # vehicle length [m] (the default where unknown)


@dataclass(frozen=True)
class LaneTraffic:
    """One lane's counts over the interval."""

    lane_index: int
    vehicles: int
    volume_vph: float
    average_speed_mps: float | None  # None when no vehicle crossed
    occupancy_percent: float
    #: Share of the interval the lane's loop spot was hidden from every sensor (None: not
    #: measured).
    hidden_share: float | None = None

    @property
    def reliable(self) -> bool:
        """Whether the lane's volume can be trusted: hidden no longer than
        :data:`HIDDEN_SHARE_LIMIT` of the interval (or not measured)."""
        return self.hidden_share is None or self.hidden_share <= HIDDEN_SHARE_LIMIT


@dataclass(frozen=True)
class TrafficSummary:
    """Every lane's counts, and the station's, over ``[start_stamp, end_stamp]``."""

    start_stamp: float
    end_stamp: float
    detector_station_m: float
    lanes: list[LaneTraffic]
    vehicles: int
    volume_vph: float
    average_speed_mps: float | None
    occupancy_percent: float


def find_crossings(
    track_id: npt.ArrayLike,
    stamp: npt.ArrayLike,
    station_m: npt.ArrayLike,
    lane_index: npt.ArrayLike,
    speed_mps: npt.ArrayLike,
    length_m: npt.ArrayLike,
    detector_station_m: float,
) -> Crossings:
    """Where each track first crosses ``detector_station_m`` going downstream.

    Parameters
    ----------
    track_id, stamp, station_m, lane_index, speed_mps, length_m : array_like, shape (N,)
        Track points in any order; ``length_m`` NaN where unknown.
    detector_station_m : float
        Station of the detection zone [m].

    Returns
    -------
    Crossings
        One entry per crossing track, ordered by track id.
    """
    ids = np.asarray(track_id, dtype=np.int64)
    t = np.asarray(stamp, dtype=np.float64)
    s = np.asarray(station_m, dtype=np.float64)
    lane = np.asarray(lane_index, dtype=np.int64)
    v = np.asarray(speed_mps, dtype=np.float64)
    length = np.asarray(length_m, dtype=np.float64)
    order = np.lexsort((t, ids))
    ids, lane = ids[order], lane[order]
    t, s, v, length = t[order], s[order], v[order], length[order]
    # Consecutive points k, k+1 of one track that straddle the detector.
    k = np.flatnonzero(
        (ids[:-1] == ids[1:]) & (s[:-1] < detector_station_m) & (s[1:] >= detector_station_m)
    )
    # np.unique keeps the first index of each id: the track's first crossing (points by time).
    _, first = np.unique(ids[k], return_index=True)
    k = k[first]
    u = (detector_station_m - s[k]) / (s[k + 1] - s[k])  # in (0, 1]
    nearer = np.where(u < 0.5, k, k + 1)
    known = np.where(np.isnan(length[k + 1]), length[k], length[k + 1])
    return Crossings(
        track_id=ids[k],
        stamp=t[k] + u * (t[k + 1] - t[k]),
        lane_index=lane[nearer],
        speed_mps=v[k] + u * (v[k + 1] - v[k]),
        length_m=np.where(np.isnan(known), DEFAULT_VEHICLE_LENGTH_M, known),
    )


def summarize(
    crossings: Crossings,
    start_stamp: float,
    end_stamp: float,
    lane_indices: list[int],
    detector_station_m: float,
    zone_length_m: float = DEFAULT_ZONE_LENGTH_M,
    hidden_shares: Mapping[int, float] | None = None,
) -> TrafficSummary:
    """Volumes, speeds and occupancies per lane over ``[start_stamp, end_stamp]``.

    Crossings outside the interval or in a lane not in ``lane_indices`` (off the road, -1)
    are left out of the lanes; the station-wide figures are over the lanes' crossings.
    ``hidden_shares``: each lane's hidden share of the interval, by lane index
    (:func:`wz_gateway.lane_sight.lane_hidden_shares`), which marks its volume's reliability.

    Raises
    ------
    ValueError
        If the interval is empty (``end_stamp <= start_stamp``).
    """
    duration_s = end_stamp - start_stamp
    if not duration_s > 0.0:
        raise ValueError(f"empty collection interval [{start_stamp}, {end_stamp}]")
    inside = (crossings.stamp >= start_stamp) & (crossings.stamp <= end_stamp)
    lanes: list[LaneTraffic] = []
    speeds: list[npt.NDArray[np.float64]] = []
    for lane_index in lane_indices:
        mine = inside & (crossings.lane_index == lane_index)
        order = np.argsort(crossings.stamp[mine], kind="stable")
        t = crossings.stamp[mine][order]
        v = crossings.speed_mps[mine][order]
        length = crossings.length_m[mine][order]
        pace = np.maximum(v, MIN_OCCUPANCY_SPEED_MPS)
        first, occupied_s = presences(
            t - length / 2.0 / pace,
            t + (length / 2.0 + zone_length_m) / pace,
            start_stamp,
            end_stamp,
        )
        v = v[first]
        lanes.append(
            LaneTraffic(
                lane_index=lane_index,
                vehicles=int(v.size),
                volume_vph=3600.0 * v.size / duration_s,
                average_speed_mps=float(v.mean()) if v.size else None,
                occupancy_percent=min(100.0, 100.0 * occupied_s / duration_s),
                hidden_share=None if hidden_shares is None else hidden_shares.get(lane_index),
            )
        )
        speeds.append(v)
    every = np.concatenate(speeds) if speeds else np.zeros(0)
    return TrafficSummary(
        start_stamp=start_stamp,
        end_stamp=end_stamp,
        detector_station_m=detector_station_m,
        lanes=lanes,
        vehicles=int(every.size),
        volume_vph=sum(lane.volume_vph for lane in lanes),
        average_speed_mps=float(every.mean()) if every.size else None,
        occupancy_percent=(
            sum(lane.occupancy_percent for lane in lanes) / len(lanes) if lanes else 0.0
        ),
    )


def presences(
    on_s: npt.NDArray[np.float64],
    off_s: npt.NDArray[np.float64],
    start_stamp: float,
    end_stamp: float,
) -> tuple[npt.NDArray[np.bool_], float]:
    """Which of a lane's occupancy intervals ``[on, off]`` (ordered by crossing time) start a
    new presence, and how long the zone was occupied within ``[start_stamp, end_stamp]`` [s].

    An interval that begins while the zone is still occupied (``on <= off`` of what came
    before) continues that presence; the occupied time is the intervals' union.
    """
    first = np.zeros(on_s.size, dtype=bool)
    occupied_s = 0.0
    busy_from, busy_until = -np.inf, -np.inf
    for k in range(on_s.size):
        if on_s[k] > busy_until:  # vacant: a new vehicle
            first[k] = True
            if busy_until > busy_from:
                occupied_s += max(0.0, min(busy_until, end_stamp) - max(busy_from, start_stamp))
            busy_from, busy_until = on_s[k], off_s[k]
        else:
            busy_until = max(busy_until, off_s[k])
    if busy_until > busy_from:
        occupied_s += max(0.0, min(busy_until, end_stamp) - max(busy_from, start_stamp))
    return first, occupied_s
