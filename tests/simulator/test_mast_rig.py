"""The rig on a real mast (issue 39): off, the very frames of the nominal rig; on, each sensor
renders from its true pose at its capture time (a wall's plane in the LiDAR's frame turned and
shifted as the drawn error says; the camera's turned frame where a pinhole at the true pose
projects), each frame stamped by its sensor's own late clock, the bump at its time and not
before, and nothing of the error in what is published."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pytest

from tests.simulator.test_camera import car_boxes, exact_model, make_mount
from wz_shared.messages import DriverProfile, VehicleClass, VehicleTruth
from wz_shared.site import DEFAULT_SITE_PATH, CameraIntrinsics, Pose, Site, load_site
from wz_simulator.node import sensor_rig
from wz_simulator.sensors.camera import PinholeCamera
from wz_simulator.sensors.mast import Bump, Mast, MastModel, MountError, Settling, Sway
from wz_simulator.sensors.rig import (
    CameraOutput,
    LidarOutput,
    RadarOutput,
    SensorOutput,
    SensorRig,
)
from wz_simulator.sensors.scene import WEATHER_PRESETS, Box, Material, StaticScene, static_scene
from wz_simulator.settings import SimulatorSettings

DAY = WEATHER_PRESETS["day"]
SEED = 5
LIDAR, CAMERA, RADAR = "lidar-mast", "camera-mast", "radar-mast"
#: The wall's yaw: its length runs 15 deg north of east, 40 m south of the mast.
WALL_YAW_RAD = math.radians(15.0)


@pytest.fixture(scope="module")
def small_site(site: Site) -> Site:
    """The default site with a small camera and a LiDAR of 1024 columns: the same code, faster."""
    sensors = []
    for mount in site.sensors:
        if mount.kind == "camera":
            small = CameraIntrinsics(width_px=320, height_px=240, horizontal_fov_deg=90.0)
            mount = mount.model_copy(update={"intrinsics": small})
        elif mount.kind == "lidar":
            fewer = mount.intrinsics.model_copy(update={"azimuth_steps": 1024})
            mount = mount.model_copy(update={"intrinsics": fewer})
        sensors.append(mount)
    return site.model_copy(update={"sensors": sensors})


@pytest.fixture(scope="module")
def scene(small_site: Site) -> StaticScene:
    return static_scene(small_site)


@pytest.fixture(scope="module")
def wall_site(small_site: Site) -> Site:
    """The small site with a LiDAR without range noise: a plane's fit is then exact."""
    sensors = [
        mount.model_copy(
            update={"intrinsics": mount.intrinsics.model_copy(update={"range_noise_std_m": 0.0})}
        )
        if mount.kind == "lidar"
        else mount
        for mount in small_site.sensors
    ]
    return small_site.model_copy(update={"sensors": sensors})


@pytest.fixture(scope="module")
def wall_scene(wall_site: Site) -> StaticScene:
    """One concrete wall 40 m south of the mast, 30 m long and 10 m high, nothing else (the
    LiDAR adds its ground plane)."""
    lidar_pose = wall_site.sensor(LIDAR).pose
    wall = Box(
        (lidar_pose.x_m, lidar_pose.y_m - 40.0, 5.0),
        (30.0, 0.5, 10.0),
        WALL_YAW_RAD,
        Material.CONCRETE,
        (150, 150, 150),
    )
    return StaticScene(boxes=[wall], ground=[])


def wall_normal_site() -> np.ndarray:
    """The wall's unit normal in the site frame, towards the mast (north of it)."""
    return np.array([-math.sin(WALL_YAW_RAD), math.cos(WALL_YAW_RAD), 0.0])


