"""The update step's measurement models (wz_fusion_tracker.updater): the capture offset's
``H = [I delta I]``, the radar speed gate and what the update reports."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wz_fusion_tracker.kalman import TrackStateBank
from wz_fusion_tracker.settings import TrackerSettings
from wz_fusion_tracker.updater import position_matrices, update_matched


def bank_of(speeds: list[float]) -> tuple[TrackStateBank, np.ndarray]:
    """Tracks at x = 0..K along east at ``speeds``, velocity std 1 m/s, position 0.5 m."""
    bank = TrackStateBank()
    P = np.diag([0.25, 0.25, 1.0, 1.0])
    slots = np.array(
        [bank.add(np.array([float(k), 0.0, v, 0.0]), P, 0.0) for k, v in enumerate(speeds)]
    )
    return bank, slots


def test_position_matrix_sees_the_velocity_over_the_capture_offset() -> None:
    (H,) = position_matrices(np.array([0.04]))
    assert H.tolist() == [[1.0, 0.0, 0.04, 0.0], [0.0, 1.0, 0.0, 0.04]]


def test_radar_speeds_within_the_gate_are_used_and_a_wrong_echo_is_refused() -> None:
    settings = TrackerSettings()
    bank, slots = bank_of([20.0, 20.0, 20.0])
    z = bank.states(slots)[:, :2].copy()
    R = np.repeat(np.eye(2)[None] * 0.04, 3, axis=0)
    east = lambda xy: np.zeros(len(xy))  # noqa: E731 - the road runs east everywhere
    # the first echo agrees, the second is the next lane's car 12 m/s slower, the third none
    outcome = update_matched(
        bank, settings, slots, z, R, None, east, np.array([20.5, 8.0, math.nan])
    )
    assert (outcome.updated, outcome.speeds_used, outcome.speeds_rejected) == (3, 1, 1)
    vx = bank.states(slots)[:, 2]
    assert vx[0] == pytest.approx(20.0 + 0.5 * 1.0 / (1.0 + settings.speed_std_mps**2), abs=0.05)
    assert vx[1] == pytest.approx(20.0) and vx[2] == pytest.approx(20.0)
    assert outcome.road_heading_rad is not None and outcome.road_heading_rad.tolist() == [0.0] * 3
    # No road prior: positions only, and no heading reported.
    bank, slots = bank_of([20.0])
    bare = update_matched(bank, settings, slots, z[:1], R[:1], None, None, np.array([8.0]))
    assert (bare.updated, bare.speeds_used, bare.road_heading_rad) == (1, 0, None)
