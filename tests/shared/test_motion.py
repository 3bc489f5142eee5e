"""The motion model and RTS smoother of :mod:`wz_shared.motion`: the model matrices (paper
Eq. 8-9, the road-aligned ``Q``), the smoother against filterpy's ``rts_smoother``, recomputed
priors against the filter's stored ones, and its invariants."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg
from filterpy.kalman import KalmanFilter as FilterpyKalmanFilter
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.purity import top_level_imports
from tests.shared.filtered import filtered_car
from wz_shared import motion
from wz_shared.motion import ProcessNoise, cv_transition, road_aligned_q, rts_smooth, white_noise_q


def test_core_imports_no_io_library() -> None:
    assert top_level_imports(motion).isdisjoint({"zenoh", "fastapi", "uvicorn", "requests", "io"})


# --- model matrices ---------------------------------------------------------------------------


def test_transition_and_paper_q_match_equations_8_and_9() -> None:
    dt = 0.1
    np.testing.assert_array_equal(
        cv_transition(dt),
        [[1, 0, 0.1, 0], [0, 1, 0, 0.1], [0, 0, 1, 0], [0, 0, 0, 1]],
    )
    # sigma_a = 2: sigma^2 dt^4/4 = 1e-4, sigma^2 dt^3/2 = 2e-3, sigma^2 dt^2 = 4e-2.
    np.testing.assert_allclose(
        white_noise_q(dt, 2.0),
        [[1e-4, 0, 2e-3, 0], [0, 1e-4, 0, 2e-3], [2e-3, 0, 4e-2, 0], [0, 2e-3, 0, 4e-2]],
        rtol=1e-12,
    )
    assert cv_transition(np.array([0.1, 0.2])).shape == (2, 4, 4)
    assert white_noise_q(np.array([0.1, 0.2]), 1.0).shape == (2, 4, 4)


def test_road_aligned_q_is_white_noise_q_when_isotropic_and_rotates_with_heading() -> None:
    np.testing.assert_allclose(road_aligned_q(0.05, 1.5, 1.5, 0.7), white_noise_q(0.05, 1.5))
    # Heading east: the along-road std acts on x, the across-road std on y.
    east = road_aligned_q(0.1, 2.0, 0.5, 0.0)
    np.testing.assert_allclose(east[[0, 2]][:, [0, 2]], white_noise_q(0.1, 2.0)[[0, 2]][:, [0, 2]])
    np.testing.assert_allclose(east[[1, 3]][:, [1, 3]], white_noise_q(0.1, 0.5)[[1, 3]][:, [1, 3]])
    # Q(h) = Rot4 Q(0) Rot4' with Rot4 = blockdiag(Rot(h), Rot(h)).
    heading = 0.6
    c, s = math.cos(heading), math.sin(heading)
    rot = np.array([[c, -s], [s, c]])
    rot4 = scipy.linalg.block_diag(rot, rot)
    np.testing.assert_allclose(
        road_aligned_q(0.1, 2.0, 0.5, heading), rot4 @ east @ rot4.T, atol=1e-15
    )
    assert ProcessNoise(2.0, 0.5).q(0.1, heading) == pytest.approx(
        road_aligned_q(0.1, 2.0, 0.5, heading)
    )
    np.testing.assert_array_equal(ProcessNoise.isotropic(2.0).q(0.1), white_noise_q(0.1, 2.0))


# --- the smoother on a filtered track (isotropic noise) ----------------------------------------


NOISE = ProcessNoise.isotropic(0.5)
R = np.diag([1.0, 0.25])  # [m^2]
H = np.eye(2, 4)


def filtered_track(
    seed: int, steps: int = 200, random_dt: bool = True
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Stamps, truth, measurements, filtered states and covariances, priors; seeded."""
    rng = np.random.default_rng(seed)
    dts = rng.uniform(0.03, 0.15, steps) if random_dt else np.full(steps, 0.1)
    dts[0] = 0.0
    stamps = np.cumsum(dts)
    truth = np.array([[100.0 + 28.0 * t, 5.0 - 0.5 * t] for t in stamps])
    z = truth + rng.multivariate_normal(np.zeros(2), R, steps)
    x, P = np.array([z[0, 0], z[0, 1], 0.0, 0.0]), np.diag([R[0, 0], R[1, 1], 900.0, 900.0])
    xs, Ps, x_priors, P_priors = [x], [P], [x], [P]
    for k in range(1, steps):
        dt = stamps[k] - stamps[k - 1]
        F = cv_transition(dt)
        x_p, P_p = F @ x, F @ P @ F.T + NOISE.q(dt)
        K = P_p @ H.T @ np.linalg.inv(H @ P_p @ H.T + R)
        I_KH = np.eye(4) - K @ H
        x, P = x_p + K @ (z[k] - H @ x_p), I_KH @ P_p @ I_KH.T + K @ R @ K.T
        xs.append(x)
        Ps.append(P)
        x_priors.append(x_p)
        P_priors.append(P_p)
    return (
        stamps,
        truth,
        z,
        np.array(xs),
        np.array(Ps),
        np.array(x_priors),
        np.array(P_priors),
    )