def traffic(site: Site, t_s: float) -> list[VehicleTruth]:
    """Six vehicles approaching the mast at 30 m/s on both lanes, a truck among them."""
    vehicles = []
    for i, (start_m, lane) in enumerate([(850, 0), (900, 1), (930, 0), (955, 1), (800, 0)]):
        station = start_m + 30.0 * t_s
        offset = site.lanes[lane].center_offset_m
        x, y = site.road_frame.to_site(station, offset)
        truck = i == 1
        vehicles.append(
            VehicleTruth(
                vehicle_id=f"v{i}",
                vehicle_class=VehicleClass.TRUCK if truck else VehicleClass.CAR,
                x_m=float(x),
                y_m=float(y),
                heading_rad=float(site.road_frame.heading_at(station)),
                speed_mps=30.0,
                accel_mps2=0.0,
                length_m=16.5 if truck else 4.5,
                width_m=2.5 if truck else 1.8,
                height_m=4.0 if truck else 1.5,
                lane_index=lane,
                station_m=float(station),
                offset_m=offset,
                driver_profile=DriverProfile.NORMAL,
            )
        )
    return vehicles


def run(rig: SensorRig, site: Site, steps: int, step_s: float = 0.05) -> list[SensorOutput]:
    """Every frame of ``steps`` truth steps, as the node fires them."""
    outputs: list[SensorOutput] = []
    for step in range(1, steps + 1):
        t_s = step * step_s
        outputs += rig.fire(traffic(site, t_s), t_s)
    return outputs


def wall_plane(output: SensorOutput) -> tuple[np.ndarray, float]:
    """The wall's plane fitted to a LiDAR frame in its sensor frame: unit normal (towards the
    sensor) and ``n . p`` on it (minus the sensor's distance to it) [m]."""
    assert isinstance(output, LidarOutput)
    points = output.scan.points[:, :3].astype(np.float64)
    points = points[np.isfinite(points).all(axis=1)]
    # Above the ground (6 m below the sensor, +-1.6 m of tilt at 60 m) and near: the wall only.
    wall = points[(points[:, 2] > -4.0) & (np.linalg.norm(points, axis=1) < 60.0)]
    assert len(wall) > 1000
    for _ in range(2):  # fit, then again without the points off the face (its ends' faces)
        centre = wall.mean(axis=0)
        normal = np.linalg.svd(wall - centre)[2][-1]
        wall = wall[np.abs((wall - centre) @ normal) < 0.01]
    centre = wall.mean(axis=0)
    normal = np.linalg.svd(wall - centre)[2][-1]
    if normal @ centre > 0.0:
        normal = -normal
    return normal, float(normal @ centre)


def azimuth_deg(vector: np.ndarray) -> float:
    return math.degrees(math.atan2(vector[1], vector[0]))


def stamp_of(output: SensorOutput) -> float:
    """The stamp the frame is published with."""
    if isinstance(output, LidarOutput):
        return output.scan.meta.stamp
    if isinstance(output, CameraOutput):
        return output.meta.stamp
    return output.result.scan.stamp


def only(outputs: Sequence[SensorOutput], sensor_id: str) -> list[SensorOutput]:
    return [o for o in outputs if o.sensor_id == sensor_id]


def same_frame(a: SensorOutput, b: SensorOutput) -> bool:
    """Bit for bit, data, truth and metadata."""
    if isinstance(a, LidarOutput) and isinstance(b, LidarOutput):
        return (
            np.array_equal(a.scan.points, b.scan.points, equal_nan=True)
            and np.array_equal(a.scan.labels, b.scan.labels)
            and a.scan.boxes == b.scan.boxes
            and a.scan.meta == b.scan.meta
        )
    if isinstance(a, CameraOutput) and isinstance(b, CameraOutput):
        return (
            np.array_equal(a.frame.image, b.frame.image)
            and a.jpeg == b.jpeg
            and a.frame.labels == b.frame.labels
            and np.array_equal(a.frame.face_buffer, b.frame.face_buffer)
            and a.meta == b.meta
        )
    assert isinstance(a, RadarOutput) and isinstance(b, RadarOutput)
    return a.result == b.result


# --- off -----------------------------------------------------------------------------------------


def test_off_by_default() -> None:
    settings = SimulatorSettings()
    assert settings.mount_errors is False and settings.bump_sensor is None


