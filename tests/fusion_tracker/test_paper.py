"""The paper's pipeline: nearest matching (nearest first, never reused, gated), sequential
updates equal to one stacked update, the average baseline, fused identity through frames where
one sensor is missing, and fusion beating each biased sensor on a seeded trajectory."""

from __future__ import annotations

import numpy as np
import pytest

from tests.purity import top_level_imports
from wz_fusion_tracker import paper
from wz_fusion_tracker.kalman import position_h, predict, update
from wz_fusion_tracker.paper import (
    Observation,
    PaperFusion,
    PaperFusionSettings,
    match_nearest,
    run_paper_pipeline,
    simple_average,
    smooth_object_tracks,
    smooth_sensor_tracks,
)
from wz_shared.motion import cv_transition, white_noise_q

SETTINGS = PaperFusionSettings()
CAMERA, LIDAR = SETTINGS.camera_sensor_id, SETTINGS.lidar_sensor_id


def obs(object_id: int, x_m: float, y_m: float, stamp_s: float = 0.0) -> Observation:
    return Observation(stamp_s=stamp_s, object_id=object_id, x_m=x_m, y_m=y_m)


def test_core_imports_no_io_library() -> None:
    assert top_level_imports(paper).isdisjoint({"zenoh", "fastapi", "requests", "io"})


def test_settings_refuse_one_sensor_in_both_roles_and_unknown_sensors() -> None:
    with pytest.raises(ValueError, match="two sensors"):
        PaperFusionSettings(camera_sensor_id="x", lidar_sensor_id="x")
    with pytest.raises(ValueError, match="radar-mast"):
        SETTINGS.role_of("radar-mast")
    np.testing.assert_allclose(SETTINGS.measurement_covariance("lidar"), np.diag([0.09, 0.09]))


# ----------------------------------------------------------------------------- matching


def test_matching_takes_the_nearest_pair_first_and_never_reuses_an_object() -> None:
    camera = [obs(1, 0.0, 0.0), obs(2, 3.0, 0.0)]
    # LiDAR 10 is 0.5 m from camera 1 and 2.5 m from camera 2; LiDAR 11 is 1.0 m from camera 1
    # and 2.0 m from camera 2. Greedy: (1, 10) at 0.5 m, then (2, 11) at 2.0 m.
    lidar = [obs(10, 0.5, 0.0), obs(11, 1.0, 0.0)]
    assert match_nearest(camera, lidar, max_distance_m=3.0) == [(0, 0), (1, 1)]
    # With a 1.5 m limit the second pair is refused; nothing is used twice.
    assert match_nearest(camera, lidar, max_distance_m=1.5) == [(0, 0)]
    # Three camera objects around one LiDAR object: only the nearest gets it.
    crowd = [obs(1, 2.0, 0.0), obs(2, 0.0, 0.4), obs(3, -1.0, 0.0)]
    assert match_nearest(crowd, [obs(10, 0.0, 0.0)], max_distance_m=5.0) == [(1, 0)]
    assert match_nearest([], lidar, 3.0) == []


def test_simple_average_is_the_midpoint() -> None:
    camera = [obs(1, 0.0, 0.0), obs(2, 10.0, 4.0)]
    lidar = [obs(10, 12.0, 6.0), obs(11, 2.0, -2.0)]
    np.testing.assert_allclose(
        simple_average(camera, lidar, [(0, 1), (1, 0)]), [[1.0, -1.0], [11.0, 5.0]]
    )
    assert simple_average(camera, lidar, []).shape == (0, 2)


# ----------------------------------------------------------------------------- fusion


