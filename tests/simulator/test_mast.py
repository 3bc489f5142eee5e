"""The real mast's model (issue 39): seeded set-up errors and clocks within their bounds and with
their stated spreads, sway and settling against closed forms, the bump, the parser, masts."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.purity import top_level_imports
from wz_shared.site import LidarIntrinsics, Pose, SensorMount, Site
from wz_simulator.sensors import mast as mast_module
from wz_simulator.sensors.mast import (
    HEIGHT_MAX_M,
    HEIGHT_STD_M,
    HORIZONTAL_MAX_M,
    HORIZONTAL_STD_M,
    TILT_MAX_DEG,
    TILT_STD_DEG,
    YAW_MAX_DEG,
    YAW_STD_DEG,
    Bump,
    Mast,
    MastModel,
    MountError,
    Settling,
    Sway,
    mast_groups,
)

DRAWS = 2000


def truncated_std(std: float, bound: float) -> float:
    """Closed form: the std of N(0, std^2) truncated to [-bound, bound]."""
    k = bound / std
    density = math.exp(-0.5 * k * k) / math.sqrt(2.0 * math.pi)
    mass = math.erf(k / math.sqrt(2.0))
    return std * math.sqrt(1.0 - 2.0 * k * density / mass)


def lidar(sensor_id: str, x: float, y: float, z: float, yaw: float = 0.0) -> SensorMount:
    return SensorMount(
        sensor_id=sensor_id,
        pose=Pose(x_m=x, y_m=y, z_m=z, yaw_deg=yaw),
        intrinsics=LidarIntrinsics(),
        rate_hz=10.0,
    )


def still_mast(mounts: list[SensorMount], sway: Sway, rate_deg_per_h: float = 0.0) -> Mast:
    return Mast(
        sensor_ids=tuple(m.sensor_id for m in mounts),
        top_z_m=max(m.pose.z_m for m in mounts),
        sway=sway,
        settling=Settling(rate_deg_per_h, 0.0),
    )


def angle_between_deg(a: np.ndarray, b: np.ndarray) -> float:
    cosine = (np.trace(a.T @ b) - 1.0) / 2.0
    return math.degrees(math.acos(max(-1.0, min(1.0, cosine))))


# --- the set-up errors and clocks ---------------------------------------------------------------


def test_a_draw_depends_only_on_the_seed_and_the_sensor() -> None:
    assert MountError.draw(7, "camera-mast", "camera") == MountError.draw(
        7, "camera-mast", "camera"
    )
    assert MountError.draw(7, "camera-mast", "camera") != MountError.draw(
        8, "camera-mast", "camera"
    )
    assert MountError.draw(7, "camera-mast", "camera") != MountError.draw(7, "radar-mast", "camera")


def test_a_site_draws_each_sensor_its_own_error_reproducibly(site: Site) -> None:
    first, again = MastModel.draw(site, 13), MastModel.draw(site, 13)
    assert first == again
    errors = [first.error(m.sensor_id) for m in site.sensors]
    assert len({e.yaw_deg for e in errors}) == len(errors)
    # One sensor's draw does not depend on which others the site has.
    alone = site.model_copy(update={"sensors": site.sensors[1:2]})
    sensor = site.sensors[1].sensor_id
    assert MastModel.draw(alone, 13).error(sensor) == first.error(sensor)
    assert MastModel.draw(site, 14) != first


def test_errors_keep_their_bounds_and_spreads_over_many_seeds() -> None:
    draws = [MountError.draw(seed, "camera-mast", "camera") for seed in range(DRAWS)]
    columns = {
        "yaw": ([d.yaw_deg for d in draws], YAW_STD_DEG, YAW_MAX_DEG),
        "pitch": ([d.pitch_deg for d in draws], TILT_STD_DEG, TILT_MAX_DEG),
        "roll": ([d.roll_deg for d in draws], TILT_STD_DEG, TILT_MAX_DEG),
        "east": ([d.dx_m for d in draws], HORIZONTAL_STD_M, HORIZONTAL_MAX_M),
        "north": ([d.dy_m for d in draws], HORIZONTAL_STD_M, HORIZONTAL_MAX_M),
        "up": ([d.dz_m for d in draws], HEIGHT_STD_M, HEIGHT_MAX_M),
    }
    for name, (values, std, bound) in columns.items():
        sample = np.asarray(values)
        assert np.abs(sample).max() <= bound, name
        expected = truncated_std(std, bound)
        # Sample std of 2000 draws: within 5 % of the truncated normal's (its error ~1.6 %).
        assert abs(sample.std() - expected) < 0.05 * expected, (name, sample.std(), expected)
        assert abs(sample.mean()) < 4.0 * expected / math.sqrt(DRAWS), name
        # Redrawn, not clipped: nothing piles up on the bound.
        assert np.count_nonzero(np.abs(sample) == bound) == 0, name
    yaw = np.asarray(columns["yaw"][0])
    assert 0.8 <= yaw.std() <= 1.2 and np.abs(yaw).max() <= 3.0  # the issue's words


def test_clock_offsets_by_kind() -> None:
    camera = np.array([MountError.draw(s, "cam", "camera").clock_offset_s for s in range(DRAWS)])
    radar = np.array([MountError.draw(s, "radar", "radar").clock_offset_s for s in range(DRAWS)])
    lidar_offsets = {MountError.draw(s, "lidar", "lidar").clock_offset_s for s in range(200)}
    assert camera.min() >= 0.03 and camera.max() <= 0.15
    assert abs(camera.mean() - 0.09) < 0.005 and abs(camera.std() - 0.12 / math.sqrt(12)) < 0.003
    assert radar.min() >= 0.0 and radar.max() <= 0.05 and abs(radar.mean() - 0.025) < 0.002
    assert lidar_offsets == {0.0}


def test_the_mounted_pose_adds_the_error_and_nothing_else(site: Site) -> None:
    model = MastModel.draw(site, 3)
    for mount in site.sensors:
        error, mounted = model.error(mount.sensor_id), model.mounted(mount)
        assert mounted.sensor_id == mount.sensor_id and mounted.intrinsics == mount.intrinsics
        pose, nominal = mounted.pose, mount.pose
        assert pose.x_m == pytest.approx(nominal.x_m + error.dx_m)
        assert pose.z_m == pytest.approx(nominal.z_m + error.dz_m)
        assert pose.yaw_deg == pytest.approx(nominal.yaw_deg + error.yaw_deg)
        assert pose.roll_deg == pytest.approx(nominal.roll_deg + error.roll_deg)
    assert site.sensors[0].pose == site.model_copy().sensors[0].pose  # the site is untouched


# --- sway, settling, bump -----------------------------------------------------------------------


def test_sway_twist_and_lean_follow_the_pose_conventions() -> None:
    """A level sensor facing east on a mast that only twists turns its yaw by the twist; one
    whose mast leans towards where it faces pitches down; towards its right, rolls right down."""
    mount = lidar("head", 0.0, 0.0, 8.0, yaw=0.0)
    t_s = 0.4
    twist_only = Sway(0.0, 0.5, 2.0, 0.0, 0.3, 0.0)
    model = MastModel({}, (still_mast([mount], twist_only),))
    pose = model.pose_at(mount, t_s)
    assert pose.yaw_deg == pytest.approx(twist_only.twist_deg(t_s), abs=1e-9)
    assert twist_only.twist_deg(t_s) == pytest.approx(0.5 * math.sin(2 * math.pi * 0.2 + 0.3))
    assert pose.pitch_deg == pytest.approx(0.0, abs=1e-12)

    forward = Sway(0.4, 0.0, 2.0, 0.7, 0.0, 0.0)  # leans east: where the sensor faces
    pose = MastModel({}, (still_mast([mount], forward),)).pose_at(mount, t_s)
    assert pose.pitch_deg == pytest.approx(-forward.lean_deg(t_s), abs=1e-9)
    assert pose.roll_deg == pytest.approx(0.0, abs=1e-9)

    right = Sway(0.4, 0.0, 2.0, 0.7, 0.0, -90.0)  # leans south: the sensor's right
    pose = MastModel({}, (still_mast([mount], right),)).pose_at(mount, t_s)
    assert pose.roll_deg == pytest.approx(right.lean_deg(t_s), abs=1e-9)
    assert pose.pitch_deg == pytest.approx(0.0, abs=1e-9)


def test_sensors_on_one_mast_share_its_sway_scaled_by_their_height() -> None:
    top, low = lidar("top", 0.0, 0.0, 8.0), lidar("low", 0.3, 0.0, 2.0)
    sway = Sway(0.08, 0.05, 1.7, 0.2, 1.1, 30.0)
    model = MastModel({}, (still_mast([top, low], sway),))
    for t_s in (0.1, 0.6, 1.3):
        top_turn = angle_between_deg(model.rotation_at(top, t_s), top.pose.rotation())
        low_turn = angle_between_deg(model.rotation_at(low, t_s), low.pose.rotation())
        assert low_turn == pytest.approx(top_turn * 2.0 / 8.0, rel=1e-6)
        # Periodic: the same turn one period later.
        later = model.rotation_at(top, t_s + sway.period_s)
        np.testing.assert_allclose(later, model.rotation_at(top, t_s), atol=1e-12)
        assert top_turn <= math.hypot(0.08, 0.05) + 1e-9


def test_drawn_sway_and_settling_are_within_the_issues_figures(site: Site) -> None:
    for seed in range(200):
        (mast,) = MastModel.draw(site, seed).masts
        assert set(mast.sensor_ids) == {m.sensor_id for m in site.sensors}
        assert 0.02 <= mast.sway.lean_amplitude_deg <= 0.1
        assert 0.02 <= mast.sway.twist_amplitude_deg <= 0.1
        assert 1.0 <= mast.sway.period_s <= 4.0
        assert 0.0 <= mast.settling.rate_deg_per_h <= 0.2
        # Small in a 10-minute run, at most 0.2 deg in an hour.
        assert mast.settling.lean_deg(600.0) <= 0.2 / 6.0 + 1e-12
    (mast,) = MastModel.draw(site, 5).masts
    assert mast.settling.lean_deg(3600.0) == pytest.approx(mast.settling.rate_deg_per_h)
    assert mast.settling.lean_deg(0.0) == 0.0


def test_settling_leans_linearly_in_time() -> None:
    mount = lidar("head", 0.0, 0.0, 6.0)
    model = MastModel({}, (still_mast([mount], Sway(0.0, 0.0, 1.0, 0.0, 0.0, 0.0), 0.18),))
    turns = [
        angle_between_deg(model.rotation_at(mount, t), mount.pose.rotation())
        for t in (0.0, 1800.0, 3600.0)
    ]
    assert turns == pytest.approx([0.0, 0.09, 0.18], abs=1e-9)


def test_the_bump_turns_its_sensor_at_its_time_and_not_before(site: Site) -> None:
    mount = site.sensors[1]
    bump = Bump(mount.sensor_id, 12.0, 2.5)
    plain, bumped = MastModel.draw(site, 9), MastModel.draw(site, 9, bump)
    for t_s in (0.0, 11.99):
        np.testing.assert_array_equal(bumped.rotation_at(mount, t_s), plain.rotation_at(mount, t_s))
    for t_s in (12.0, 30.0):
        # Pre-multiplied by a rotation of 2.5 deg about the vertical: the yaw adds exactly.
        turn = bumped.rotation_at(mount, t_s) @ plain.rotation_at(mount, t_s).T
        assert math.degrees(math.atan2(turn[1, 0], turn[0, 0])) == pytest.approx(2.5)
        assert turn[2, 2] == pytest.approx(1.0)
    other = site.sensors[0]
    np.testing.assert_array_equal(bumped.rotation_at(other, 30.0), plain.rotation_at(other, 30.0))
    assert bumped.mounted(mount, 30.0).pose.yaw_deg == pytest.approx(
        plain.mounted(mount).pose.yaw_deg + 2.5
    )


def test_a_bump_of_a_sensor_the_site_lacks_is_refused(site: Site) -> None:
    with pytest.raises(ValueError, match="no such sensor"):
        MastModel.draw(site, 1, Bump("nowhere", 10.0))


def test_bump_parsing() -> None:
    assert Bump.parse("camera-mast@300") == Bump("camera-mast", 300.0, 2.0)
    assert Bump.parse("camera-mast@300:-1.5", after_s=60.0) == Bump("camera-mast", 360.0, -1.5)
    for text in ("camera-mast", "@30", "camera-mast@", "camera-mast@x", "c@-1", "c@3:y", "c@inf"):
        with pytest.raises(ValueError, match="SENSOR@SECONDS"):
            Bump.parse(text)


def test_pose_at_reads_back_the_mounted_pose_without_motion(site: Site) -> None:
    model = MastModel.draw(site, 21)
    still = MastModel(model.errors)
    for mount in site.sensors:
        pose, mounted = still.pose_at(mount, 100.0), still.mounted(mount).pose
        assert pose.yaw_deg == pytest.approx(mounted.yaw_deg, abs=1e-9)
        assert pose.pitch_deg == pytest.approx(mounted.pitch_deg, abs=1e-9)
        assert pose.roll_deg == pytest.approx(mounted.roll_deg, abs=1e-9)
        np.testing.assert_array_equal(still.rotation_at(mount, 5.0), mounted.rotation())


def test_sensors_far_apart_stand_on_separate_masts() -> None:
    a, b, c = lidar("a", 0.0, 0.0, 6.0), lidar("b", 1.5, 0.0, 5.0), lidar("c", 3.0, 0.0, 4.0)
    far = lidar("far", 80.0, 0.0, 6.0)
    groups = mast_groups([a, far, c, b])  # c joins a through b
    assert [[m.sensor_id for m in g] for g in groups] == [["a", "c", "b"], ["far"]]


def test_describe_and_log_lines_name_every_sensor(site: Site) -> None:
    model = MastModel.draw(site, 4, Bump(site.sensors[0].sensor_id, 5.0))
    described = model.describe()
    assert set(described["sensors"]) == {m.sensor_id for m in site.sensors}
    assert described["bump"] == {
        "sensor_id": site.sensors[0].sensor_id,
        "at_s": 5.0,
        "yaw_deg": 2.0,
    }
    lines = model.lines()
    assert len(lines) == len(site.sensors) + 2
    assert all(m.sensor_id in "".join(lines) for m in site.sensors)


def test_the_model_imports_no_io_library() -> None:
    imported = top_level_imports(mast_module)
    assert not imported & {"zenoh", "fastapi", "pathlib", "os", "io", "socket", "requests"}