def test_smoothed_rmse_of_a_filtered_track_is_below_the_filtered_one() -> None:
    stamps, truth, _, x_filt, P_filt, _, _ = filtered_track(seed=3)
    x_smooth, P_smooth = rts_smooth(stamps, x_filt, P_filt, NOISE)
    settle = 20  # leave out the filter's initial transient
    filtered_rmse = np.sqrt(np.mean(np.sum((x_filt[settle:, :2] - truth[settle:]) ** 2, axis=1)))
    smoothed_rmse = np.sqrt(np.mean(np.sum((x_smooth[settle:, :2] - truth[settle:]) ** 2, axis=1)))
    assert smoothed_rmse < 0.7 * filtered_rmse
    # The smoother never claims more uncertainty than the filter.
    assert np.all(
        np.trace(P_smooth, axis1=1, axis2=2) <= np.trace(P_filt, axis1=1, axis2=2) + 1e-12
    )
    np.testing.assert_array_equal(x_smooth[-1], x_filt[-1])


def test_a_single_state_is_returned_unchanged() -> None:
    x = np.array([[1.0, 2.0, 3.0, 4.0]])
    P = np.eye(4)[None] * 2.0
    x_smooth, P_smooth = rts_smooth([5.0], x, P, NOISE)
    np.testing.assert_array_equal(x_smooth, x)
    np.testing.assert_array_equal(P_smooth, P)