def test_a_mast_without_errors_draws_the_nominal_frames_bit_for_bit(
    small_site: Site, scene: StaticScene
) -> None:
    """The mast's code path with nothing to add reproduces the rig without a mast (itself the
    rig as it was before the model: see the report of issue 39's change)."""
    nominal = SensorRig(small_site, DAY, SEED, scene=scene)
    still = SensorRig(small_site, DAY, SEED, scene=scene, mast=MastModel({}))
    a, b = run(nominal, small_site, 8), run(still, small_site, 8)
    assert [o.sensor_id for o in a] == [o.sensor_id for o in b] and len(a) == 21
    assert all(same_frame(x, y) for x, y in zip(a, b, strict=True))
    assert all(o.capture_s == stamp_of(o) for o in a + b)
    drawn = SensorRig(small_site, DAY, SEED, scene=scene, mast=MastModel.draw(small_site, SEED))
    c = run(drawn, small_site, 8)
    assert not any(same_frame(x, y) for x, y in zip(a, c, strict=True) if x.capture_s > 0.0)


# --- on: the LiDAR --------------------------------------------------------------------------------


def lidar_frame(site: Site, scene: StaticScene, mast: MastModel | None, index: int) -> LidarOutput:
    rig = SensorRig(site, DAY, SEED, sensor_ids=[LIDAR], scene=scene, mast=mast)
    output = rig.capture(LIDAR, index, index * 0.05, [], index * 0.05)
    assert isinstance(output, LidarOutput)
    return output


def test_the_lidar_sees_the_wall_turned_and_shifted_by_the_drawn_yaw_and_position(
    wall_site: Site, wall_scene: StaticScene
) -> None:
    error = MountError(yaw_deg=1.7, dx_m=0.3, dy_m=-0.4, dz_m=0.1)
    nominal_normal, nominal_offset = wall_plane(lidar_frame(wall_site, wall_scene, None, 2))
    mast = MastModel({LIDAR: error})
    normal, offset = wall_plane(lidar_frame(wall_site, wall_scene, mast, 2))
    # Read with the nominal pose, the wall has turned by minus the yaw error ...
    turned = (azimuth_deg(normal) - azimuth_deg(nominal_normal) + 180.0) % 360.0 - 180.0
    assert turned == pytest.approx(-error.yaw_deg, abs=0.001)
    # ... and moved nearer by the sensor's move towards it.
    towards = float(wall_normal_site() @ np.array([error.dx_m, error.dy_m, error.dz_m]))
    assert offset - nominal_offset == pytest.approx(-towards, abs=0.001)
    assert abs(towards) > 0.3  # a shift the tolerance could not hide


def test_the_lidar_renders_pitch_and_roll_errors_in_its_own_frame(
    wall_site: Site, wall_scene: StaticScene
) -> None:
    mount = wall_site.sensor(LIDAR)
    mast = MastModel({LIDAR: MountError(yaw_deg=-2.2, pitch_deg=1.3, roll_deg=-0.9, dx_m=0.2)})
    normal, _ = wall_plane(lidar_frame(wall_site, wall_scene, mast, 3))
    expected = mast.mounted(mount).pose.rotation().T @ wall_normal_site()
    assert math.degrees(math.acos(min(1.0, float(normal @ expected)))) < 0.001
    nominal = mount.pose.rotation().T @ wall_normal_site()
    assert math.degrees(math.acos(float(nominal @ expected))) > 2.0


def test_the_lidar_head_sways_frame_by_frame(wall_site: Site, wall_scene: StaticScene) -> None:
    """A strong sway, to see: each sweep renders at the orientation of its middle."""
    mount = wall_site.sensor(LIDAR)
    sway = Sway(0.6, 0.4, 1.2, 0.3, 1.9, 200.0)
    mast = MastModel({}, (Mast((LIDAR,), mount.pose.z_m, sway, Settling(0.0, 0.0)),))
    rig = SensorRig(wall_site, DAY, SEED, sensor_ids=[LIDAR], scene=wall_scene, mast=mast)
    normals = []
    for index in (4, 9, 14):
        output = rig.capture(LIDAR, index, index * 0.05, [], index * 0.05)
        normal, _ = wall_plane(output)
        middle_s = index * 0.05 + 0.5 / mount.rate_hz
        expected = mast.rotation_at(mount, middle_s).T @ wall_normal_site()
        assert math.degrees(math.acos(min(1.0, float(normal @ expected)))) < 0.001
        normals.append(normal)
    assert math.degrees(math.acos(float(normals[0] @ normals[1]))) > 0.1


