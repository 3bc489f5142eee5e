"""The spinning LiDAR model: ranges, occlusion, sweep timing, labels and weather, checked
against closed forms and against a brute-force reference caster."""

from __future__ import annotations

import ast
import inspect
import math
from collections.abc import Sequence
from types import ModuleType

import numpy as np
import open3d as o3d
import pytest

from tests.purity import top_level_imports
from wz_shared.codec import decode_frame, encode_lidar_frame
from wz_shared.messages import LidarFrameMeta, VehicleTruth
from wz_shared.site import LidarIntrinsics, Pose, RadarIntrinsics, SensorMount, Site
from wz_simulator.sensors import lidar as lidar_module
from wz_simulator.sensors import lidar_frame, lidar_geometry, lidar_physics
from wz_simulator.sensors.lidar import (
    BOX_TRIANGLES,
    MATERIAL_RESPONSE,
    LidarModel,
    LidarPhysics,
    LidarScan,
    fog_extinction_per_m,
    rain_extinction_per_m,
    triangulate_polygon,
)
from wz_simulator.sensors.scene import (
    BOX_FACES,
    Box,
    GroundPolygon,
    Material,
    Weather,
    static_scene,
    vehicle_boxes,
)

CLEAR = Weather()


def one_box_per_vehicle(vehicles: Sequence[VehicleTruth], dt_s: float) -> list[Box]:
    """Each vehicle as one box of its truth size, moved ``dt_s`` along its heading."""
    boxes = []
    for label, vehicle in enumerate(vehicles, start=1):
        c, s = math.cos(vehicle.heading_rad), math.sin(vehicle.heading_rad)
        boxes.append(
            Box(
                (
                    vehicle.x_m + vehicle.speed_mps * dt_s * c,
                    vehicle.y_m + vehicle.speed_mps * dt_s * s,
                    vehicle.z_m + 0.5 * vehicle.height_m,
                ),
                (vehicle.length_m, vehicle.width_m, vehicle.height_m),
                vehicle.heading_rad,
                Material.CAR_PAINT,
                (200, 200, 200),
                label,
            )
        )
    return boxes


def vehicle(
    vehicle_id: str,
    x: float,
    y: float,
    heading: float = 0.0,
    speed: float = 0.0,
    size: tuple[float, float, float] = (4.5, 1.8, 1.5),
) -> VehicleTruth:
    length, width, height = size
    return VehicleTruth(
        vehicle_id=vehicle_id,
        vehicle_class="truck" if length > 8 else "car",
        x_m=x,
        y_m=y,
        heading_rad=heading,
        speed_mps=speed,
        accel_mps2=0.0,
        length_m=length,
        width_m=width,
        height_m=height,
        lane_index=0,
        station_m=0.0,
        offset_m=0.0,
        driver_profile="normal",
    )


def lidar_mount(
    height_m: float = 5.0,
    *,
    yaw_deg: float = 0.0,
    pitch_deg: float = 0.0,
    roll_deg: float = 0.0,
    noise_m: float = 0.0,
    beams: int = 64,
    vertical_deg: tuple[float, float] = (-30.0, 11.0),
    steps: int = 2048,
    x_m: float = 0.0,
    y_m: float = 0.0,
) -> SensorMount:
    return SensorMount(
        sensor_id="lidar-test",
        pose=Pose(
            x_m=x_m, y_m=y_m, z_m=height_m, yaw_deg=yaw_deg, pitch_deg=pitch_deg, roll_deg=roll_deg
        ),
        intrinsics=LidarIntrinsics(
            beams=beams,
            vertical_min_deg=vertical_deg[0],
            vertical_max_deg=vertical_deg[1],
            azimuth_steps=steps,
            max_range_m=200.0,
            range_noise_std_m=noise_m,
        ),
        rate_hz=20.0,
    )


def model(
    mount: SensorMount,
    boxes: Sequence[Box] = (),
    ground: Sequence[GroundPolygon] = (),
    *,
    weather: Weather = CLEAR,
    physics: LidarPhysics | None = None,
    seed: int = 3,
) -> LidarModel:
    return LidarModel(
        mount,
        boxes,
        ground,
        weather,
        seed,
        boxes_for=one_box_per_vehicle,
        physics=LidarPhysics.ideal() if physics is None else physics,
    )


def wall(x_near: float, y: float, length_y: float, height: float, material: Material) -> Box:
    """A thick wall whose face towards the sensor is the plane x = x_near."""
    return Box((x_near + 2.0, y, 0.5 * height), (4.0, length_y, height), 0.0, material, (0, 0, 0))


