"""The gateway's RTS smoother against two references (the fusion tracker's smoother, filterpy's
``rts_smoother``), its invariants, and what it does to a stored trajectory."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.gateway.helpers import SITE
from tests.gateway.tracking import filtered_car
from wz_fusion_tracker import kalman
from wz_fusion_tracker.smoothing import rts_smooth as tracker_rts_smooth
from wz_gateway.smoothing import (
    HEADING_MIN_SPEED_MPS,
    StoredTrajectory,
    cv_transitions,
    road_aligned_q,
    rts_smooth,
    smooth_trajectory,
)

ALONG, ACROSS = 3.5, 0.5


def random_states(seed: int, n: int, *, heading_rad: float | None = 0.7) -> tuple[
    np.ndarray, np.ndarray, np.ndarray
]:  # fmt: skip
    """Stamps at irregular 40-60 ms, states (moving along ``heading_rad`` when given, else in
    random directions and sometimes slow) and random SPD covariances."""
    rng = np.random.default_rng(seed)
    stamps = np.cumsum(rng.uniform(0.04, 0.06, n))
    x = np.column_stack([rng.normal(scale=20.0, size=(n, 2)), np.zeros((n, 2))])
    if heading_rad is None:
        speed = rng.choice([0.5, 1.9, 12.0, 30.0], size=n)
        heading = rng.uniform(-np.pi, np.pi, n)
    else:
        speed, heading = np.full(n, 25.0), np.full(n, heading_rad)
    x[:, 2], x[:, 3] = speed * np.cos(heading), speed * np.sin(heading)
    A = rng.normal(size=(n, 4, 4))
    P = A @ np.swapaxes(A, -1, -2) + 0.05 * np.eye(4)
    return stamps, x, P


def test_agrees_with_the_trackers_smoother_at_a_constant_heading() -> None:
    stamps, x, P = random_states(1, 400)
    ours = rts_smooth(stamps, x, P, sigma_along_mps2=ALONG, sigma_across_mps2=ACROSS)
    theirs = tracker_rts_smooth(stamps, x, P, kalman.ProcessNoise(ALONG, ACROSS, 0.7))
    np.testing.assert_allclose(ours[0], theirs[0], rtol=0.0, atol=1e-12)
    np.testing.assert_allclose(ours[1], theirs[1], rtol=0.0, atol=1e-12)


def test_agrees_with_the_trackers_smoother_given_its_priors_for_any_heading_and_speed() -> None:
    """Headings that change at every step and slow states (isotropic noise): the tracker's
    smoother is given the priors built with its own ``road_aligned_q``/``white_noise_q``."""
    stamps, x, P = random_states(2, 300, heading_rad=None)
    x_pred, P_pred = x.copy(), P.copy()
    for k in range(1, len(stamps)):
        dt = stamps[k] - stamps[k - 1]
        speed = np.hypot(x[k - 1, 2], x[k - 1, 3])
        Q = (kalman.white_noise_q(dt, ALONG) if speed < HEADING_MIN_SPEED_MPS else
             kalman.road_aligned_q(dt, ALONG, ACROSS, np.arctan2(x[k - 1, 3], x[k - 1, 2])))  # fmt: skip
        F = kalman.cv_transition(dt)
        x_pred[k], P_pred[k] = F @ x[k - 1], F @ P[k - 1] @ F.T + Q
    ours = rts_smooth(stamps, x, P, sigma_along_mps2=ALONG, sigma_across_mps2=ACROSS)
    theirs = tracker_rts_smooth(stamps, x, P, None, x_pred=x_pred, P_pred=P_pred)
    np.testing.assert_allclose(ours[0], theirs[0], rtol=0.0, atol=1e-11)
    np.testing.assert_allclose(ours[1], theirs[1], rtol=0.0, atol=1e-11)


def test_agrees_with_filterpy_on_a_filtered_car() -> None:
    car = filtered_car(seed=3, count=300, sigma_a_mps2=1.2)
    ours = rts_smooth(car.stamps_s, car.x_filt, car.P_filt, sigma_along_mps2=1.2,
                      sigma_across_mps2=1.2)  # fmt: skip
    dts = np.diff(car.stamps_s)
    # filterpy's convention: Fs[k + 1] and Qs[k + 1] predict from step k to step k + 1
    Fs = np.concatenate([np.eye(4)[None], cv_transitions(dts)])
    Qs = np.concatenate([np.zeros((1, 4, 4)),
                         road_aligned_q(dts, np.zeros(len(dts)), 1.2, 1.2)])  # fmt: skip
    x_ref, P_ref, _, _ = KalmanFilter(dim_x=4, dim_z=2).rts_smoother(car.x_filt, car.P_filt,
                                                                     Fs=Fs, Qs=Qs)  # fmt: skip
    np.testing.assert_allclose(ours[0], x_ref, rtol=0.0, atol=1e-9)
    np.testing.assert_allclose(ours[1], P_ref, rtol=0.0, atol=1e-9)


def test_road_aligned_q_is_the_closed_form() -> None:
    """Along the heading, ``G Sigma_a G^T`` with ``G = [dt^2/2, dt]``: ``[[dt^4/4, dt^3/2],
    [dt^3/2, dt^2]] sigma^2`` per axis; across it the same with the other sigma."""
    dt, h = 0.2, np.pi / 2  # heading north: along is y, across is x
    Q = road_aligned_q(np.array([dt]), np.array([h]), 3.0, 0.5)[0]
    block = np.array([[dt**4 / 4, dt**3 / 2], [dt**3 / 2, dt**2]])
    np.testing.assert_allclose(Q[np.ix_([1, 3], [1, 3])], 9.0 * block, atol=1e-15)
    np.testing.assert_allclose(Q[np.ix_([0, 2], [0, 2])], 0.25 * block, atol=1e-15)
    np.testing.assert_allclose(Q[np.ix_([0, 2], [1, 3])], 0.0, atol=1e-15)


def test_smoothing_brings_a_filtered_car_closer_to_the_truth() -> None:
    car = filtered_car(seed=4, count=400)
    x_s, _ = rts_smooth(car.stamps_s, car.x_filt, car.P_filt, sigma_along_mps2=1.0,
                        sigma_across_mps2=1.0)  # fmt: skip
    settled = slice(20, None)  # after the filter's start-up

    def rmse(estimate: np.ndarray) -> float:
        return float(np.sqrt(np.mean(np.sum((estimate[settled, :2] -
                                             car.truth[settled, :2]) ** 2, axis=1))))  # fmt: skip

    assert rmse(x_s) < 0.75 * rmse(car.x_filt)


def test_one_state_or_exact_states_come_back_unchanged() -> None:
    stamps, x, P = random_states(5, 1)
    x_s, P_s = rts_smooth(stamps, x, P, sigma_along_mps2=ALONG, sigma_across_mps2=ACROSS)
    assert np.array_equal(x_s, x) and np.array_equal(P_s, P)
    # No uncertainty in the stored states: nothing to correct (the gain is zero).
    stamps, x, _ = random_states(6, 50)
    x_s, P_s = rts_smooth(stamps, x, np.zeros((50, 4, 4)), sigma_along_mps2=ALONG,
                          sigma_across_mps2=ACROSS)  # fmt: skip
    np.testing.assert_allclose(x_s, x, atol=1e-12)
    # A repeated stamp of an exact state: a singular prior, passed over, no error.
    x_s, _ = rts_smooth([0.0, 0.0, 0.05], x[:3], np.zeros((3, 4, 4)), sigma_along_mps2=ALONG,
                        sigma_across_mps2=ACROSS)  # fmt: skip
    assert np.all(np.isfinite(x_s))


def test_refuses_bad_shapes_and_stamps_that_go_back() -> None:
    stamps, x, P = random_states(7, 5)
    with pytest.raises(ValueError, match="5 stamps but 4 states"):
        rts_smooth(stamps, x[:4], P, sigma_along_mps2=ALONG, sigma_across_mps2=ACROSS)
    with pytest.raises(ValueError, match="must not decrease"):
        rts_smooth(stamps[::-1], x, P, sigma_along_mps2=ALONG, sigma_across_mps2=ACROSS)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 40),
       along=st.floats(0.1, 10.0), across=st.floats(0.1, 10.0))  # fmt: skip
def test_smoothed_covariances_are_symmetric_positive_and_never_larger(seed: int, n: int,
                                                                      along: float,
                                                                      across: float) -> None:  # fmt: skip
    """``P_k|n`` is symmetric positive semi-definite and ``P_k|k - P_k|n`` too (using every
    measurement never makes an estimate less certain); the last state is the stored one.
    The covariances are a filter's: predicted with the smoother's Q, updated with random
    position measurements (Joseph form)."""
    stamps, x, P = random_states(seed, n, heading_rad=None)
    rng = np.random.default_rng(seed)
    H = np.eye(2, 4)
    dts = np.diff(stamps)
    speed = np.hypot(x[:-1, 2], x[:-1, 3])
    Q = road_aligned_q(dts, np.arctan2(x[:-1, 3], x[:-1, 2]), along,
                       np.where(speed < HEADING_MIN_SPEED_MPS, along, across))  # fmt: skip
    F = cv_transitions(dts)
    for k in range(1, n):
        prior = F[k - 1] @ P[k - 1] @ F[k - 1].T + Q[k - 1]
        A = rng.normal(scale=0.3, size=(2, 2))
        R = A @ A.T + 0.01 * np.eye(2)
        K = prior @ H.T @ np.linalg.inv(H @ prior @ H.T + R)
        I_KH = np.eye(4) - K @ H
        P[k] = I_KH @ prior @ I_KH.T + K @ R @ K.T
        P[k] = (P[k] + P[k].T) / 2
    x_s, P_s = rts_smooth(stamps, x, P, sigma_along_mps2=along, sigma_across_mps2=across)
    assert np.array_equal(x_s[-1], x[-1]) and np.array_equal(P_s[-1], P[-1])
    assert np.array_equal(P_s, np.swapaxes(P_s, -1, -2))
    scale = np.linalg.norm(P, axis=(1, 2))[:, None]
    assert np.all(np.linalg.eigvalsh(P_s) >= -1e-9 * scale)
    assert np.all(np.linalg.eigvalsh(P - P_s) >= -1e-9 * scale)


def test_a_smoothed_trajectory_gets_its_road_position_lane_and_wgs84_again() -> None:
    car = filtered_car(seed=8, count=120)
    n = len(car.stamps_s)
    station, offset = SITE.road_frame.to_road(car.x_filt[:, 0], car.x_filt[:, 1])
    latitude, longitude, _ = SITE.geo_frame.to_wgs84(car.x_filt[:, 0], car.x_filt[:, 1])
    stored = StoredTrajectory(
        track_id=5, stamp=car.stamps_s, x_m=car.x_filt[:, 0], y_m=car.x_filt[:, 1],
        vx_mps=car.x_filt[:, 2], vy_mps=car.x_filt[:, 3], covariance=car.P_filt,
        latitude_deg=latitude, longitude_deg=longitude, station_m=station, offset_m=offset,
        lane_index=SITE.lane_index_at(offset).astype(np.int64),
        speed_mps=np.hypot(car.x_filt[:, 2], car.x_filt[:, 3]),
        heading_rad=np.arctan2(car.x_filt[:, 3], car.x_filt[:, 2]),
        object_class=("unknown",) * (n - 1) + ("car",), status=("tentative",) + ("confirmed",) * (n - 1),
        length_m=np.r_[np.full(n - 1, np.nan), 4.4], width_m=np.r_[np.full(n - 1, np.nan), 1.8],
        received_at=1000.0 + car.stamps_s,
    )  # fmt: skip
    smoothed = smooth_trajectory(stored, SITE, sigma_along_mps2=1.0, sigma_across_mps2=1.0)
    x_s, _ = rts_smooth(car.stamps_s, car.x_filt, car.P_filt, sigma_along_mps2=1.0,
                        sigma_across_mps2=1.0)  # fmt: skip
    assert np.array_equal(smoothed.x_m, x_s[:, 0]) and np.array_equal(smoothed.vy_mps, x_s[:, 3])
    s, d = SITE.road_frame.to_road(x_s[:, 0], x_s[:, 1])
    np.testing.assert_allclose(smoothed.station_m, s, atol=1e-9)
    np.testing.assert_allclose(smoothed.offset_m, d, atol=1e-9)
    assert np.array_equal(smoothed.lane_index, SITE.lane_index_at(d))
    lat, lon, _ = SITE.geo_frame.to_wgs84(x_s[:, 0], x_s[:, 1])
    np.testing.assert_allclose(smoothed.latitude_deg, lat, atol=1e-12)
    np.testing.assert_allclose(smoothed.longitude_deg, lon, atol=1e-12)
    np.testing.assert_allclose(smoothed.speed_mps, np.hypot(x_s[:, 2], x_s[:, 3]), atol=1e-12)
    # hindsight: the last class and size for every point; stamps, status, arrival kept
    assert set(smoothed.object_class) == {"car"}
    assert np.all(smoothed.length_m == 4.4) and np.all(smoothed.width_m == 1.8)
    assert smoothed.status == stored.status
    assert np.array_equal(smoothed.stamp, stored.stamp)
    assert np.array_equal(smoothed.received_at, stored.received_at)