# --- on: stamps -----------------------------------------------------------------------------------


def test_frames_carry_their_capture_time_plus_the_sensors_clock_offset(
    small_site: Site, scene: StaticScene
) -> None:
    offsets = {CAMERA: 0.1, RADAR: 0.04, LIDAR: 0.0}
    mast = MastModel({sensor: MountError(clock_offset_s=s) for sensor, s in offsets.items()})
    late = SensorRig(small_site, DAY, SEED, scene=scene, mast=mast)
    nominal = SensorRig(small_site, DAY, SEED, scene=scene)
    truth_s = 0.5
    vehicles = traffic(small_site, truth_s)
    for sensor, offset in offsets.items():
        index = 3 if sensor == RADAR else 2
        fire_s = index / small_site.sensor(sensor).rate_hz
        output = late.capture(sensor, index, fire_s, vehicles, truth_s)
        # The same frame as a perfect clock's captured at fire - offset, stamped fire.
        reference = nominal.capture(sensor, index, fire_s - offset, vehicles, truth_s)
        assert output.capture_s == pytest.approx(fire_s - offset)
        if isinstance(output, CameraOutput):
            assert isinstance(reference, CameraOutput)
            assert output.meta.stamp == fire_s
            assert output.meta.stamp == pytest.approx(output.frame.stamp + offset)
            assert np.array_equal(output.frame.image, reference.frame.image)
            assert output.frame.labels == reference.frame.labels
        elif isinstance(output, RadarOutput):
            assert isinstance(reference, RadarOutput)
            assert output.result.scan.stamp == fire_s
            assert output.result.scan.targets == reference.result.scan.targets
            assert len(output.result.scan.targets) > 0
        else:
            assert isinstance(output, LidarOutput) and isinstance(reference, LidarOutput)
            assert output.scan.meta.stamp == output.capture_s == fire_s  # synchronised
            assert same_frame(output, reference)
    # The offset shows: the camera's truth boxes move between the two captures.
    on_time = nominal.capture(CAMERA, 2, 0.2, vehicles, truth_s)
    stamped_late = late.capture(CAMERA, 2, 0.2, vehicles, truth_s)
    assert isinstance(on_time, CameraOutput) and isinstance(stamped_late, CameraOutput)
    assert on_time.frame.labels != stamped_late.frame.labels


def test_drawn_offsets_reach_the_schedule(small_site: Site, scene: StaticScene) -> None:
    mast = MastModel.draw(small_site, SEED)
    rig = SensorRig(small_site, DAY, SEED, scene=scene, mast=mast)
    for output in run(rig, small_site, 10):
        offset = mast.clock_offset_s(output.sensor_id)
        assert output.capture_s == pytest.approx(max(0.0, stamp_of(output) - offset), abs=1e-12)
    assert mast.clock_offset_s(CAMERA) >= 0.03 and mast.clock_offset_s(LIDAR) == 0.0


# --- on: the camera -------------------------------------------------------------------------------


def test_a_turned_camera_frame_is_where_a_pinhole_at_the_true_pose_projects() -> None:
    """Sway and settling turn the rendered frame by its homography: the car's box is the box of
    its corners projected from the true pose, and its pixels those of a camera built there."""
    mounted = make_mount(z=6.0, pitch=-10.0)
    true_pose = Pose(x_m=0.0, y_m=0.0, z_m=6.0, yaw_deg=1.5, pitch_deg=-9.0, roll_deg=0.0)
    boxes = car_boxes(1, 22.0, 1.0)
    turned = exact_model(mounted).render(boxes, ["car"], 0.0, rotation=true_pose.rotation())
    at_true_pose = exact_model(mounted.model_copy(update={"pose": true_pose}))
    exact = at_true_pose.render(boxes, ["car"], 0.0)
    unturned = exact_model(mounted).render(boxes, ["car"], 0.0)
    corners = np.concatenate([b.corners() for b in boxes])
    uv, _ = PinholeCamera(mounted.model_copy(update={"pose": true_pose})).project(corners)
    projected = [uv[:, 0].min(), uv[:, 1].min(), uv[:, 0].max(), uv[:, 1].max()]
    turned_box, unturned_box = turned.labels[0].box_xyxy_px, unturned.labels[0].box_xyxy_px
    assert turned_box is not None and unturned_box is not None
    np.testing.assert_allclose(turned_box, projected, atol=1.5)
    assert np.abs(np.subtract(unturned_box, projected)).max() > 3.0
    mask, exact_mask = turned.id_buffer == 0, exact.id_buffer == 0
    assert (mask & exact_mask).sum() / (mask | exact_mask).sum() > 0.85
    assert turned.labels[0].visible_pixels == int(mask.sum())
    assert abs(turned.labels[0].visible_pixels - exact.labels[0].visible_pixels) < 0.05 * int(
        exact_mask.sum()
    )
    # The whole picture too: far nearer the exact one than the frame left unturned.
    difference = np.abs(turned.image.astype(np.int16) - exact.image.astype(np.int16)).mean()
    unturned_difference = np.abs(unturned.image.astype(np.int16) - exact.image.astype(np.int16))
    assert difference < 0.5 * unturned_difference.mean()


