"""The IMM bank: its Markov chain, filterpy's IMMEstimator as a reference, the single-model bank
as its special case, covariances that stay positive definite, and what it is for: smooth across
the road while a vehicle keeps its lane, and still following a merge."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
from filterpy.kalman import IMMEstimator
from filterpy.kalman import KalmanFilter as FilterpyKalmanFilter
from hypothesis import given, settings
from hypothesis import strategies as st

from wz_fusion_tracker.imm import IMMStateBank, mixture_moments, two_mode_transition
from wz_fusion_tracker.kalman import TrackStateBank, is_symmetric_positive_definite, position_h
from wz_shared.motion import cv_transition, road_aligned_q

STEADY = (0.5, 0.3)  # acceleration std along, across [m/s^2]
MANOEUVRE = (3.5, 3.0)
ALONG = np.array([STEADY[0], MANOEUVRE[0]])
ACROSS = np.array([STEADY[1], MANOEUVRE[1]])
SOJOURN_S = (10.0, 2.0)


def test_the_transition_matrix_is_the_chains_over_dt() -> None:
    dt = np.array([0.0, 0.05, 0.5, 3.0, 1e4])
    P = two_mode_transition(dt, *SOJOURN_S)
    np.testing.assert_allclose(P.sum(axis=2), 1.0, atol=1e-15)
    np.testing.assert_allclose(P[0], np.eye(2), atol=1e-15)
    # exp(G dt) of the generator G = [[-a, a], [b, -b]]
    a, b = 1.0 / SOJOURN_S[0], 1.0 / SOJOURN_S[1]
    generator = np.array([[-a, a], [b, -b]])
    for k in range(len(dt) - 1):
        np.testing.assert_allclose(P[k], scipy.linalg.expm(generator * dt[k]), atol=1e-12)
    # long after, the stationary distribution (b, a) / (a + b) from either mode
    stationary = np.array([b, a]) / (a + b)
    np.testing.assert_allclose(P[-1], [stationary, stationary], atol=1e-12)
    np.testing.assert_allclose(IMMStateBank(SOJOURN_S).initial_probabilities, stationary)


def test_the_mixture_moments_of_two_gaussians() -> None:
    x = np.array([[[0.0, 0.0], [2.0, 0.0]]])
    P = np.array([[np.eye(2), 3.0 * np.eye(2)]])
    mean, cov = mixture_moments(np.array([[0.5, 0.5]]), x, P)
    np.testing.assert_allclose(mean, [[1.0, 0.0]])
    # 0.5 (I + diag(1, 0)) + 0.5 (3 I + diag(1, 0)) = diag(3, 2)
    np.testing.assert_allclose(cov, [np.diag([3.0, 2.0])])


def _lane_change_truth(times: np.ndarray) -> np.ndarray:
    """A car at 28 m/s along x that keeps its lane, changes lanes (3.6 m in y over 3 s, a
    half-cosine) at t = 10 s, and keeps its new lane."""
    y = np.where(
        times < 10.0,
        0.0,
        np.where(times > 13.0, 3.6, 1.8 * (1.0 - np.cos(np.pi * (times - 10.0) / 3.0))),
    )
    return np.stack([28.0 * times, y], axis=1)


def test_agrees_with_filterpys_imm_estimator_on_a_seeded_sequence() -> None:
    """filterpy's IMMEstimator with the same modes and transition matrix, fixed dt: the same
    posterior mixture and mode probabilities at every step."""
    dt, heading = 0.1, 0.3
    rng = np.random.default_rng(11)
    R = np.array([[0.3, 0.05], [0.05, 0.1]])
    times = np.arange(1, 201) * dt
    truth = _lane_change_truth(times)
    c, s = np.cos(heading), np.sin(heading)
    truth = truth @ np.array([[c, s], [-s, c]])  # the road along `heading`
    z = truth + rng.multivariate_normal(np.zeros(2), R, size=len(times))
    x0 = np.array([0.0, 0.0, 28.0 * c, 28.0 * s])
    P0 = np.diag([1.0, 1.0, 4.0, 4.0])

    filters = []
    for along, across in (STEADY, MANOEUVRE):
        kf = FilterpyKalmanFilter(dim_x=4, dim_z=2)
        kf.x, kf.P = x0.copy(), P0.copy()
        kf.F = cv_transition(dt)
        kf.Q = road_aligned_q(dt, along, across, heading)
        kf.H, kf.R = position_h(), R
        filters.append(kf)
    bank = IMMStateBank(SOJOURN_S)
    reference = IMMEstimator(
        filters, bank.initial_probabilities.copy(), two_mode_transition(np.array(dt), *SOJOURN_S)
    )
    slot = bank.add(x0, P0, 0.0)
    slots = np.array([slot])
    for k, t in enumerate(times):
        reference.predict()
        bank.predict_to(slots, t, ALONG, ACROSS, heading)
        reference.update(z[k])
        bank.update(slots, z[k][None], R[None])
        np.testing.assert_allclose(bank.states(slots)[0], reference.x, rtol=0, atol=1e-9)
        np.testing.assert_allclose(bank.covariances(slots)[0], reference.P, rtol=0, atol=1e-9)
        np.testing.assert_allclose(bank.mode_probabilities(slots)[0], reference.mu, atol=1e-9)


def test_with_two_equal_modes_it_is_the_single_model_bank() -> None:
    rng = np.random.default_rng(5)
    imm, single = IMMStateBank(SOJOURN_S), TrackStateBank()
    for i in range(6):
        x = np.array([10.0 * i, 3.6 * (i % 2), 25.0 + i, 0.3])
        P = np.diag([0.5, 0.5, 9.0, 1.0])
        assert imm.add(x, P, 0.0) == single.add(x, P, 0.0)
    t = 0.0
    for _ in range(300):
        t += float(rng.uniform(0.0, 0.12))
        slots = np.sort(rng.choice(6, size=int(rng.integers(1, 7)), replace=False))
        heading = rng.uniform(-0.2, 0.2, size=len(slots))
        imm.predict_to(slots, t, [2.0, 2.0], [1.0, 1.0], heading)
        single.predict_to(slots, t, 2.0, 1.0, heading)
        z = single.states(slots)[:, :2] + rng.normal(0.0, 0.3, size=(len(slots), 2))
        R = np.broadcast_to(np.diag([0.09, 0.04]), (len(slots), 2, 2))
        imm.update(slots, z, R)
        single.update(slots, z, R)
    everyone = np.arange(6)
    np.testing.assert_allclose(imm.states(everyone), single.states(everyone), atol=1e-9)
    np.testing.assert_allclose(imm.covariances(everyone), single.covariances(everyone), atol=1e-9)
    np.testing.assert_allclose(
        imm.mode_probabilities(everyone),
        np.broadcast_to(imm.initial_probabilities, (6, 2)),
        atol=1e-9,
    )


def _track_lateral(
    bank_kind: str, z: np.ndarray, times: np.ndarray, R: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Filtered lateral positions over the run, and the manoeuvre probability (IMM only)."""
    bank: IMMStateBank | TrackStateBank
    bank = IMMStateBank(SOJOURN_S) if bank_kind == "imm" else TrackStateBank()
    slots = np.array(
        [bank.add([z[0, 0], z[0, 1], 28.0, 0.0], np.diag([0.1, 0.1, 1.0, 1.0]), times[0])]
    )
    lateral, manoeuvre = [], []
    for k in range(1, len(times)):
        if bank_kind == "imm":
            bank.predict_to(slots, times[k], ALONG, ACROSS)
        else:
            along, across = STEADY if bank_kind == "steady" else MANOEUVRE
            bank.predict_to(slots, times[k], along, across)
        bank.update(slots, z[k][None], R[None])
        lateral.append(bank.states(slots)[0, 1])
        if isinstance(bank, IMMStateBank):
            manoeuvre.append(bank.mode_probabilities(slots)[0, 1])
    return np.array(lateral), np.array(manoeuvre)


