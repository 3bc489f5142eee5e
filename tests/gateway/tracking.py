"""A car on the test site's straight road and a Kalman filter's estimates of it, for the
smoothing tests: what the fusion tracker would publish, with real covariances."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from filterpy.kalman import KalmanFilter

from tests.gateway.helpers import SITE
from wz_gateway.smoothing import cv_transitions, road_aligned_q
from wz_shared.messages import Track, TrackBatch

F64 = npt.NDArray[np.float64]


@dataclass(frozen=True)
class FilteredCar:
    """Truth and filtered states ``[x, y, vx, vy]`` (n, 4), covariances (n, 4, 4), stamps (n,)."""

    stamps_s: F64
    truth: F64
    x_filt: F64
    P_filt: F64


def filtered_car(*, seed: int, count: int = 200, period_s: float = 0.05, start_s: float = 0.0,
                 station0_m: float = 800.0, speed_mps: float = 25.0, offset_m: float = -1.83,
                 sigma_a_mps2: float = 1.0, sigma_across_mps2: float | None = None,
                 noise_m: float = 0.3) -> FilteredCar:  # fmt: skip
    """A car driving north (the site's road runs along ``y`` here: ``x = -offset``) with white
    acceleration ``sigma_a`` along the road (``sigma_across``, default the same, across it),
    measured every ``period_s`` with ``noise_m`` position noise and followed by a
    constant-velocity Kalman filter (filterpy) with the matching Q."""
    rng = np.random.default_rng(seed)
    stamps = start_s + period_s * np.arange(count, dtype=np.float64)
    F = cv_transitions(np.array([period_s]))[0]
    across = sigma_a_mps2 if sigma_across_mps2 is None else sigma_across_mps2
    Q = road_aligned_q(np.array([period_s]), np.array([np.pi / 2]), sigma_a_mps2, across)[0]
    truth = np.empty((count, 4))
    truth[0] = [-offset_m, station0_m, 0.0, speed_mps]
    for k in range(1, count):
        truth[k] = F @ truth[k - 1] + rng.multivariate_normal(np.zeros(4), Q)
    kf = KalmanFilter(dim_x=4, dim_z=2)
    kf.F, kf.Q = F, Q
    kf.H = np.eye(2, 4)
    kf.R = noise_m**2 * np.eye(2)
    kf.x = truth[0] + np.array([0.2, -0.3, 0.5, -1.0])
    kf.P = np.diag([1.0, 1.0, 4.0, 4.0])
    x_filt, P_filt = np.empty((count, 4)), np.empty((count, 4, 4))
    for k in range(count):
        if k:
            kf.predict()
        kf.update(truth[k, :2] + rng.normal(scale=noise_m, size=2))
        x_filt[k], P_filt[k] = kf.x, kf.P
    return FilteredCar(stamps, truth, x_filt, P_filt)


def car_tracks(track_id: int, car: FilteredCar) -> list[Track]:
    """The filtered states as the tracker's Track messages (road frame and lane included)."""
    station, offset = SITE.road_frame.to_road(car.x_filt[:, 0], car.x_filt[:, 1])
    lanes = SITE.lane_index_at(offset)
    return [
        Track(track_id=track_id, x_m=float(x[0]), y_m=float(x[1]), vx_mps=float(x[2]),
              vy_mps=float(x[3]), covariance=[float(v) for v in ((P + P.T) / 2).reshape(-1)],
              station_m=float(s), offset_m=float(d), speed_mps=float(np.hypot(x[2], x[3])),
              heading_rad=float(np.arctan2(x[3], x[2])), lane_index=max(int(lane), -1),
              age_s=0.05 * k, hits=k + 1, confirmed=True, sources=["lidar-mast"],
              length_m=4.5 if k > 10 else None, width_m=1.8 if k > 10 else None)
        for k, (x, P, s, d, lane) in enumerate(zip(car.x_filt, car.P_filt, station, offset, lanes,
                                                   strict=True))
    ]  # fmt: skip


def merged_batches(*cars: tuple[F64, list[Track]], first_cycle: int = 0) -> list[TrackBatch]:
    """One batch per distinct stamp, holding the track of every car seen at that stamp."""
    by_stamp: dict[float, list[Track]] = {}
    for stamps, tracks in cars:
        for stamp, track in zip(stamps, tracks, strict=True):
            by_stamp.setdefault(round(float(stamp), 9), []).append(track)
    return [TrackBatch(site=SITE.site_id, source_id="fusion-tracker", stamp=stamp,
                       cycle_index=first_cycle + k, tracks=tracks)
            for k, (stamp, tracks) in enumerate(sorted(by_stamp.items()))]  # fmt: skip