def test_the_rig_turns_a_swaying_camera_to_its_pose_at_capture(
    small_site: Site, scene: StaticScene
) -> None:
    """A strong sway and a late clock, to see: the frame stamped 0.3 s shows the vehicles as a
    camera standing still at the pose of 0.2 s (its capture) does, not at that of 0.3 s."""
    mount = small_site.sensor(CAMERA)
    sway = Sway(3.0, 3.0, 1.2, 0.3, 1.9, 200.0)
    late = MountError(clock_offset_s=0.1)
    mast = MastModel({CAMERA: late}, (Mast((CAMERA,), mount.pose.z_m, sway, Settling(0.0, 0.0)),))

    def boxes(model: MastModel) -> list[tuple[float, float, float, float] | None]:
        rig = SensorRig(small_site, DAY, SEED, sensor_ids=[CAMERA], scene=scene, mast=model)
        output = rig.capture(CAMERA, 3, 0.3, traffic(small_site, 0.3), 0.3)
        assert isinstance(output, CameraOutput) and output.meta.stamp == 0.3
        return [label.full_box_xyxy_px for label in output.frame.labels]

    def standing_at(t_s: float) -> MastModel:
        pose, nominal = mast.pose_at(mount, t_s), mount.pose
        error = MountError(
            yaw_deg=pose.yaw_deg - nominal.yaw_deg,
            pitch_deg=pose.pitch_deg - nominal.pitch_deg,
            roll_deg=pose.roll_deg - nominal.roll_deg,
            clock_offset_s=late.clock_offset_s,
        )
        return MastModel({CAMERA: error})

    shown = [
        np.array([a, b, c], dtype=np.float64)
        for a, b, c in zip(
            boxes(mast), boxes(standing_at(0.2)), boxes(standing_at(0.3)), strict=True
        )
        if a is not None and b is not None and c is not None
    ]
    assert len(shown) >= 3
    swaying, at_capture, at_stamp = (np.stack([box[k] for box in shown]) for k in range(3))
    assert np.abs(swaying - at_capture).max() < 1.5
    assert np.abs(at_stamp - at_capture).max() > 3.0


def test_the_camera_bump_turns_the_frames_from_its_time_and_not_before(
    small_site: Site, scene: StaticScene
) -> None:
    bump = Bump(CAMERA, 0.25, 2.0)
    plain = SensorRig(small_site, DAY, SEED, scene=scene, mast=MastModel({}))
    bumped = SensorRig(small_site, DAY, SEED, scene=scene, mast=MastModel({}, bump=bump))
    before = only(run(plain, small_site, 8), CAMERA)
    after = only(run(bumped, small_site, 8), CAMERA)
    assert [o.capture_s for o in before] == pytest.approx([0.0, 0.1, 0.2, 0.3, 0.4])
    for a, b in zip(before, after, strict=True):
        assert same_frame(a, b) == (a.capture_s < bump.at_s)
    # After it, a car's box moved as a pinhole turned by the bump predicts.
    mount = small_site.sensor(CAMERA)
    a, b = before[-1], after[-1]
    assert isinstance(a, CameraOutput) and isinstance(b, CameraOutput)
    vehicle = next(
        i
        for i, label in enumerate(a.frame.labels)
        if label.visibility > 0.9 and b.frame.labels[i].visibility > 0.9
    )
    truth = traffic(small_site, 0.4)[vehicle]
    centre = np.array([[truth.x_m, truth.y_m, 0.5 * truth.height_m]])
    uv_before, _ = PinholeCamera(mount).project(centre)
    uv_after, _ = PinholeCamera(MastModel({}, bump=bump).mounted(mount, 1.0)).project(centre)
    expected = uv_after[0] - uv_before[0]
    box_a, box_b = a.frame.labels[vehicle].box_xyxy_px, b.frame.labels[vehicle].box_xyxy_px
    assert box_a is not None and box_b is not None
    moved = 0.5 * (np.add(box_b[:2], box_b[2:]) - np.add(box_a[:2], box_a[2:]))
    assert abs(expected[0]) > 4.0  # 2 deg at f = 160 px
    np.testing.assert_allclose(moved, expected, atol=1.0)