def test_agrees_with_filterpy_rts_smoother_on_a_filtered_track_at_fixed_dt() -> None:
    stamps, _, _, x_filt, P_filt, _, _ = filtered_track(seed=5, steps=150, random_dt=False)
    x_smooth, P_smooth = rts_smooth(stamps, x_filt, P_filt, NOISE)
    dt = 0.1
    reference = FilterpyKalmanFilter(dim_x=4, dim_z=2)
    reference.F = cv_transition(dt)
    reference.Q = NOISE.q(dt)
    x_ref, P_ref, _, _ = reference.rts_smoother(x_filt, P_filt)
    np.testing.assert_allclose(x_smooth, x_ref, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(P_smooth, P_ref, rtol=1e-9, atol=1e-9)


def test_stored_priors_give_the_same_result_as_recomputed_ones() -> None:
    stamps, _, _, x_filt, P_filt, x_prior, P_prior = filtered_track(seed=9, steps=80)
    recomputed = rts_smooth(stamps, x_filt, P_filt, NOISE)
    stored = rts_smooth(stamps, x_filt, P_filt, None, x_pred=x_prior, P_pred=P_prior)
    np.testing.assert_allclose(stored[0], recomputed[0], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(stored[1], recomputed[1], rtol=1e-9, atol=1e-9)


def test_refuses_inconsistent_input() -> None:
    with pytest.raises(ValueError, match="stamps"):
        rts_smooth([0.0, 1.0], np.zeros((3, 4)), np.zeros((3, 4, 4)), NOISE)
    with pytest.raises(ValueError, match="decrease"):
        rts_smooth([1.0, 0.0], np.zeros((2, 4)), np.zeros((2, 4, 4)), NOISE)
    with pytest.raises(ValueError, match="noise"):
        rts_smooth([0.0, 1.0], np.zeros((2, 4)), np.zeros((2, 4, 4)), None)


# --- the smoother on stored states, recomputing the priors ---------------------------------------


ALONG, ACROSS = 3.5, 0.5
ROAD_NOISE = ProcessNoise(ALONG, ACROSS)


def random_states(
    seed: int, n: int, *, heading_rad: float | None = 0.7
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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


def priors_at(
    stamps: np.ndarray, x: np.ndarray, P: np.ndarray, heading_rad: float | None
) -> tuple[np.ndarray, np.ndarray]:
    """The priors a filter with the filter's ``Q`` (:meth:`ProcessNoise.q`) would have stored:
    along ``heading_rad``, or along each state's velocity (isotropic when slow) when None."""
    x_pred, P_pred = x.copy(), P.copy()
    for k in range(1, len(stamps)):
        dt = stamps[k] - stamps[k - 1]
        speed = np.hypot(x[k - 1, 2], x[k - 1, 3])
        heading = np.arctan2(x[k - 1, 3], x[k - 1, 2]) if heading_rad is None else heading_rad
        Q = (
            white_noise_q(dt, ALONG)
            if speed < ROAD_NOISE.heading_min_speed_mps
            else road_aligned_q(dt, ALONG, ACROSS, heading)
        )
        F = cv_transition(dt)
        x_pred[k], P_pred[k] = F @ x[k - 1], F @ P[k - 1] @ F.T + Q
    return x_pred, P_pred


def test_recomputed_priors_agree_with_stored_ones_at_a_constant_heading() -> None:
    stamps, x, P = random_states(1, 400)
    ours = rts_smooth(stamps, x, P, ROAD_NOISE)
    x_pred, P_pred = priors_at(stamps, x, P, 0.7)
    theirs = rts_smooth(stamps, x, P, x_pred=x_pred, P_pred=P_pred)
    np.testing.assert_allclose(ours[0], theirs[0], rtol=0.0, atol=1e-12)
    np.testing.assert_allclose(ours[1], theirs[1], rtol=0.0, atol=1e-12)


def test_recomputed_priors_agree_with_stored_ones_for_any_heading_and_speed() -> None:
    """Headings that change at every step and slow states (isotropic noise): the stored priors
    are built with ``road_aligned_q``/``white_noise_q``, as the filter builds them."""
    stamps, x, P = random_states(2, 300, heading_rad=None)
    ours = rts_smooth(stamps, x, P, ROAD_NOISE)
    x_pred, P_pred = priors_at(stamps, x, P, None)
    theirs = rts_smooth(stamps, x, P, x_pred=x_pred, P_pred=P_pred)
    np.testing.assert_allclose(ours[0], theirs[0], rtol=0.0, atol=1e-11)
    np.testing.assert_allclose(ours[1], theirs[1], rtol=0.0, atol=1e-11)


def test_agrees_with_filterpy_on_a_filtered_car() -> None:
    car = filtered_car(seed=3, count=300, sigma_a_mps2=1.2)
    ours = rts_smooth(car.stamps_s, car.x_filt, car.P_filt, ProcessNoise.isotropic(1.2))
    dts = np.diff(car.stamps_s)
    # filterpy's convention: Fs[k + 1] and Qs[k + 1] predict from step k to step k + 1
    Fs = np.concatenate([np.eye(4)[None], cv_transition(dts)])
    Qs = np.concatenate([np.zeros((1, 4, 4)), road_aligned_q(dts, 1.2, 1.2, 0.0)])
    x_ref, P_ref, _, _ = FilterpyKalmanFilter(dim_x=4, dim_z=2).rts_smoother(
        car.x_filt, car.P_filt, Fs=Fs, Qs=Qs
    )
    np.testing.assert_allclose(ours[0], x_ref, rtol=0.0, atol=1e-9)
    np.testing.assert_allclose(ours[1], P_ref, rtol=0.0, atol=1e-9)


def test_road_aligned_q_is_the_closed_form() -> None:
    """Along the heading, ``G Sigma_a G^T`` with ``G = [dt^2/2, dt]``: ``[[dt^4/4, dt^3/2],
    [dt^3/2, dt^2]] sigma^2`` per axis; across it the same with the other sigma."""
    dt, h = 0.2, np.pi / 2  # heading north: along is y, across is x
    Q = road_aligned_q(dt, 3.0, 0.5, h)
    block = np.array([[dt**4 / 4, dt**3 / 2], [dt**3 / 2, dt**2]])
    np.testing.assert_allclose(Q[np.ix_([1, 3], [1, 3])], 9.0 * block, atol=1e-15)
    np.testing.assert_allclose(Q[np.ix_([0, 2], [0, 2])], 0.25 * block, atol=1e-15)
    np.testing.assert_allclose(Q[np.ix_([0, 2], [1, 3])], 0.0, atol=1e-15)


def test_smoothing_brings_a_filtered_car_closer_to_the_truth() -> None:
    car = filtered_car(seed=4, count=400)
    x_s, _ = rts_smooth(car.stamps_s, car.x_filt, car.P_filt, ProcessNoise.isotropic(1.0))
    settled = slice(20, None)  # after the filter's start-up

    def rmse(estimate: np.ndarray) -> float:
        return float(
            np.sqrt(np.mean(np.sum((estimate[settled, :2] - car.truth[settled, :2]) ** 2, axis=1)))
        )

    assert rmse(x_s) < 0.75 * rmse(car.x_filt)


def test_one_state_or_exact_states_come_back_unchanged() -> None:
    stamps, x, P = random_states(5, 1)
    x_s, P_s = rts_smooth(stamps, x, P, ROAD_NOISE)
    assert np.array_equal(x_s, x) and np.array_equal(P_s, P)
    # No uncertainty in the stored states: nothing to correct (the gain is zero).
    stamps, x, _ = random_states(6, 50)
    x_s, P_s = rts_smooth(stamps, x, np.zeros((50, 4, 4)), ROAD_NOISE)
    np.testing.assert_allclose(x_s, x, atol=1e-12)
    # A repeated stamp of an exact state: a singular prior, passed over, no error.
    x_s, _ = rts_smooth([0.0, 0.0, 0.05], x[:3], np.zeros((3, 4, 4)), ROAD_NOISE)
    assert np.all(np.isfinite(x_s))


def test_refuses_bad_shapes_and_stamps_that_go_back() -> None:
    stamps, x, P = random_states(7, 5)
    with pytest.raises(ValueError, match="5 stamps but 4 states"):
        rts_smooth(stamps, x[:4], P, ROAD_NOISE)
    with pytest.raises(ValueError, match="must not decrease"):
        rts_smooth(stamps[::-1], x, P, ROAD_NOISE)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(2, 40),
    along=st.floats(0.1, 10.0),
    across=st.floats(0.1, 10.0),
)
def test_smoothed_covariances_are_symmetric_positive_and_never_larger(
    seed: int, n: int, along: float, across: float
) -> None:
    """``P_k|n`` is symmetric positive semi-definite and ``P_k|k - P_k|n`` too (using every
    measurement never makes an estimate less certain); the last state is the stored one.
    The covariances are a filter's: predicted with the smoother's Q, updated with random
    position measurements (Joseph form)."""
    stamps, x, P = random_states(seed, n, heading_rad=None)
    rng = np.random.default_rng(seed)
    H = np.eye(2, 4)
    dts = np.diff(stamps)
    speed = np.hypot(x[:-1, 2], x[:-1, 3])
    noise = ProcessNoise(along, across)
    Q = road_aligned_q(dts, along, noise.sigma_across_at(speed), np.arctan2(x[:-1, 3], x[:-1, 2]))
    F = cv_transition(dts)
    for k in range(1, n):
        prior = F[k - 1] @ P[k - 1] @ F[k - 1].T + Q[k - 1]
        A = rng.normal(scale=0.3, size=(2, 2))
        R = A @ A.T + 0.01 * np.eye(2)
        K = prior @ H.T @ np.linalg.inv(H @ prior @ H.T + R)
        I_KH = np.eye(4) - K @ H
        P[k] = I_KH @ prior @ I_KH.T + K @ R @ K.T
        P[k] = (P[k] + P[k].T) / 2
    x_s, P_s = rts_smooth(stamps, x, P, noise)
    assert np.array_equal(x_s[-1], x[-1]) and np.array_equal(P_s[-1], P[-1])
    assert np.array_equal(P_s, np.swapaxes(P_s, -1, -2))
    scale = np.linalg.norm(P, axis=(1, 2))[:, None]
    assert np.all(np.linalg.eigvalsh(P_s) >= -1e-9 * scale)
    assert np.all(np.linalg.eigvalsh(P - P_s) >= -1e-9 * scale)