def face_hit_range(
    directions: np.ndarray, height: float, x_face: float, half_width: float, top: float
) -> np.ndarray:
    """Range along each ray (from a sensor at (0, 0, height)) to the wall face x = x_face,
    |y| < half_width, 0 < z < top, where met before the ground; NaN elsewhere. Rays within
    10 cm of the face's edges are left out (NaN)."""
    d = directions
    with np.errstate(divide="ignore", invalid="ignore"):
        t = x_face / d[:, 0]
        t_ground = np.where(d[:, 2] < 0, height / -d[:, 2], np.inf)
        y, z = t * d[:, 1], height + t * d[:, 2]
        ok = (t > 0) & np.isfinite(t) & (np.abs(y) < half_width - 0.1)
        ok &= (z > 0.1) & (z < top - 0.1) & (t < t_ground - 0.01)
    return np.where(ok, t, np.nan)


def ranges(scan: LidarScan) -> np.ndarray:
    """Range of every point [m] (NaN: no return), (n,)."""
    distance: np.ndarray = np.linalg.norm(scan.points[:, :3].astype(np.float64), axis=1)
    return distance


def to_site(lidar: LidarModel, points: np.ndarray) -> np.ndarray:
    """Sensor-frame points in the site frame, (n, 3)."""
    site: np.ndarray = points[:, :3].astype(np.float64) @ lidar.rotation.T + lidar.position_m
    return site


def box_surface_distance(box: Box, points_site: np.ndarray) -> np.ndarray:
    """Signed distance-like measure of points to a box's surface: 0 on it (inside the faces)."""
    c, s = math.cos(box.yaw_rad), math.sin(box.yaw_rad)
    rel = points_site - np.asarray(box.center_xyz_m)
    local = np.column_stack(
        [rel[:, 0] * c + rel[:, 1] * s, -rel[:, 0] * s + rel[:, 1] * c, rel[:, 2]]
    )
    excess = np.abs(local) - 0.5 * np.asarray(box.size_lwh_m)
    distance: np.ndarray = excess.max(axis=1)
    return distance


# --- geometry ----------------------------------------------------------------------------------