def test_the_lidar_bump_turns_its_head_at_its_time(
    wall_site: Site, wall_scene: StaticScene
) -> None:
    bump = Bump(LIDAR, 0.1, -2.0)
    rig = SensorRig(
        wall_site, DAY, SEED, sensor_ids=[LIDAR], scene=wall_scene, mast=MastModel({}, bump=bump)
    )
    plain = SensorRig(wall_site, DAY, SEED, sensor_ids=[LIDAR], scene=wall_scene)
    frames = {i: rig.capture(LIDAR, i, i * 0.05, [], i * 0.05) for i in (0, 1, 2)}
    # Sweep 1 turns mid-sweep at 0.075 s, before the bump: as without; sweep 2 after it.
    assert same_frame(frames[0], plain.capture(LIDAR, 0, 0.0, [], 0.0))
    assert same_frame(frames[1], plain.capture(LIDAR, 1, 0.05, [], 0.05))
    before, _ = wall_plane(frames[1])
    after, _ = wall_plane(frames[2])
    assert azimuth_deg(after) - azimuth_deg(before) == pytest.approx(2.0, abs=0.001)


# --- nothing reaches the services but the data ----------------------------------------------------


def test_nothing_of_the_error_is_published(small_site: Site, scene: StaticScene) -> None:
    nominal = SensorRig(small_site, DAY, SEED, scene=scene)
    real = SensorRig(small_site, DAY, SEED, scene=scene, mast=MastModel.draw(small_site, SEED))
    a, b = run(nominal, small_site, 8), run(real, small_site, 8)
    for x, y in zip(a, b, strict=True):
        if isinstance(x, LidarOutput) and isinstance(y, LidarOutput):
            assert x.scan.meta == y.scan.meta
        elif isinstance(x, CameraOutput) and isinstance(y, CameraOutput):
            assert x.meta == y.meta
        else:
            assert isinstance(x, RadarOutput) and isinstance(y, RadarOutput)
            assert x.result.scan.model_dump(exclude={"targets"}) == y.result.scan.model_dump(
                exclude={"targets"}
            )
    # The rig's site, and its mounts, are the file's.
    assert real.site == small_site and real.mounts == list(small_site.sensors)


def test_the_node_serves_the_site_files_poses_and_logs_the_draw(
    caplog: pytest.LogCaptureFixture,
) -> None:
    site = load_site(DEFAULT_SITE_PATH)
    served_before = site.model_dump_json()
    settings = SimulatorSettings(
        seed=11, mount_errors=True, bump_sensor=RADAR, bump_at_s=30.0, sensors_enabled=True
    )
    with caplog.at_level("INFO", logger="wz_simulator.node"):
        rig = sensor_rig(site, settings)
    assert rig.mast == MastModel.draw(site, 11, Bump(RADAR, 30.0, 2.0))
    assert site.model_dump_json() == served_before == load_site(DEFAULT_SITE_PATH).model_dump_json()
    logged = "\n".join(record.getMessage() for record in caplog.records)
    for mount in site.sensors:
        assert f"{mount.sensor_id}: yaw" in logged
    assert "bump: radar-mast" in logged
    assert sensor_rig(site, SimulatorSettings()).mast is None
