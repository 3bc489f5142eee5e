"""RTS smoother: better than the filter on a noisy constant-velocity track, a single state
unchanged, filterpy's ``rts_smoother`` as a reference, stored priors equal recomputed ones."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter as FilterpyKalmanFilter

from tests.purity import top_level_imports
from wz_fusion_tracker import smoothing
from wz_fusion_tracker.kalman import ProcessNoise, cv_transition, position_h, predict, update
from wz_fusion_tracker.smoothing import rts_smooth

NOISE = ProcessNoise.isotropic(0.5)
R = np.diag([1.0, 0.25])  # [m^2]


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
        x_p, P_p = predict(x, P, cv_transition(dt), NOISE.q(dt))
        x, P = update(x_p, P_p, z[k], position_h(), R)
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


def test_core_imports_no_io_library() -> None:
    assert top_level_imports(smoothing).isdisjoint({"zenoh", "fastapi", "requests", "io"})


def test_smoothed_rmse_is_below_the_filtered_one() -> None:
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


def test_agrees_with_filterpy_rts_smoother_at_fixed_dt() -> None:
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
