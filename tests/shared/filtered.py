"""A car on a straight road running north and a Kalman filter's estimates of it, for the
smoothing tests: what the fusion tracker would publish, with real covariances."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from filterpy.kalman import KalmanFilter

from wz_shared.arrays import F64
from wz_shared.motion import cv_transition, road_aligned_q


@dataclass(frozen=True)
class FilteredCar:
    """Truth and filtered states ``[x, y, vx, vy]`` (n, 4), covariances (n, 4, 4), stamps (n,)."""

    stamps_s: F64
    truth: F64
    x_filt: F64
    P_filt: F64


def filtered_car(
    *,
    seed: int,
    count: int = 200,
    period_s: float = 0.05,
    start_s: float = 0.0,
    station0_m: float = 800.0,
    speed_mps: float = 25.0,
    offset_m: float = -1.83,
    sigma_a_mps2: float = 1.0,
    sigma_across_mps2: float | None = None,
    noise_m: float = 0.3,
) -> FilteredCar:
    """A car driving north (the site's road runs along ``y`` here: ``x = -offset``) with white
    acceleration ``sigma_a`` along the road (``sigma_across``, default the same, across it),
    measured every ``period_s`` with ``noise_m`` position noise and followed by a
    constant-velocity Kalman filter (filterpy) with the matching Q."""
    rng = np.random.default_rng(seed)
    stamps = start_s + period_s * np.arange(count, dtype=np.float64)
    F = cv_transition(period_s)
    across = sigma_a_mps2 if sigma_across_mps2 is None else sigma_across_mps2
    Q = road_aligned_q(period_s, sigma_a_mps2, across, np.pi / 2)
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