def test_sequential_camera_then_lidar_update_equals_the_stacked_update() -> None:
    rng = np.random.default_rng(2)
    x = np.array([100.0, 3.0, 25.0, 0.5])
    P = np.diag([4.0, 1.0, 30.0, 2.0])
    x_p, P_p = predict(x, P, cv_transition(0.1), white_noise_q(0.1, 2.0))
    R_camera = np.array([[2.0, 0.3], [0.3, 0.5]])
    R_lidar = np.array([[0.1, -0.02], [-0.02, 0.05]])
    z_camera, z_lidar = rng.normal([102.5, 3.0], 1.0), rng.normal([102.5, 3.0], 0.3)
    H = position_h()
    x_seq, P_seq = update(x_p, P_p, z_camera, H, R_camera)
    x_seq, P_seq = update(x_seq, P_seq, z_lidar, H, R_lidar)
    # One update with z = [z_c; z_l], H = [H; H], R = blockdiag(R_c, R_l).
    R_stacked = np.zeros((4, 4))
    R_stacked[:2, :2], R_stacked[2:, 2:] = R_camera, R_lidar
    x_batch, P_batch = update(
        x_p, P_p, np.concatenate([z_camera, z_lidar]), np.vstack([H, H]), R_stacked
    )
    np.testing.assert_allclose(x_seq, x_batch, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(P_seq, P_batch, rtol=1e-9, atol=1e-9)

    # PaperFusion's step does the same: start it, then one frame with both sensors.
    settings = PaperFusionSettings(camera_std_xy_m=(1.2, 0.8), lidar_std_xy_m=(0.3, 0.25))
    fusion = PaperFusion(settings)
    first = fusion.step(0.0, [obs(1, 100.0, 3.0)], [obs(7, 100.2, 3.1)])
    assert [(e.fused_id, e.roles) for e in first] == [(1, ("camera", "lidar"))]
    second = fusion.step(0.1, [obs(1, *z_camera)], [obs(7, *z_lidar)])
    R_c, R_l = (settings.measurement_covariance(role) for role in ("camera", "lidar"))
    x_p, P_p = predict(
        [first[0].x_m, first[0].y_m, first[0].vx_mps, first[0].vy_mps],
        first[0].P,
        cv_transition(0.1),
        white_noise_q(0.1, settings.sigma_a_mps2),
    )
    R_stacked[:2, :2], R_stacked[2:, 2:] = R_c, R_l
    x_batch, P_batch = update(
        x_p, P_p, np.concatenate([z_camera, z_lidar]), np.vstack([H, H]), R_stacked
    )
    np.testing.assert_allclose(
        [second[0].x_m, second[0].y_m, second[0].vx_mps, second[0].vy_mps], x_batch, atol=1e-9
    )
    np.testing.assert_allclose(second[0].P, P_batch, atol=1e-9)
    assert second[0].average_xy_m == pytest.approx(tuple((z_camera + z_lidar) / 2.0))


def test_fused_identity_survives_a_frame_with_one_sensor_and_unmatched_objects_start_their_own() -> (
    None
):
    fusion = PaperFusion(SETTINGS)
    fusion.step(0.0, [obs(1, 0.0, 0.0)], [obs(5, 0.2, 0.0)])
    lidar_only = fusion.step(0.05, [], [obs(5, 1.5, 0.0)])
    assert [(e.fused_id, e.roles, e.camera_object_id) for e in lidar_only] == [(1, ("lidar",), 1)]
    assert lidar_only[0].average_xy_m is None
    # A far camera object and an unseen LiDAR object: two new fused objects, one sensor each.
    later = fusion.step(
        0.1, [obs(1, 2.5, 0.0), obs(2, 50.0, 0.0)], [obs(5, 2.6, 0.0), obs(9, -40.0, 0.0)]
    )
    assert [(e.fused_id, e.roles) for e in later] == [
        (1, ("camera", "lidar")),
        (2, ("camera",)),
        (3, ("lidar",)),
    ]
    with pytest.raises(ValueError, match="before the previous"):
        fusion.step(0.05, [], [])


def synthetic_run(
    seed: int, duration_s: float = 8.0
) -> tuple[dict[str, list[Observation]], dict[float, tuple[float, float]]]:
    """One vehicle at constant velocity seen by a biased, noisy camera and a biased, less noisy
    LiDAR at 20 Hz (the paper's synchronous simulation); the truth by stamp."""
    rng = np.random.default_rng(seed)
    stamps = np.round(np.arange(0.0, duration_s, 0.05), 6)
    truth = {float(t): (800.0 + 25.0 * t, 4.0 + 0.1 * t) for t in stamps}
    camera_bias, lidar_bias = np.array([1.5, -0.4]), np.array([-0.6, 0.3])
    camera, lidar = [], []
    for t in stamps:
        position = np.array(truth[float(t)])
        x_c, y_c = position + camera_bias + rng.normal(0.0, 1.0, 2)
        x_l, y_l = position + lidar_bias + rng.normal(0.0, 0.3, 2)
        camera.append(obs(3, float(x_c), float(y_c), float(t)))
        lidar.append(obs(8, float(x_l), float(y_l), float(t)))
    return {CAMERA: camera, LIDAR: lidar}, truth


def rmse(
    points: list[tuple[float, float, float]], truth: dict[float, tuple[float, float]]
) -> float:
    errors = [np.hypot(x - truth[t][0], y - truth[t][1]) for t, x, y in points if t >= 1.0]
    return float(np.sqrt(np.mean(np.square(errors))))


def test_fusion_of_two_biased_noisy_sensors_beats_each_sensor() -> None:
    observations, truth = synthetic_run(seed=4)
    estimates = run_paper_pipeline(observations, SETTINGS)
    assert {e.fused_id for e in estimates} == {1}
    assert all(e.roles == ("camera", "lidar") for e in estimates)
    fused = rmse([(e.stamp_s, e.x_m, e.y_m) for e in estimates], truth)
    averaged = rmse(
        [(e.stamp_s, *e.average_xy_m) for e in estimates if e.average_xy_m is not None], truth
    )
    camera = rmse([(o.stamp_s, o.x_m, o.y_m) for o in observations[CAMERA]], truth)
    lidar = rmse([(o.stamp_s, o.x_m, o.y_m) for o in observations[LIDAR]], truth)
    assert fused < lidar < camera
    assert fused < averaged


def test_per_sensor_smoothing_reduces_each_sensors_noise_and_keeps_order() -> None:
    observations, truth = synthetic_run(seed=6)
    shuffled = list(reversed(observations[CAMERA]))
    smoothed = smooth_object_tracks(shuffled, np.eye(2), 2.0, 15.0)
    assert [o.stamp_s for o in smoothed] == [o.stamp_s for o in shuffled]
    # Remove the bias to compare the noise alone.
    unbiased = {t: (x + 1.5, y - 0.4) for t, (x, y) in truth.items()}
    raw_rmse = rmse([(o.stamp_s, o.x_m, o.y_m) for o in shuffled], unbiased)
    smooth_rmse = rmse([(o.stamp_s, o.x_m, o.y_m) for o in smoothed], unbiased)
    assert smooth_rmse < 0.6 * raw_rmse
    by_sensor = smooth_sensor_tracks(observations, SETTINGS)
    assert set(by_sensor) == {CAMERA, LIDAR}
    assert len(by_sensor[LIDAR]) == len(observations[LIDAR])


def test_asynchronous_sensors_fuse_with_a_frame_tolerance() -> None:
    # Camera at 10 Hz offset by 20 ms from the 20 Hz LiDAR: with a 25 ms tolerance the
    # camera's frames hold both sensors, the others the LiDAR alone; one fused object.
    lidar = [obs(8, 25.0 * t, 0.0, t) for t in np.round(np.arange(0.0, 2.0, 0.05), 6)]
    camera = [obs(3, 25.0 * t, 0.0, t) for t in np.round(np.arange(0.02, 2.0, 0.1), 6)]
    settings = PaperFusionSettings(frame_tolerance_s=0.025, smooth_per_sensor=False)
    estimates = run_paper_pipeline({CAMERA: camera, LIDAR: lidar}, settings)
    assert {e.fused_id for e in estimates} == {1}
    assert sum(e.roles == ("camera", "lidar") for e in estimates) == len(camera)
    assert sum(e.roles == ("lidar",) for e in estimates) == len(lidar) - len(camera)