def test_smooth_while_the_lane_is_kept_and_following_the_lane_change() -> None:
    """A camera-like sensor at 10 Hz, 0.3 m across: the IMM's lateral error is below the
    manoeuvre model's while the car keeps its lane, and far below the steady model's through
    the lane change; its manoeuvre probability rises in the change and falls after it."""
    times = np.arange(0.0, 25.0, 0.1)
    truth = _lane_change_truth(times)
    R = np.diag([0.5**2, 0.3**2])
    rng = np.random.default_rng(3)
    z = truth + rng.multivariate_normal(np.zeros(2), R, size=len(times))
    error, manoeuvre = {}, None
    for kind in ("imm", "steady", "manoeuvre"):
        lateral, p = _track_lateral(kind, z, times, R)
        error[kind] = lateral - truth[1:, 1]
        if kind == "imm":
            manoeuvre = p
    assert manoeuvre is not None
    t = times[1:]
    keeping = (t >= 3.0) & (t < 10.0) | (t >= 17.0)
    changing = (t >= 10.0) & (t < 14.0)

    def rmse(kind: str, mask: np.ndarray) -> float:
        return float(np.sqrt(np.mean(error[kind][mask] ** 2)))

    assert rmse("imm", keeping) < 0.8 * rmse("manoeuvre", keeping)
    assert rmse("imm", changing) < 0.6 * rmse("steady", changing)
    assert rmse("imm", changing) < 1.5 * rmse("manoeuvre", changing)
    assert np.median(manoeuvre[(t >= 3.0) & (t < 10.0)]) < 0.1
    assert manoeuvre[changing].max() > 0.5
    assert np.median(manoeuvre[t >= 20.0]) < 0.1