def test_rotation_convention_yaw_ccw_pitch_nose_up() -> None:
    lidar = model(lidar_mount(yaw_deg=90.0, pitch_deg=10.0, beams=42, vertical_deg=(-30, 11)))
    horizontal_row = int(np.argmin(np.abs(lidar.elevations_rad)))
    forward = horizontal_row * lidar.columns + lidar.columns // 2
    assert lidar.elevations_rad[horizontal_row] == pytest.approx(0.0, abs=1e-12)
    # Yaw 90 deg: forward is north (+y); pitch +10 deg raises it.
    np.testing.assert_allclose(
        lidar.ray_directions_site[forward],
        [0.0, math.cos(math.radians(10)), math.sin(math.radians(10))],
        atol=1e-12,
    )
    # Column 0 looks backwards, a quarter turn later (clockwise) the beam looks left.
    np.testing.assert_allclose(
        lidar.ray_directions_sensor[horizontal_row * lidar.columns], [-1, 0, 0], atol=1e-12
    )
    np.testing.assert_allclose(
        lidar.ray_directions_sensor[horizontal_row * lidar.columns + lidar.columns // 4],
        [0, 1, 0],
        atol=1e-12,
    )


@pytest.mark.parametrize(("yaw_deg", "pitch_deg"), [(0.0, 0.0), (0.0, -5.0), (25.0, 0.0)])
def test_range_to_a_wall_matches_the_closed_form(yaw_deg: float, pitch_deg: float) -> None:
    height, distance = 3.0, 30.0
    mount = lidar_mount(
        height, yaw_deg=yaw_deg, pitch_deg=pitch_deg, beams=42, vertical_deg=(-30, 11)
    )
    lidar = model(mount, [wall(distance, 0.0, 80.0, 20.0, Material.CONCRETE)])
    scan = lidar.scan([], 0.0, 0)
    horizontal_row = int(np.argmin(np.abs(lidar.elevations_rad)))
    forward = horizontal_row * lidar.columns + lidar.columns // 2
    # The forward horizontal beam: pitch tilts it, so it meets the plane x = D at D / cos(pitch)
    # when the yaw is 0.
    if yaw_deg == 0.0:
        expected = distance / math.cos(math.radians(pitch_deg))
        assert ranges(scan)[forward] == pytest.approx(expected, abs=1e-4)
        np.testing.assert_allclose(scan.points[forward, :3], [expected, 0.0, 0.0], atol=1e-4)
    # Every ray: t = D / d_x where it meets the face inside its bounds before the ground.
    t_wall = face_hit_range(lidar.ray_directions_site, height, distance, 40.0, 20.0)
    on_face = ~np.isnan(t_wall)
    assert on_face.sum() > 2000
    np.testing.assert_allclose(ranges(scan)[on_face], t_wall[on_face], atol=2e-4)


def test_ground_returns_at_mast_height_over_sine() -> None:
    height = 5.0
    lidar = model(lidar_mount(height))
    scan = lidar.scan([], 0.0, 0)
    image = ranges(scan).reshape(lidar.rows, lidar.columns)
    for row, elevation in enumerate(lidar.elevations_rad):
        expected = height / math.sin(-elevation) if elevation < 0 else math.inf
        if expected <= lidar.max_range_m:
            np.testing.assert_allclose(image[row], expected, rtol=2e-6, atol=2e-4)
            z = scan.range_image[row, :, 2]
            np.testing.assert_allclose(z, -height, atol=2e-4)
        else:
            assert np.isnan(image[row]).all(), f"beam {row} should see nothing within range"
    assert (scan.labels == 0).all()


def test_organized_frame_shape_and_nan_rows() -> None:
    lidar = model(lidar_mount(5.0), physics=LidarPhysics())
    scan = lidar.scan([vehicle("a", 20.0, 3.0, speed=10.0)], 1.5, 7)
    n = lidar.rows * lidar.columns
    assert scan.points.shape == (n, 4) and scan.points.dtype == np.float32
    assert scan.labels.shape == (n,) and scan.labels.dtype == np.int32
    assert scan.range_image.shape == (64, 2048, 4)
    missing = np.isnan(scan.points)
    # A row is all NaN or all finite; a no-return is labelled 0.
    assert (missing.all(axis=1) == missing.any(axis=1)).all()
    assert (scan.labels[missing[:, 0]] == 0).all()
    # The upward beams have nothing to hit.
    assert np.isnan(scan.range_image[lidar.elevations_rad > 0]).all()
    meta = scan.meta
    assert (meta.rows, meta.columns, meta.num_points) == (64, 2048, n)
    assert meta.sweep_duration_s == pytest.approx(0.05)
    assert (meta.stamp, meta.frame_index, meta.organized) == (1.5, 7, True)
    assert meta.source_id == "lidar-test"
    assert scan.vehicle_ids == ("a",)
    intensity = scan.points[~missing[:, 0], 3]
    assert (intensity >= 0).all() and (intensity <= 1).all()


# --- vehicles ----------------------------------------------------------------------------------


def test_a_car_behind_a_truck_gets_no_returns() -> None:
    lidar = model(lidar_mount(3.0))
    truck = vehicle("truck", 20.0, 0.0, heading=math.pi / 2, size=(16.0, 2.6, 4.0))
    car = vehicle("car", 40.0, 0.0, heading=math.pi / 2)
    hidden = lidar.scan([truck, car], 0.0, 0)
    counts = {box.vehicle_id: box.num_points for box in hidden.boxes}
    assert counts["car"] == 0 and counts["truck"] > 500
    assert (hidden.labels == 2).sum() == 0
    # Without the truck the same car is well seen.
    alone = lidar.scan([car], 0.0, 0)
    assert alone.boxes[0].num_points > 100


def test_labelled_points_lie_on_their_vehicle_box() -> None:
    mount = lidar_mount(5.0, x_m=100.0, y_m=-40.0, yaw_deg=-60.0, pitch_deg=-3.0, roll_deg=1.0)
    lidar = model(mount, [wall(140.0, -40.0, 30.0, 3.0, Material.METAL)])
    vehicles = [
        vehicle("near", 108.0, -33.0, heading=0.3, speed=12.0),
        vehicle("under", 100.0, -40.0, heading=1.0, size=(16.0, 2.6, 4.0)),  # below the mast
        vehicle("seam", 75.0, -55.0, heading=2.0, speed=25.0),  # behind the sensor
        vehicle("far", 150.0, -90.0, heading=-2.2, speed=30.0),
        vehicle("fast", 110.0, -80.0, heading=math.pi / 2, speed=40.0, size=(12.0, 2.5, 3.2)),
    ]
    scan = lidar.scan(vehicles, 4.0, 1, truth_stamp_s=3.98)
    columns = np.arange(lidar.num_rays) % lidar.columns
    # Each column sees the vehicles where they are when it fires.
    dt = 0.02 + lidar.column_time_offsets_s[columns]
    site = to_site(lidar, scan.points)
    for label in range(1, len(vehicles) + 1):
        on = scan.labels == label
        assert on.sum() > 20, vehicles[label - 1].vehicle_id
        distance = np.concatenate(
            [
                box_surface_distance(one_box_per_vehicle(vehicles, t)[label - 1], site[i : i + 1])
                for i, t in zip(np.flatnonzero(on)[:400], dt[on][:400], strict=True)
            ]
        )
        np.testing.assert_allclose(distance, 0.0, atol=1e-3)
    assert [box.num_points for box in scan.boxes] == [
        int((scan.labels == k).sum()) for k in range(1, 6)
    ]


def test_labelled_points_lie_on_their_box_within_noise() -> None:
    lidar = model(lidar_mount(5.0, noise_m=0.02))
    vehicles = [vehicle(f"v{k}", 15.0 + 7.0 * k, -8.0 + 4.0 * k, heading=0.5 * k) for k in range(6)]
    scan = lidar.scan(vehicles, 0.0, 0)
    site = to_site(lidar, scan.points)
    boxes = one_box_per_vehicle(vehicles, 0.0)
    for label, box in enumerate(boxes, start=1):
        on = scan.labels == label
        assert on.sum() > 50
        assert np.abs(box_surface_distance(box, site[on])).max() < 6 * 0.02


def test_fast_vehicle_is_skewed_as_its_columns_fire() -> None:
    """Rolling shutter: a car at 30 m/s passing 5 m from a 1 m high sensor is drawn where it is
    when each column fires. On the left the sweep runs back to front, with the car: it looks
    longer by ``v (t_front - t_rear)``; on the right front to back: it looks shorter."""
    speed, lateral, (length, width, height) = 30.0, 5.0, (4.5, 1.8, 1.5)
    lidar = model(lidar_mount(1.0, beams=42, vertical_deg=(-30, 11)))
    duration, columns = lidar.sweep_duration_s, lidar.columns
    row = int(np.argmin(np.abs(lidar.elevations_rad)))  # the horizontal beam, at z = 1 m
    column = np.arange(columns)
    azimuth, t = lidar.azimuths_rad, lidar.column_time_offsets_s
    for side in (1.0, -1.0):
        face_y = side * (lateral - 0.5 * width)
        moving = lidar.scan(
            [vehicle("car", 0.0, side * lateral, speed=speed, size=(length, width, height))], 0.0, 0
        )
        still = lidar.scan(
            [vehicle("car", 0.0, side * lateral, size=(length, width, height))], 0.0, 0
        )
        for scan, v in ((moving, speed), (still, 0.0)):
            # Closed form: column j meets the near face y = face_y at x_j = face_y / tan(az_j),
            # and does so when the car, centred at v t_j, spans x_j.
            with np.errstate(divide="ignore"):
                x_face = face_y / np.tan(azimuth)
            expected = (np.sign(np.sin(azimuth)) == side) & (np.abs(x_face - v * t) <= 0.5 * length)
            index = row * columns + column
            seen = scan.labels[index] == 1
            np.testing.assert_array_equal(seen, expected)
            x = to_site(lidar, scan.points[index[seen]])[:, 0]
            np.testing.assert_allclose(x, x_face[expected], atol=1e-4)
        # The apparent length: L + v (t_front - t_rear), to within a column at the ends.
        x_moving = to_site(
            lidar, moving.points[row * columns + column[moving.labels[row * columns + column] == 1]]
        )[:, 0]
        front, rear = x_moving.max(), x_moving.min()
        t_front = ((np.pi - math.atan2(face_y, front)) / (2 * np.pi) % 1.0) * duration
        t_rear = ((np.pi - math.atan2(face_y, rear)) / (2 * np.pi) % 1.0) * duration
        apparent = length + speed * (t_front - t_rear)
        assert front - rear == pytest.approx(apparent, abs=0.05)
        assert side * (front - rear - length) > 0.15  # longer on the left, shorter on the right
    # Truth boxes are stamped when the beam crosses each car's centre (left: a quarter turn).
    scan = lidar.scan([vehicle("car", 0.0, 20.0, speed=speed)], 0.0, 0)
    box = scan.boxes[0]
    assert box.stamp_s == pytest.approx(duration / 4, abs=duration / 100)
    assert box.center_site_m[0] == pytest.approx(speed * box.stamp_s, abs=1e-9)
    np.testing.assert_allclose(box.size_lwh_m, (4.5, 1.8, 1.5))


def test_culled_universes_match_a_brute_force_caster() -> None:
    """Culled rays cast in per-vehicle universes give what casting every column's rays against
    the whole scene (static and vehicles where they are when the column fires) gives."""
    mount = lidar_mount(5.0, yaw_deg=30.0, steps=512, beams=32)
    static = [
        wall(30.0, 10.0, 8.0, 3.0, Material.CONCRETE),
        wall(-50.0, -20.0, 6.0, 2.0, Material.DRUM),
    ]
    lidar = model(mount, static, physics=LidarPhysics.ideal(sectors=8))
    vehicles = [
        vehicle("a", 20.0, -10.0, speed=30.0),
        vehicle("under", 0.0, 0.0, heading=1.0, speed=20.0, size=(16.0, 2.6, 4.0)),
        vehicle("seam", -20.0, -12.0, heading=0.4, speed=25.0),  # behind: column 0 / last
        vehicle("b", 60.0, 40.0, heading=-2.0, speed=15.0),
        vehicle("behind-wall", 36.0, 10.0, speed=5.0),
        vehicle("a-shadow", 35.0, -17.0, heading=0.1, speed=30.0),  # partly behind "a"
    ]
    scan = lidar.scan(vehicles, 0.0, 0)

    def triangles(boxes: list[Box]) -> tuple[np.ndarray, np.ndarray]:
        corners = np.concatenate([box.corners() for box in boxes]) - lidar.position_m
        faces = np.concatenate([BOX_TRIANGLES + 8 * i for i in range(len(boxes))])
        return corners.astype(np.float32), faces.astype(np.uint32)

    expected = np.full(lidar.num_rays, np.nan)
    expected_label = np.zeros(lidar.num_rays, dtype=np.int32)
    plane = np.array([[-500, -500, -5], [500, -500, -5], [500, 500, -5], [-500, 500, -5]])
    for column, t in enumerate(lidar.column_time_offsets_s):
        scene = o3d.t.geometry.RaycastingScene()
        for box_set in (static, one_box_per_vehicle(vehicles, float(t))):
            v, f = triangles(box_set)
            scene.add_triangles(o3d.core.Tensor.from_numpy(v), o3d.core.Tensor.from_numpy(f))
        scene.add_triangles(
            o3d.core.Tensor.from_numpy(plane.astype(np.float32)),
            o3d.core.Tensor.from_numpy(np.array([[0, 1, 2], [0, 2, 3]], dtype=np.uint32)),
        )
        rays_of = column + lidar.columns * np.arange(lidar.rows)
        rays = np.zeros((len(rays_of), 6), dtype=np.float32)
        rays[:, 3:] = lidar.ray_directions_site[rays_of]
        hit = scene.cast_rays(o3d.core.Tensor.from_numpy(rays))
        t_hit = hit["t_hit"].numpy()
        within = t_hit <= lidar.max_range_m
        expected[rays_of[within]] = t_hit[within]
        is_vehicle = within & (hit["geometry_ids"].numpy() == 1)
        expected_label[rays_of[is_vehicle]] = hit["primitive_ids"].numpy()[is_vehicle] // 12 + 1
    got = ranges(scan)
    assert (np.isnan(got) == np.isnan(expected)).all()
    np.testing.assert_allclose(got[~np.isnan(got)], expected[~np.isnan(expected)], atol=2e-3)
    np.testing.assert_array_equal(scan.labels, expected_label)
    seen = {box.vehicle_id: box.num_points for box in scan.boxes}
    assert seen.pop("behind-wall") == 0
    assert all(count > 0 for count in seen.values())


def test_work_zone_scene_with_vehicle_bodies(site: Site) -> None:
    """The site's static scene and the vehicle bodies: every vehicle point lies in its truth
    box where the vehicle is when the point's column fires."""
    mount = site.sensor("lidar-mast")
    lidar = LidarModel.from_scene(
        mount, static_scene(site), Weather(), 4, boxes_for=vehicle_boxes, site_id=site.site_id
    )
    frame = site.road_frame
    station, _ = frame.to_road(mount.pose.x_m, mount.pose.y_m)
    vehicles = []
    for k, ds in enumerate((-60.0, -25.0, 5.0, 30.0)):
        lane = site.lanes[k % 2]
        x, y = frame.to_site(float(station) + ds, lane.center_offset_m)
        truck = k == 1
        vehicles.append(
            VehicleTruth(
                vehicle_id=f"v{k}",
                vehicle_class="truck" if truck else "car",
                x_m=float(x),
                y_m=float(y),
                heading_rad=float(frame.heading_at(float(station) + ds)),
                speed_mps=28.0,
                accel_mps2=0.0,
                length_m=16.5 if truck else 4.6,
                width_m=2.6 if truck else 1.8,
                height_m=4.0 if truck else 1.5,
                lane_index=lane.index,
                station_m=float(station) + ds,
                offset_m=lane.center_offset_m,
                driver_profile="normal",
            )
        )
    scan = lidar.scan(vehicles, 10.0, 200, truth_stamp_s=9.99)
    site_points = to_site(lidar, scan.points)
    column = np.arange(lidar.num_rays) % lidar.columns
    dt = 0.01 + lidar.column_time_offsets_s[column]
    for label, vehicle_truth in enumerate(vehicles, start=1):
        on = np.flatnonzero(scan.labels == label)
        assert len(on) > 5, vehicle_truth.vehicle_id
        c, s_ = math.cos(vehicle_truth.heading_rad), math.sin(vehicle_truth.heading_rad)
        travel = vehicle_truth.speed_mps * dt[on]
        rel = site_points[on, :2] - [vehicle_truth.x_m, vehicle_truth.y_m]
        along = rel @ [c, s_] - travel
        across = rel @ [-s_, c]
        noise = 4 * lidar.intrinsics.range_noise_std_m
        assert np.abs(along).max() <= 0.5 * vehicle_truth.length_m + 0.05 + noise
        assert np.abs(across).max() <= 0.5 * vehicle_truth.width_m + noise
        assert site_points[on, 2].max() <= vehicle_truth.height_m + noise
        box = scan.boxes[label - 1]
        np.testing.assert_allclose(
            box.size_lwh_m[1:], (vehicle_truth.width_m, vehicle_truth.height_m), atol=1e-9
        )
    # The ground and the work zone furniture return, labelled 0.
    assert (~np.isnan(scan.points[scan.labels == 0, 0])).sum() > 20_000


# --- physics and weather -------------------------------------------------------------------------


def test_fog_keeps_near_returns_and_loses_far_ones_as_the_lidar_equation_says() -> None:
    physics = LidarPhysics(
        dropout_probability=0.0, grazing_dropout_probability=0.0, rain_clutter_per_mm_h=0.0
    )
    height = 2.0
    mount = lidar_mount(height, beams=42, vertical_deg=(-30, 11))
    walls = [
        wall(20.0, 0.0, 16.0, 6.0, Material.CONCRETE),
        wall(-60.0, 0.0, 40.0, 12.0, Material.CONCRETE),
    ]
    fog = Weather(fog_visibility_m=100.0)
    alpha = fog_extinction_per_m(100.0)
    assert alpha == pytest.approx(3.912 / 100.0)
    clear_scan = model(mount, walls, physics=physics).scan([], 0.0, 0)
    foggy_scan = model(mount, walls, weather=fog, physics=physics).scan([], 0.0, 0)
    lidar = model(mount, walls, physics=physics)

    d = lidar.ray_directions_site
    t_near = face_hit_range(d, height, 20.0, 8.0, 6.0)
    t_far = face_hit_range(d, height, -60.0, 20.0, 12.0)
    near, far = ~np.isnan(t_near), ~np.isnan(t_far)
    t = np.where(near, t_near, t_far)
    cos_incidence = np.abs(d[:, 0])
    rho = MATERIAL_RESPONSE[Material.CONCRETE].reflectivity
    for scan, extinction in ((clear_scan, 0.0), (foggy_scan, alpha)):
        intensity = rho * cos_incidence * np.exp(-2 * extinction * t)
        margin = intensity * (lidar.max_range_m / t) ** 2 / 0.8  # > 1: detected
        returned = ~np.isnan(scan.points[:, 0])
        sure = (near | far) & (np.abs(margin - 1.0) > 0.02)
        np.testing.assert_array_equal(returned[sure], margin[sure] > 1.0)
        np.testing.assert_allclose(
            scan.points[returned & sure, 3], intensity[returned & sure], rtol=1e-4
        )
    clear_returned = ~np.isnan(clear_scan.points[:, 0])
    foggy_returned = ~np.isnan(foggy_scan.points[:, 0])
    assert clear_returned[far].mean() > 0.95 and clear_returned[near].all()
    assert foggy_returned[near].mean() > 0.95 and not foggy_returned[far].any()


def test_rain_adds_spurious_near_returns() -> None:
    height = 20.0  # every real return is at least 20 m away
    mount = lidar_mount(height)
    physics = LidarPhysics(dropout_probability=0.0, grazing_dropout_probability=0.0)
    dry = model(mount, physics=physics)
    wet = model(mount, weather=Weather(rain_mm_per_h=8.0), physics=physics)
    frames = 20
    near_counts = []
    for index in range(frames):
        assert (ranges(dry.scan([], 0.05 * index, index)) < height - 0.01).sum() == 0
        scan = wet.scan([], 0.05 * index, index)
        r = ranges(scan)
        spurious = r < height - 0.01
        near_counts.append(int(spurious.sum()))
        assert (r[spurious] >= 5.0).all() and (r[spurious] <= 15.0).all()
        assert (scan.labels[spurious] == 0).all()
        intensity = scan.points[spurious, 3]
        assert (intensity >= 0.01).all() and (intensity <= 0.1).all()
    mean = physics.rain_clutter_per_mm_h * 8.0 * frames
    assert sum(near_counts) == pytest.approx(mean, abs=4 * math.sqrt(mean))
    assert min(near_counts) >= 1
    # Rain also dims: two-way FSO attenuation 1.076 R^0.67 dB/km.
    assert rain_extinction_per_m(8.0) == pytest.approx(1.076 * 8**0.67 / 4342.9, rel=1e-4)


def test_dropouts_follow_their_probability() -> None:
    physics = LidarPhysics(
        dropout_probability=0.1, grazing_dropout_probability=0.0, range_spec_reflectivity=0.0
    )
    lidar = model(lidar_mount(5.0), physics=physics)
    ideal = model(lidar_mount(5.0)).scan([], 0.0, 0)
    scan = lidar.scan([], 0.0, 0)
    possible = ~np.isnan(ideal.points[:, 0])
    lost = np.isnan(scan.points[possible, 0]).mean()
    assert lost == pytest.approx(0.1, abs=0.005)


def test_glass_drops_more_returns_than_paint() -> None:
    physics = LidarPhysics(
        dropout_probability=0.0, grazing_dropout_probability=0.0, range_spec_reflectivity=0.0
    )
    walls = [
        wall(10.0, 0.0, 10.0, 8.0, Material.GLASS),
        wall(-14.0, 0.0, 10.0, 8.0, Material.CAR_PAINT),
    ]
    scan = model(lidar_mount(3.0), walls, physics=physics).scan([], 0.0, 0)
    x = scan.points[:, 0]
    glass = np.isclose(x, 10.0, atol=1e-3).sum()
    paint = np.isclose(x, -10.0, atol=1e-3).sum()
    assert glass == pytest.approx(0.5 * paint, rel=0.1)


def test_same_seed_and_frame_reproduce_the_frame() -> None:
    mount = lidar_mount(5.0, noise_m=0.02)
    vehicles = [vehicle("a", 20.0, 3.0, speed=20.0), vehicle("b", -15.0, -4.0, heading=3.0)]
    rain = Weather(rain_mm_per_h=10.0)
    first = model(mount, weather=rain, physics=LidarPhysics(), seed=5).scan(vehicles, 2.0, 40)
    again = model(mount, weather=rain, physics=LidarPhysics(), seed=5).scan(vehicles, 2.0, 40)
    np.testing.assert_array_equal(first.points, again.points)
    np.testing.assert_array_equal(first.labels, again.labels)
    assert first.boxes == again.boxes
    other_frame = model(mount, weather=rain, physics=LidarPhysics(), seed=5).scan(vehicles, 2.0, 41)
    other_seed = model(mount, weather=rain, physics=LidarPhysics(), seed=6).scan(vehicles, 2.0, 40)
    for other in (other_frame, other_seed):
        assert not np.array_equal(first.points, other.points, equal_nan=True)


def test_frame_goes_through_the_codec_intact() -> None:
    lidar = model(lidar_mount(5.0, noise_m=0.02), physics=LidarPhysics())
    vehicles = [vehicle("a", 20.0, 3.0, speed=20.0), vehicle("b", -15.0, -4.0, heading=3.0)]
    scan = lidar.scan(vehicles, 2.0, 40)
    frame = decode_frame(encode_lidar_frame(scan.meta, scan.points), LidarFrameMeta)
    assert frame.meta == scan.meta
    decoded = frame.points()
    np.testing.assert_array_equal(decoded, scan.points)
    # Labels travel separately and stay aligned with the decoded rows.
    site = to_site(lidar, decoded)
    for box in scan.boxes:
        on = scan.labels == box.label
        assert on.sum() == box.num_points > 0
        truth = one_box_per_vehicle(vehicles, 0.0)[box.label - 1]
        assert np.abs(box_surface_distance(truth, site[on])).max() < 0.1 + 20.0 * 0.05


# --- pieces ----------------------------------------------------------------------------------


def test_every_material_has_a_response() -> None:
    assert set(MATERIAL_RESPONSE) == set(Material)
    assert all(0.0 <= r.reflectivity <= 1.0 for r in MATERIAL_RESPONSE.values())
    retro = (Material.MARKING, Material.DRUM, Material.SIGN)
    assert min(MATERIAL_RESPONSE[m].reflectivity for m in retro) > 2 * max(
        MATERIAL_RESPONSE[m].reflectivity
        for m in (Material.ASPHALT, Material.CAR_PAINT, Material.GLASS)
    )


@pytest.mark.parametrize("clockwise", [False, True])
def test_ear_clipping_covers_a_concave_polygon(clockwise: bool) -> None:
    polygon = np.array([[0, 0], [4, 0], [4, 1], [2, 1], [2, 3], [1, 3], [1, 4], [0, 4], [0, 2]])
    if clockwise:
        polygon = polygon[::-1]
    triangles = triangulate_polygon(polygon)
    a, b, c = (polygon[triangles[:, i]].astype(float) for i in range(3))
    signed = 0.5 * ((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0])
    assert (signed > 0).all()  # counter-clockwise, none degenerate
    assert signed.sum() == pytest.approx(4 + 2 + 2 + 1)  # area of the L-shaped polygon
    assert len(triangles) == len(polygon) - 3  # the collinear vertex (0, 2) makes none


def test_ground_polygons_are_seen_at_their_layer() -> None:
    square = np.array([[5.0, -5.0], [25.0, -5.0], [25.0, 5.0], [5.0, 5.0]])
    ground = [
        GroundPolygon(square, Material.ASPHALT, (60, 60, 60), z_m=0.0),
        GroundPolygon(square[:, :] * [1, 0.1], Material.MARKING, (255, 255, 255), z_m=0.005),
    ]
    lidar = model(lidar_mount(5.0), ground=ground)
    scan = lidar.scan([], 0.0, 0)
    site = to_site(lidar, scan.points)
    ok = ~np.isnan(site[:, 0])
    inside = ok & (site[:, 0] > 5.2) & (site[:, 0] < 24.8) & (np.abs(site[:, 1]) < 4.8)
    marking = inside & (np.abs(site[:, 1]) < 0.45)
    asphalt = inside & (np.abs(site[:, 1]) > 0.55)
    np.testing.assert_allclose(site[marking, 2], 0.005, atol=2e-4)
    np.testing.assert_allclose(site[asphalt, 2], 0.0, atol=2e-4)
    # The base plane lies below the grass-free default: the polygons are on top of it.
    assert scan.points[marking, 3].min() > scan.points[asphalt, 3].max()


def test_rejects_a_non_lidar_mount_and_bad_settings() -> None:
    radar = SensorMount(
        sensor_id="radar", pose=Pose(x_m=0, y_m=0, z_m=5), intrinsics=RadarIntrinsics(), rate_hz=15
    )
    with pytest.raises(ValueError, match="not a lidar"):
        model(radar)
    with pytest.raises(ValueError, match="sectors"):
        model(lidar_mount(), physics=LidarPhysics(sectors=0))


def test_box_triangles_cover_the_faces() -> None:
    assert BOX_TRIANGLES.shape == (12, 3)
    assert {tuple(sorted(set(face))) for face in BOX_FACES} == {
        tuple(sorted(set(BOX_TRIANGLES[2 * i]) | set(BOX_TRIANGLES[2 * i + 1]))) for i in range(6)
    }


@pytest.mark.parametrize(
    "module", [lidar_module, lidar_frame, lidar_geometry, lidar_physics], ids=lambda m: m.__name__
)
def test_the_core_does_no_io(module: ModuleType) -> None:
    """A pure core: numpy, open3d and the shared models only; no bus, web or files."""
    imported = top_level_imports(module)
    assert imported <= {
        "__future__",
        "math",
        "collections",
        "dataclasses",
        "types",
        "typing",
        "numpy",
        "open3d",
        "wz_shared",
        "wz_simulator",
    }
    tree = ast.parse(inspect.getsource(module))
    calls = {
        node.func.id
        for node in ast.walk(tree)
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
    }
    assert "open" not in calls and "print" not in calls
