"""Scripted near misses with hand-computed TTC and PET, for the conflict tests (core and API).

Rear end (``rear_end``): a lead car at 10 m/s and a follower at 20 m/s, 15 m apart bumper to
bumper at t = 0 (TTC = 15 / 10 = 1.5 s, DRAC = 10^2 / (2 15) = 10/3 m/s^2); the follower brakes
at 5 m/s^2 until it is down to 10 m/s at t = 2 s, 5 m behind. With gap ``g = 15 - 10t +
2.5t^2`` and closing speed ``10 - 5t``, ``TTC(t) = (2 - t) / 2 + 1 / (2 - t)``: at most 1.5 s
for t in [0, 1], least ``sqrt(2)`` at ``t = 2 - sqrt(2)``; PET = 5 m / 10 m/s = 0.5 s.

Crossing (``crossing``): car A drives east along y = 0 at 10 m/s, its rear leaving the origin at
t = 2.0 s; car B drives north along x = 0, its front 15 m short of the origin at 10 m/s (on a
collision course: TTC 1.46 s at t = 0, when A's front reaches x = -0.9), brakes from t = 0.3 s
to t = 1.8 s and reaches the origin at t = 3.2 s: PET = 1.2 s.
"""

from __future__ import annotations

import math
from collections import defaultdict

import numpy as np

from tests.alert_service.helpers import batch
from wz_gateway.conflicts import Trajectories, trajectories
from wz_shared.messages import Track, TrackBatch

DT_S = 0.05
LENGTH_M = 4.5
WIDTH_M = 1.8
#: Crossing: B's speed after braking, so that its front reaches the origin at 3.2 s:
#: 15 m = 10 m/s * 0.3 s + (10 + v) / 2 * 1.5 s + v * 1.4 s.
CROSSING_SLOW_MPS = (15.0 - 3.0 - 7.5) / (0.75 + 1.4)


def times(duration_s: float) -> np.ndarray:
    return np.round(np.arange(round(duration_s / DT_S) + 1) * DT_S, 6)


def follower_state(t: float) -> tuple[float, float]:
    """The rear-end follower's centre x [m] and speed [m/s] at ``t``."""
    if t <= 2.0:
        return 20.0 * t - 2.5 * t * t, 20.0 - 5.0 * t
    return 30.0 + 10.0 * (t - 2.0), 10.0


def crossing_b_state(t: float) -> tuple[float, float]:
    """The crossing car B's front y [m] and speed [m/s] at ``t``."""
    v = CROSSING_SLOW_MPS
    if t <= 0.3:
        return -15.0 + 10.0 * t, 10.0
    if t <= 1.8:
        tau = t - 0.3
        decel = (10.0 - v) / 1.5
        return -12.0 + 10.0 * tau - 0.5 * decel * tau * tau, 10.0 - decel * tau
    return -12.0 + (10.0 + v) / 2.0 * 1.5 + v * (t - 1.8), v


Row = tuple[str, float, float, float, float, float, float, int]


def rear_end_rows(duration_s: float = 6.0, y_m: float = 0.0) -> list[Row]:
    """``(id, t, x, y, vx, vy, heading, lane)`` of the lead ("lead") and follower ("follow")."""
    rows: list[Row] = []
    for t in times(duration_s):
        rows.append(("lead", t, 19.5 + 10.0 * t, y_m, 10.0, 0.0, 0.0, 0))
        x, v = follower_state(t)
        rows.append(("follow", t, x, y_m, v, 0.0, 0.0, 0))
    return rows


def crossing_rows(duration_s: float = 6.0) -> list[Row]:
    """Cars "a" (east) and "b" (north), lanes unknown (-1)."""
    rows: list[Row] = []
    for t in times(duration_s):
        rows.append(("a", t, -17.75 + 10.0 * t, 0.0, 10.0, 0.0, 0.0, -1))
        front, v = crossing_b_state(t)
        rows.append(("b", t, 0.0, front - LENGTH_M / 2, 0.0, v, math.pi / 2, -1))
    return rows


def as_trajectories(rows: list[Row]) -> Trajectories:
    ids, t, x, y, vx, vy, heading, lane = zip(*rows, strict=True)
    return trajectories(
        list(ids),
        t,
        x,
        y,
        vx,
        vy,
        heading,
        length_m=[LENGTH_M] * len(rows),
        width_m=[WIDTH_M] * len(rows),
        lane_index=lane,
    )


def scene_track(
    track_id: int, x: float, y: float, vx: float, vy: float, heading: float, lane: int
) -> Track:
    """A scene's vehicle as a published track (station and offset: y and -x)."""
    return Track(
        track_id=track_id,
        x_m=x,
        y_m=y,
        vx_mps=vx,
        vy_mps=vy,
        covariance=[0.0] * 16,
        station_m=y,
        offset_m=-x,
        speed_mps=math.hypot(vx, vy),
        heading_rad=heading,
        lane_index=lane,
        age_s=1.0,
        hits=10,
        confirmed=True,
        sources=["lidar-mast"],
        length_m=LENGTH_M,
        width_m=WIDTH_M,
    )


#: The scenes' track ids on the bus (the API tests store them as track batches).
TRACK_IDS = {"lead": 1, "follow": 2, "a": 3, "b": 4}


def scene_batches() -> list[TrackBatch]:
    """The rear end (at y = 300 m) and the crossing as the tracker would publish them."""
    by_stamp: dict[float, list[Track]] = defaultdict(list)
    for name, t, x, y, vx, vy, heading, lane in rear_end_rows(y_m=300.0) + crossing_rows():
        by_stamp[float(t)].append(scene_track(TRACK_IDS[name], x, y, vx, vy, heading, lane))
    return [batch(t, tracks, k) for k, (t, tracks) in enumerate(sorted(by_stamp.items()))]