def test_a_widened_prior_is_committed_to_every_mode() -> None:
    bank = IMMStateBank(SOJOURN_S)
    slots = np.array([bank.add([0.0, 0.0, 25.0, 0.0], np.eye(4), 0.0)])
    bank.update(slots, np.array([[0.1, 0.2]]), np.eye(2)[None] * 0.04)
    x, P = bank.predicted(slots, 0.5, ALONG, ACROSS)
    # committed as predicted: the stored mixture is the prediction, the modes stay apart
    bank.commit_prior(slots, x, P, 0.5)
    np.testing.assert_allclose(bank.states(slots), x, atol=1e-12)
    np.testing.assert_allclose(bank.covariances(slots), P, atol=1e-12)
    P_modes = bank._Pm[slots[0]]
    assert P_modes[1, 3, 3] > 2.0 * P_modes[0, 3, 3]  # the manoeuvre mode: vy far less certain
    # widened by the tracker (a track taken up after a gap): the widening reaches the mixture
    bank2 = IMMStateBank(SOJOURN_S)
    slots2 = np.array([bank2.add([0.0, 0.0, 25.0, 0.0], np.eye(4), 0.0)])
    bank2.update(slots2, np.array([[0.1, 0.2]]), np.eye(2)[None] * 0.04)
    x2, P2 = bank2.predicted(slots2, 0.5, ALONG, ACROSS)
    P2 = P2.copy()
    P2[0, :2, :2] += 4.0 * np.eye(2)
    bank2.commit_prior(slots2, x2, P2, 0.5)
    np.testing.assert_allclose(bank2.covariances(slots2), P2, atol=1e-12)
    # a stamp the last prediction was not made to: every mode at the given state
    bank2.commit_prior(slots2, x2, P2, 0.7)
    np.testing.assert_allclose(bank2.states(slots2), x2, atol=1e-12)
    np.testing.assert_allclose(bank2.covariances(slots2), P2, atol=1e-12)


def test_slots_are_reused_and_copied_whole() -> None:
    bank = IMMStateBank(SOJOURN_S, capacity=1)
    a = bank.add([0.0, 0.0, 1.0, 0.0], np.eye(4), 0.0)
    b = bank.add([5.0, 0.0, 1.0, 0.0], 2.0 * np.eye(4), 1.0)
    assert bank.capacity >= 2 and len(bank) == 2
    bank.update(np.array([b]), np.array([[5.5, 0.5]]), np.eye(2)[None])
    bank.copy_slot(b, a)
    for read in (bank.states, bank.covariances, bank.stamps_s, bank.mode_probabilities):
        np.testing.assert_array_equal(read(np.array([a])), read(np.array([b])))
    bank.remove(b)
    with pytest.raises(KeyError):
        bank.remove(b)
    assert bank.add([0.0, 0.0, 0.0, 0.0], np.eye(4), 2.0) == b
    with pytest.raises(ValueError, match="sojourn"):
        IMMStateBank((10.0, 0.0))


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    lidar_std=st.floats(0.01, 0.5),
    camera_std=st.floats(0.2, 20.0),
    gap=st.floats(0.001, 2.0),
)
def test_the_mixture_covariance_stays_symmetric_positive_definite(
    seed: int, lidar_std: float, camera_std: float, gap: float
) -> None:
    rng = np.random.default_rng(seed)
    bank = IMMStateBank(SOJOURN_S)
    slots = np.array([bank.add([0.0, 0.0, 30.0, 0.0], np.diag([1.0, 1.0, 100.0, 4.0]), 0.0)])
    t = 0.0
    for k in range(200):
        t += gap if k % 50 == 49 else float(rng.uniform(0.0, 0.1))
        bank.predict_to(slots, t, ALONG, ACROSS, 0.1)
        std = lidar_std if k % 2 else camera_std
        z = bank.states(slots)[:, :2] + rng.normal(0.0, std, size=(1, 2))
        bank.update(slots, z, np.eye(2)[None] * std**2)
        if k % 3 == 0:  # a radar speed along the road
            H = np.array([[[0.0, 0.0, np.cos(0.1), np.sin(0.1)]]])
            bank.update(slots, np.array([[30.0 + rng.normal(0, 0.5)]]), np.array([[[0.25]]]), H)
        assert is_symmetric_positive_definite(bank.covariances(slots))
        mu = bank.mode_probabilities(slots)
        assert np.all(mu > 0.0) and abs(mu.sum() - 1.0) < 1e-12
