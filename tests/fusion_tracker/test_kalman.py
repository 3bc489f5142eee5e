"""Constant-velocity Kalman filter (the model matrices: tests/shared/test_motion.py): one
predict/update against hand computation, the steady state against the Riccati equation, filterpy as a reference, the three
forms (functions, one filter, the vectorised bank) side by side for 2000 steps, and the
covariance staying symmetric positive definite under random sequences."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg
from filterpy.kalman import KalmanFilter as FilterpyKalmanFilter
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.purity import top_level_imports
from wz_fusion_tracker import kalman
from wz_fusion_tracker.kalman import (
    KalmanFilter,
    TrackStateBank,
    innovation,
    is_symmetric_positive_definite,
    position_h,
    predict,
    update,
)
from wz_shared.motion import ProcessNoise, cv_transition, road_aligned_q, white_noise_q

H = position_h()


def random_covariance(rng: np.random.Generator, dim: int, scale: float = 1.0) -> np.ndarray:
    """A random symmetric positive definite matrix with eigenvalues in [0.05, 1] * scale."""
    basis, _ = np.linalg.qr(rng.normal(size=(dim, dim)))
    covariance: np.ndarray = scale * basis @ np.diag(rng.uniform(0.05, 1.0, dim)) @ basis.T
    return covariance


def test_core_imports_no_io_library() -> None:
    assert top_level_imports(kalman).isdisjoint({"zenoh", "fastapi", "uvicorn", "requests", "io"})


# ----------------------------------------------------------------------------- hand computation


def test_one_prediction_is_f_p_ft_plus_q_by_hand() -> None:
    x = np.array([10.0, 20.0, 3.0, -4.0])
    P = np.diag([1.0, 2.0, 3.0, 4.0])
    x_p, P_p = predict(x, P, cv_transition(0.1), white_noise_q(0.1, 2.0))
    np.testing.assert_allclose(x_p, [10.3, 19.6, 3.0, -4.0])
    # F P F': P[0,0] + dt^2 P[2,2] = 1.03, dt P[2,2] = 0.3, ...; plus Q (previous test).
    expected = np.array(
        [
            [1.03 + 1e-4, 0.0, 0.3 + 2e-3, 0.0],
            [0.0, 2.04 + 1e-4, 0.0, 0.4 + 2e-3],
            [0.3 + 2e-3, 0.0, 3.0 + 4e-2, 0.0],
            [0.0, 0.4 + 2e-3, 0.0, 4.0 + 4e-2],
        ]
    )
    np.testing.assert_allclose(P_p, expected, rtol=1e-12)


def test_scalar_update_matches_the_hand_computed_gain() -> None:
    # x = 0, P = 4, z = 1, R = 1: S = 5, K = 0.8, x = 0.8, P = (1 - 0.8)^2 4 + 0.8^2 1 = 0.8.
    y, S = innovation([0.0], [[4.0]], [1.0], [[1.0]], [[1.0]])
    np.testing.assert_allclose(y, [1.0])
    np.testing.assert_allclose(S, [[5.0]])
    x, P = update([0.0], [[4.0]], [1.0], [[1.0]], [[1.0]])
    np.testing.assert_allclose(x, [0.8], rtol=1e-14)
    np.testing.assert_allclose(P, [[0.8]], rtol=1e-14)


def test_static_target_converges_to_the_riccati_steady_state() -> None:
    dt, sigma_a = 0.1, 0.5
    F, Q = cv_transition(dt), white_noise_q(dt, sigma_a)
    R = np.diag([0.3, 0.2])
    z = np.array([5.0, -2.0])
    x, P = np.array([0.0, 0.0, 1.0, 1.0]), np.diag([100.0, 100.0, 25.0, 25.0])
    for _ in range(2000):
        x_p, P_p = predict(x, P, F, Q)
        x, P = update(x_p, P_p, z, H, R)
    np.testing.assert_allclose(x, [5.0, -2.0, 0.0, 0.0], atol=1e-9)
    # Predicted steady state: P = F P F' - F P H' (H P H' + R)^-1 H P F' + Q.
    P_p_steady = scipy.linalg.solve_discrete_are(F.T, H.T, Q, R)
    np.testing.assert_allclose(P_p, P_p_steady, rtol=1e-9, atol=1e-12)


# ----------------------------------------------------------------------------- references


def cv_sequence(
    rng: np.random.Generator, steps: int, fixed_dt_s: float | None = None
) -> list[tuple[float, np.ndarray, np.ndarray]]:
    """(dt, z, R) triples of a noisy constant-velocity target with random dt and R."""
    position = np.array([0.0, 0.0])
    velocity = np.array([25.0, -3.0])
    sequence = []
    for _ in range(steps):
        dt = fixed_dt_s if fixed_dt_s is not None else float(rng.uniform(0.0, 0.2))
        position = position + velocity * dt
        R = random_covariance(rng, 2, scale=rng.uniform(0.01, 4.0))
        z = rng.multivariate_normal(position, R)
        sequence.append((dt, z, R))
    return sequence


def test_agrees_with_filterpy_on_a_seeded_random_sequence() -> None:
    rng = np.random.default_rng(7)
    x0, P0 = np.array([1.0, -1.0, 20.0, 0.0]), np.diag([4.0, 4.0, 100.0, 100.0])
    reference = FilterpyKalmanFilter(dim_x=4, dim_z=2)
    reference.x = x0.copy()
    reference.P = P0.copy()
    reference.H = H
    x, P = x0, P0
    for dt, z, R in cv_sequence(rng, 300):
        reference.F = cv_transition(dt)
        reference.Q = white_noise_q(dt, 1.5)
        reference.predict()
        reference.update(z, R=R)
        x, P = predict(x, P, cv_transition(dt), white_noise_q(dt, 1.5))
        x, P = update(x, P, z, H, R)
        np.testing.assert_allclose(x, reference.x, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(P, reference.P, rtol=1e-9, atol=1e-9)


def test_functions_filter_class_and_bank_agree_over_2000_steps() -> None:
    rng = np.random.default_rng(11)
    targets = 3
    sigma_along, sigma_across = 2.0, 0.3
    headings = np.array([0.0, 1.2, -2.5])
    x0 = rng.normal(size=(targets, 4)) * [50.0, 50.0, 10.0, 10.0]
    P0 = np.array([random_covariance(rng, 4, 10.0) for _ in range(targets)])
    filters = [KalmanFilter(x0[i], P0[i]) for i in range(targets)]
    function_states = [(x0[i].copy(), P0[i].copy()) for i in range(targets)]
    bank = TrackStateBank(capacity=2)  # grows while the targets are added
    slots = np.array([bank.add(x0[i], P0[i], 0.0) for i in range(targets)])
    speed_row = np.array([[0.0, 0.0, 1.0, 0.0]])
    for step in range(2000):
        dt = rng.uniform(0.0, 0.25, targets)
        z = rng.normal(size=(targets, 2)) * 30.0
        R = np.array([random_covariance(rng, 2, rng.uniform(0.01, 5.0)) for _ in range(targets)])
        bank.predict(slots, dt, sigma_along, sigma_across, headings)
        bank.update(slots, z, R)
        for i in range(targets):
            noise = ProcessNoise(sigma_along, sigma_across)
            filters[i].predict(float(dt[i]), noise, float(headings[i]))
            filters[i].update(z[i], R[i])
            x, P = function_states[i]
            x, P = predict(x, P, cv_transition(dt[i]), noise.q(float(dt[i]), float(headings[i])))
            function_states[i] = update(x, P, z[i], H, R[i])
        if step % 10 == 0:  # now and then a 1-D velocity measurement, general H
            speeds = rng.normal(size=(targets, 1)) * 20.0
            bank.update(slots, speeds, np.full((targets, 1, 1), 0.5), speed_row)
            for i in range(targets):
                filters[i].update(speeds[i], [[0.5]], speed_row)
                x, P = function_states[i]
                function_states[i] = update(x, P, speeds[i], speed_row, [[0.5]])
        for i in range(targets):
            x, P = function_states[i]
            np.testing.assert_allclose(filters[i].x, x, rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(filters[i].P, P, rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(bank.states(slots)[i], x, rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(bank.covariances(slots)[i], P, rtol=1e-9, atol=1e-9)


def test_bank_predicted_leaves_state_alone_and_slots_are_reused() -> None:
    bank = TrackStateBank(capacity=1)
    first = bank.add([0.0, 0.0, 10.0, 0.0], np.eye(4), 1.0)
    second = bank.add([5.0, 5.0, 0.0, 1.0], np.eye(4), 1.0)
    assert bank.capacity == 2 and len(bank) == 2
    x_p, _ = bank.predicted([first, second], 1.5, 1.0, 1.0)
    np.testing.assert_allclose(x_p[:, :2], [[5.0, 0.0], [5.0, 5.5]])
    np.testing.assert_array_equal(bank.states([first])[0], [0.0, 0.0, 10.0, 0.0])
    bank.predict_to([first], 2.0, 1.0, 1.0)
    np.testing.assert_array_equal(bank.stamps_s([first, second]), [2.0, 1.0])
    bank.remove(first)
    assert bank.add(np.zeros(4), np.eye(4), 0.0) == first
    np.testing.assert_array_equal(bank.live_slots(), [0, 1])
    bank.remove(second)
    with pytest.raises(KeyError):
        bank.remove(second)


# ----------------------------------------------------------------------------- invariants


@settings(max_examples=50, deadline=None, derandomize=True)
@given(
    seed=st.integers(min_value=0, max_value=2**32 - 1),
    steps=st.integers(min_value=1, max_value=60),
    sigma_a=st.floats(min_value=0.01, max_value=10.0),
    measurement_scale=st.floats(min_value=1e-4, max_value=1e3),
)
def test_covariance_stays_symmetric_positive_definite(
    seed: int, steps: int, sigma_a: float, measurement_scale: float
) -> None:
    rng = np.random.default_rng(seed)
    x, P = np.zeros(4), np.diag([100.0, 100.0, 400.0, 400.0])
    bank = TrackStateBank()
    slot = np.array([bank.add(x, P, 0.0)])
    for _ in range(steps):
        dt = float(rng.choice([0.0, rng.uniform(0.0, 2.0)]))
        heading = float(rng.uniform(-math.pi, math.pi))
        R = random_covariance(rng, 2, measurement_scale)
        z = rng.normal(size=2) * 100.0
        x, P = predict(x, P, cv_transition(dt), road_aligned_q(dt, sigma_a, sigma_a / 5, heading))
        assert is_symmetric_positive_definite(P)
        x, P = update(x, P, z, H, R)
        assert is_symmetric_positive_definite(P)
        bank.predict(slot, dt, sigma_a, sigma_a / 5, heading)
        bank.update(slot, z[None], R[None])
        assert is_symmetric_positive_definite(bank.covariances(slot))
