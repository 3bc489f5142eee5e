"""The pinhole camera model and renderer: closed-form projection, back-projection, paper Eq. 1-2,
truth labels from the id buffer, occlusion, clipping, weather, determinism."""

from __future__ import annotations

import math
from types import ModuleType

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.purity import top_level_imports
from wz_shared.messages import VehicleClass
from wz_shared.site import CameraIntrinsics, LidarIntrinsics, Pose, SensorMount
from wz_simulator.sensors import camera as camera_module
from wz_simulator.sensors import (
    camera_effects,
    camera_frame,
    camera_light,
    camera_paint,
    camera_projection,
)
from wz_simulator.sensors.camera import (
    CameraModel,
    PinholeCamera,
    backproject_to_ground,
    draw_truth,
    encode_jpeg,
    paper_flat_road_ground_point,
    paper_pixel_angles,
)
from wz_simulator.sensors.scene import (
    WEATHER_PRESETS,
    Box,
    GroundPolygon,
    Material,
    Weather,
)

# Small frames keep the rendering tests fast; geometry is resolution-independent.
WIDTH, HEIGHT = 320, 240


def make_mount(
    *,
    x: float = 0.0,
    y: float = 0.0,
    z: float = 6.0,
    yaw: float = 0.0,
    pitch: float = 0.0,
    roll: float = 0.0,
    width: int = WIDTH,
    height: int = HEIGHT,
    fov: float = 60.0,
) -> SensorMount:
    return SensorMount(
        sensor_id="cam-test",
        pose=Pose(x_m=x, y_m=y, z_m=z, yaw_deg=yaw, pitch_deg=pitch, roll_deg=roll),
        intrinsics=CameraIntrinsics(width_px=width, height_px=height, horizontal_fov_deg=fov),
        rate_hz=10.0,
    )


def car_boxes(
    label: int,
    x: float,
    y: float,
    yaw: float = math.pi,
    color: tuple[int, int, int] = (190, 40, 40),
) -> list[Box]:
    """A car like the scene module's: lower body, cabin on top, four wheels (4.5 m long)."""
    c, s = math.cos(yaw), math.sin(yaw)

    def at(
        along: float,
        across: float,
        z: float,
        size: tuple[float, float, float],
        material: Material,
        rgb: tuple[int, int, int],
    ) -> Box:
        return Box(
            (x + c * along - s * across, y + s * along + c * across, z),
            size,
            yaw,
            material,
            rgb,
            label,
        )

    boxes = [
        at(0.0, 0.0, 0.65, (4.5, 1.8, 0.7), Material.CAR_PAINT, color),
        at(-0.3, 0.0, 1.25, (2.4, 1.7, 0.5), Material.CAR_PAINT, color),
    ]
    for along in (1.4, -1.4):
        for across in (0.8, -0.8):
            boxes.append(at(along, across, 0.33, (0.66, 0.25, 0.66), Material.TIRE, (20, 20, 20)))
    return boxes


def truck_boxes(label: int, x: float, y: float, yaw: float = math.pi) -> list[Box]:
    """A semi: tractor in front of a 13 m trailer, eight wheels (about 16 m long, 4 m tall)."""
    c, s = math.cos(yaw), math.sin(yaw)

    def at(
        along: float,
        across: float,
        z: float,
        size: tuple[float, float, float],
        material: Material,
        rgb: tuple[int, int, int],
    ) -> Box:
        return Box(
            (x + c * along - s * across, y + s * along + c * across, z),
            size,
            yaw,
            material,
            rgb,
            label,
        )

    boxes = [
        at(6.5, 0.0, 1.9, (3.0, 2.5, 3.0), Material.TRUCK_BODY, (40, 60, 160)),
        at(-1.5, 0.0, 2.45, (13.0, 2.6, 3.1), Material.TRUCK_BODY, (230, 230, 230)),
    ]
    for along in (7.2, 5.8, -5.5, -6.8):
        for across in (1.05, -1.05):
            boxes.append(at(along, across, 0.5, (1.0, 0.4, 1.0), Material.TIRE, (20, 20, 20)))
    return boxes


def road() -> list[GroundPolygon]:
    asphalt = GroundPolygon(
        np.array([[-100.0, -6.0], [400.0, -6.0], [400.0, 6.0], [-100.0, 6.0]]),
        Material.ASPHALT,
        (70, 70, 72),
    )
    marking = GroundPolygon(
        np.array([[-100.0, -0.1], [400.0, -0.1], [400.0, 0.1], [-100.0, 0.1]]),
        Material.MARKING,
        (235, 235, 235),
    )
    return [asphalt, marking]


def exact_model(
    mount: SensorMount,
    static_boxes: list[Box] | None = None,
    weather: Weather | None = None,
    seed: int = 0,
) -> CameraModel:
    """No noise or blur: pixel-exact checks."""
    return CameraModel(
        mount, static_boxes or [], road(), weather, seed, blur_sigma_px=0.0, noise_std=0.0
    )


# --- pinhole geometry ---------------------------------------------------------------------------


def test_intrinsics_follow_fov_and_resolution() -> None:
    cam = PinholeCamera(make_mount(width=1200, height=800, fov=90.0))
    assert cam.focal_px == pytest.approx(600.0)
    np.testing.assert_allclose(cam.K, [[600.0, 0.0, 600.0], [0.0, 600.0, 400.0], [0.0, 0.0, 1.0]])
    assert cam.vertical_fov_deg == pytest.approx(2 * math.degrees(math.atan(400 / 600)))


def test_camera_needs_camera_intrinsics() -> None:
    lidar = SensorMount(
        sensor_id="l", pose=Pose(x_m=0, y_m=0, z_m=2), intrinsics=LidarIntrinsics(), rate_hz=10.0
    )
    with pytest.raises(ValueError, match="not a camera"):
        PinholeCamera(lidar)


def test_known_points_project_as_the_closed_form_predicts() -> None:
    # Level camera looking east: X = -left, Y = -up, Z = forward in the optical frame.
    cam = PinholeCamera(make_mount(x=10.0, y=-5.0, z=6.0))
    f = (WIDTH / 2) / math.tan(math.radians(30.0))
    forward, left, up = 20.0, 3.0, -2.5
    uv, depth = cam.project([[10.0 + forward, -5.0 + left, 6.0 + up]])
    assert depth[0] == pytest.approx(forward)
    np.testing.assert_allclose(
        uv[0], [WIDTH / 2 - f * left / forward, HEIGHT / 2 - f * up / forward]
    )
    # Yawed 90 degrees (looking north) the same relative point lands on the same pixel.
    north = PinholeCamera(make_mount(x=10.0, y=-5.0, z=6.0, yaw=90.0))
    uv_north, _ = north.project([[10.0 - left, -5.0 + forward, 6.0 + up]])
    np.testing.assert_allclose(uv_north, uv, atol=1e-9)


def test_pitch_and_roll_follow_the_pose_conventions() -> None:
    f = (WIDTH / 2) / math.tan(math.radians(30.0))
    # Looking 10 degrees down: a point level with the camera is above the centre.
    down = PinholeCamera(make_mount(z=6.0, pitch=-10.0))
    uv, _ = down.project([[50.0, 0.0, 6.0]])
    np.testing.assert_allclose(uv[0], [WIDTH / 2, HEIGHT / 2 - f * math.tan(math.radians(10.0))])
    # Rolled +90 degrees about the forward axis: the camera's left points up.
    rolled = PinholeCamera(make_mount(z=6.0, roll=90.0))
    uv, _ = rolled.project([[20.0, 0.0, 8.0]])
    np.testing.assert_allclose(uv[0], [WIDTH / 2 - f * 2.0 / 20.0, HEIGHT / 2], atol=1e-9)


@pytest.mark.parametrize("pose", [(0.0, -8.0, 0.0), (-93.0, -8.0, 0.0), (37.0, -20.0, 4.0)])
def test_optical_axis_projects_to_the_centre(pose: tuple[float, float, float]) -> None:
    yaw, pitch, roll = pose
    cam = PinholeCamera(make_mount(x=7.5, y=980.2, z=6.2, yaw=yaw, pitch=pitch, roll=roll))
    axis = cam.rotation_site_from_camera[:, 2]
    uv, depth = cam.project([cam.position_m + 35.0 * axis])
    np.testing.assert_allclose(uv[0], [WIDTH / 2, HEIGHT / 2], atol=1e-9)
    assert depth[0] == pytest.approx(35.0)


def test_points_behind_the_camera_have_no_pixel() -> None:
    cam = PinholeCamera(make_mount())
    uv, depth = cam.project([[-5.0, 0.0, 6.0], [5.0, 0.0, 6.0]])
    assert depth[0] < 0 < depth[1]
    assert np.isnan(uv[0]).all() and np.isfinite(uv[1]).all()


def ground_points_in_view(cam: PinholeCamera, count: int, seed: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    uv = np.column_stack(
        [
            rng.uniform(0, cam.width_px, count),
            rng.uniform(0.6 * cam.height_px, cam.height_px, count),
        ]
    )
    return backproject_to_ground(cam, uv)


def test_pixel_rays_and_ground_back_projection_invert_projection() -> None:
    cam = PinholeCamera(make_mount(x=7.5, y=980.2, z=6.2, yaw=-93.0, pitch=-8.0, roll=1.5))
    rng = np.random.default_rng(1)
    points = np.column_stack([rng.uniform(-15, 30, 200), rng.uniform(900, 975, 200), np.zeros(200)])
    uv, depth = cam.project(points)
    in_front = depth > 0
    assert in_front.sum() > 100
    back = backproject_to_ground(cam, uv[in_front])
    np.testing.assert_allclose(back, points[in_front], atol=1e-7)
    rays = cam.pixel_to_ray(uv[in_front])
    towards = points[in_front] - cam.position_m
    towards /= np.linalg.norm(towards, axis=1, keepdims=True)
    np.testing.assert_allclose(rays, towards, atol=1e-9)
    np.testing.assert_allclose(cam.ground_point(uv[in_front]), back)


@settings(max_examples=60, deadline=None)
@given(
    yaw=st.floats(-180.0, 180.0),
    pitch=st.floats(-60.0, 5.0),
    roll=st.floats(-10.0, 10.0),
    height=st.floats(1.0, 30.0),
    fov=st.floats(20.0, 120.0),
)
def test_ground_back_projection_round_trips_for_any_pose(
    yaw: float, pitch: float, roll: float, height: float, fov: float
) -> None:
    mount = make_mount(x=3.0, y=-4.0, z=height, yaw=yaw, pitch=pitch, roll=roll, fov=fov)
    cam = PinholeCamera(mount)
    u, v = np.meshgrid(np.linspace(0, WIDTH, 9), np.linspace(0, HEIGHT, 9))
    uv = np.column_stack([u.ravel(), v.ravel()])
    ground = backproject_to_ground(cam, uv)
    hit = np.isfinite(ground[:, 0])
    if hit.any():
        np.testing.assert_allclose(ground[hit, 2], 0.0, atol=1e-6)
        again, depth = cam.project(ground[hit])
        assert (depth > 0).all()
        np.testing.assert_allclose(again, uv[hit], atol=1e-6)
    if roll == 0.0:  # Eq. 1-2 agree, away from the horizon itself
        paper = paper_flat_road_ground_point(mount, uv)
        clear = np.abs(cam.pixel_to_ray(uv)[:, 2]) > 1e-6
        np.testing.assert_array_equal(np.isfinite(paper[clear, 0]), hit[clear])
        np.testing.assert_allclose(paper[clear & hit], ground[clear & hit], rtol=1e-7, atol=1e-6)


def test_back_projection_above_the_horizon_is_nan() -> None:
    cam = PinholeCamera(make_mount(z=6.0, pitch=0.0))
    points = backproject_to_ground(cam, [[WIDTH / 2, 10.0], [WIDTH / 2, HEIGHT - 1.0]])
    assert np.isnan(points[0]).all() and np.isfinite(points[1]).all()


def test_paper_eq1_angles_at_the_centre_and_edge() -> None:
    intrinsics = CameraIntrinsics(width_px=1200, height_px=1200, horizontal_fov_deg=90.0)
    x_phi, y_phi = paper_pixel_angles([[600.0, 600.0], [0.0, 1200.0]], intrinsics, -0.1)
    np.testing.assert_allclose(x_phi, [0.0, math.pi / 4])  # left edge: half the FOV, left +
    np.testing.assert_allclose(y_phi, [-0.1, -math.pi / 4 - 0.1])


@pytest.mark.parametrize("yaw, pitch", [(0.0, -8.0), (-93.0, -8.0), (45.0, -25.0), (160.0, -3.0)])
def test_paper_flat_road_mapping_equals_the_pinhole_model_without_roll(
    yaw: float, pitch: float
) -> None:
    mount = make_mount(
        x=7.5, y=980.2, z=6.2, yaw=yaw, pitch=pitch, width=1200, height=1200, fov=90.0
    )
    cam = PinholeCamera(mount)
    u, v = np.meshgrid(np.linspace(0, 1200, 25), np.linspace(0, 1200, 25))
    uv = np.column_stack([u.ravel(), v.ravel()])
    exact = backproject_to_ground(cam, uv)
    paper = paper_flat_road_ground_point(mount, uv)
    on_road = np.isfinite(exact[:, 0])
    assert on_road.sum() > 100
    np.testing.assert_array_equal(np.isfinite(paper[:, 0]), on_road)
    np.testing.assert_allclose(paper[on_road], exact[on_road], rtol=1e-9, atol=1e-6)


def test_paper_mapping_is_only_approximate_with_roll() -> None:
    mount = make_mount(z=6.2, pitch=-8.0, roll=3.0)
    uv = np.array([[40.0, 200.0]])
    gap = np.linalg.norm(
        paper_flat_road_ground_point(mount, uv) - backproject_to_ground(PinholeCamera(mount), uv)
    )
    assert gap > 0.1


# --- rendering -----------------------------------------------------------------------------


def test_truth_box_encloses_visible_pixels_tightly() -> None:
    mount = make_mount(z=6.0, pitch=-10.0)
    model = exact_model(mount)
    boxes = car_boxes(1, 30.0, 2.0) + car_boxes(2, 45.0, -2.0, yaw=0.3) + truck_boxes(3, 70.0, 1.5)
    frame = model.render(boxes, ["a", "b", "c"], 1.0)
    ids = frame.id_buffer
    assert ids.dtype == np.int16 and ids.shape == (HEIGHT, WIDTH)
    assert frame.image.dtype == np.uint8 and frame.image.shape == (HEIGHT, WIDTH, 3)
    for label in frame.labels:
        rows, cols = np.nonzero(ids == label.index)
        assert rows.size == label.visible_pixels > 0
        assert label.box_xyxy_px is not None
        x0, y0, x1, y1 = label.box_xyxy_px
        # Pixel (row i, column j) spans [j, j + 1) x [i, i + 1).
        assert (
            x0 <= cols.min() and cols.max() + 1 <= x1 and y0 <= rows.min() and rows.max() + 1 <= y1
        )
        assert cols.min() - x0 <= 1 and x1 - cols.max() - 1 <= 1
        assert rows.min() - y0 <= 1 and y1 - rows.max() - 1 <= 1
    car = frame.labels[0]
    assert car.visibility == pytest.approx(1.0)
    assert (
        car.vehicle_class == VehicleClass.CAR
        and frame.labels[2].vehicle_class == VehicleClass.TRUCK
    )
    # An unoccluded vehicle's box is the box of its projected corners (within a pixel).
    corners = np.concatenate([b.corners() for b in boxes if b.label == 1])
    uv, _ = model.camera.project(corners)
    expected = [uv[:, 0].min(), uv[:, 1].min(), uv[:, 0].max(), uv[:, 1].max()]
    np.testing.assert_allclose(car.box_xyxy_px, expected, atol=1.0)


def test_vehicle_has_visible_structure() -> None:
    model = exact_model(make_mount(z=6.0, pitch=-10.0))
    frame = model.render(car_boxes(1, 25.0, 0.0), ["a"], 0.0)
    pixels = frame.image[frame.id_buffer == 0]
    # Paint in several shades, dark wheels and windows, light lamps and plate.
    assert len(np.unique(pixels // 16, axis=0)) >= 5
    brightness = pixels.mean(axis=1)
    assert brightness.min() < 45 and brightness.max() > 150


def occluded_setup() -> tuple[CameraModel, list[Box]]:
    """Camera low behind a truck (along the road); cars farther on."""
    model = exact_model(make_mount(z=2.5, pitch=-2.0))
    truck = truck_boxes(1, 24.0, 0.0, yaw=0.0)
    return model, truck


def test_vehicle_behind_a_truck_is_hidden_and_half_behind_is_half_visible() -> None:
    model, truck = occluded_setup()
    cam = model.camera
    # The truck's left edge in the image, and the lateral offset that puts a car's centre on it
    # at 60 m (level camera: u = cx - f * y / x up to the small pitch).
    corners = np.concatenate([b.corners() for b in truck])
    uv, _ = cam.project(corners)
    edge_u = uv[:, 0].min()
    distance = 60.0
    ray = cam.pixel_to_ray([[edge_u, HEIGHT / 2]])[0]
    edge_y = ray[1] / ray[0] * distance
    hidden = car_boxes(2, distance, 0.0)
    half = car_boxes(3, distance, edge_y, yaw=0.0)
    frame = model.render(truck + hidden + half, ["truck", "hidden", "half"], 0.0)
    truck_label, hidden_label, half_label = frame.labels
    assert truck_label.visibility == pytest.approx(1.0)
    assert hidden_label.silhouette_pixels > 50
    assert hidden_label.visibility < 0.02
    assert 0.35 < half_label.visibility < 0.65
    alone = model.render(half, ["", "", "half"], 0.0).labels[2]
    assert alone.visibility == pytest.approx(1.0)
    assert alone.silhouette_pixels == half_label.silhouette_pixels


def test_static_box_in_front_hides_the_vehicle_and_one_behind_does_not() -> None:
    mount = make_mount(z=3.0, pitch=-3.0)
    sign = Box((15.0, 0.0, 1.5), (0.1, 4.0, 3.0), 0.0, Material.SIGN, (250, 140, 20))
    wall_behind = Box((60.0, 0.0, 2.0), (0.3, 8.0, 4.0), 0.0, Material.CONCRETE, (150, 150, 150))
    car = car_boxes(1, 40.0, 0.0)
    clear = exact_model(mount, [wall_behind]).render(car, ["car"], 0.0).labels[0]
    assert clear.visibility == pytest.approx(1.0)
    model = exact_model(mount, [sign, wall_behind])
    frame = model.render(car, ["car"], 0.0)
    blocked = frame.labels[0]
    assert blocked.silhouette_pixels == clear.silhouette_pixels
    assert blocked.visibility < 0.5 * clear.visibility
    # Where the sign covers the car the frame shows the background (the sign), not the car.
    sign_pixels = np.isfinite(model.static_box_depth) & (model.static_box_depth < 20.0)
    assert sign_pixels.any()
    assert not (frame.id_buffer[sign_pixels] >= 0).any()
    np.testing.assert_array_equal(frame.image[sign_pixels], model.background[sign_pixels])


def test_faces_crossing_the_camera_plane_are_clipped_not_smeared() -> None:
    model = exact_model(make_mount(z=1.5, pitch=0.0))
    # A trailer beside the camera on its right, from 10 m behind to 10 m ahead.
    passing = Box((0.0, -3.0, 2.0), (20.0, 2.6, 3.0), 0.0, Material.TRUCK_BODY, (230, 230, 230), 1)
    behind = Box((-20.0, 0.0, 2.0), (5.0, 2.6, 3.0), 0.0, Material.TRUCK_BODY, (230, 230, 230), 2)
    frame = model.render([passing, behind], ["passing", "behind"], 0.0)
    rows, cols = np.nonzero(frame.id_buffer == 0)
    assert rows.size > 0.1 * WIDTH * HEIGHT  # it fills the right part of the view
    assert cols.min() >= WIDTH // 2 - 1  # nothing mirrored onto the left half
    assert frame.labels[1].visible_pixels == 0 and frame.labels[1].box_xyxy_px is None
    # Same for a static box crossing the camera plane (guardrail from behind the camera).
    rail = Box((0.0, -2.0, 0.5), (40.0, 0.3, 0.6), 0.0, Material.METAL, (255, 0, 255))
    static = exact_model(make_mount(z=1.5, pitch=0.0), [rail])
    _, rail_cols = np.nonzero(np.isfinite(static.static_box_depth))
    assert rail_cols.size > 0 and rail_cols.min() >= WIDTH // 2 - 1


def traffic(count: int = 6) -> tuple[list[Box], list[str]]:
    boxes: list[Box] = []
    for i in range(count):
        boxes += car_boxes(i + 1, 25.0 + 22.0 * i, 2.0 if i % 2 else -2.0)
    return boxes, [f"v{i}" for i in range(count)]


def test_rendering_is_deterministic_with_a_seed() -> None:
    mount = make_mount(z=6.0, pitch=-8.0)
    boxes, ids = traffic()
    rain = WEATHER_PRESETS["rain"]
    first = [
        CameraModel(mount, [], road(), rain, seed=7).render(boxes, ids, t).image for t in (0, 1)
    ]
    again = [
        CameraModel(mount, [], road(), rain, seed=7).render(boxes, ids, t).image for t in (0, 1)
    ]
    other = CameraModel(mount, [], road(), rain, seed=8).render(boxes, ids, 0).image
    for a, b in zip(first, again, strict=True):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(first[0], other)


def contrast(frame_image: np.ndarray, mask: np.ndarray) -> float:
    """|mean inside - mean of a ring around| of a mask, grey levels."""
    grey = cv2.cvtColor(frame_image, cv2.COLOR_BGR2GRAY).astype(float)
    ring = cv2.dilate(mask.astype(np.uint8), np.ones((7, 7), np.uint8)).astype(bool) & ~mask
    return abs(grey[mask].mean() - grey[ring].mean())


def test_weather_changes_the_image() -> None:
    mount = make_mount(z=6.0, pitch=-8.0)
    boxes, ids = traffic()
    frames = {
        name: exact_model(mount, weather=WEATHER_PRESETS[name]).render(boxes, ids, 0.0)
        for name in ("day", "dusk", "rain", "fog")
    }
    day, dusk, rain, fog = (frames[n] for n in ("day", "dusk", "rain", "fog"))
    # Dusk is darker overall, but lamps glow.
    assert dusk.image.mean() < 0.6 * day.image.mean()
    near_car = dusk.labels[0].box_xyxy_px
    assert near_car is not None
    x0, y0, x1, y1 = (int(c) for c in near_car)
    assert dusk.image[y0:y1, x0:x1].max() > 230
    # Fog: far vehicles fade into the fog (lower contrast), near ones less so.
    far = len(ids) - 1
    far_day = contrast(day.image, day.id_buffer == far)
    far_fog = contrast(fog.image, fog.id_buffer == far)
    assert far_fog < 0.35 * far_day
    near_fog = contrast(fog.image, fog.id_buffer == 0)
    assert near_fog > far_fog
    # Rain: lower contrast and streaks; the same truth.
    assert not np.array_equal(rain.image, day.image)
    assert rain.image.std() < day.image.std()
    assert [lab.visible_pixels for lab in rain.labels] == [lab.visible_pixels for lab in day.labels]


def test_no_vehicles_and_bad_labels() -> None:
    model = exact_model(make_mount(z=6.0, pitch=-8.0))
    frame = model.render([], ["x"], 2.5)
    assert frame.stamp == 2.5 and frame.labels[0].box_xyxy_px is None
    assert (frame.id_buffer == -1).all()
    np.testing.assert_array_equal(frame.image, model.background)
    with pytest.raises(ValueError, match=r"labels must be 1\.\.1"):
        model.render(car_boxes(2, 20.0, 0.0), ["x"], 0.0)
    with pytest.raises(ValueError, match="vehicle classes"):
        model.render(car_boxes(1, 20.0, 0.0), ["x"], 0.0, [VehicleClass.CAR] * 2)


def test_classes_given_are_used() -> None:
    model = exact_model(make_mount(z=6.0, pitch=-8.0))
    frame = model.render(car_boxes(1, 20.0, 0.0), ["bus-ish"], 0.0, [VehicleClass.BUS])
    assert frame.labels[0].vehicle_class == VehicleClass.BUS


def test_jpeg_and_truth_drawing() -> None:
    model = CameraModel(make_mount(z=6.0, pitch=-8.0), [], road(), seed=1)
    boxes, ids = traffic(3)
    frame = model.render(boxes, ids, 0.0)
    data = encode_jpeg(frame.image, 85)
    assert data[:2] == b"\xff\xd8"
    decoded = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    assert decoded.shape == frame.image.shape
    assert np.abs(decoded.astype(int) - frame.image.astype(int)).mean() < 4.0
    with pytest.raises(ValueError):
        encode_jpeg(frame.image, 0)
    before = frame.image.copy()
    drawn = draw_truth(frame.image, frame.labels)
    np.testing.assert_array_equal(frame.image, before)
    assert drawn.shape == frame.image.shape and not np.array_equal(drawn, frame.image)


@pytest.mark.parametrize(
    "module",
    [
        camera_module,
        camera_effects,
        camera_frame,
        camera_light,
        camera_paint,
        camera_projection,
    ],
    ids=lambda m: m.__name__,
)
def test_core_imports_no_io_library(module: ModuleType) -> None:
    imported = top_level_imports(module)
    assert not imported & {"zenoh", "fastapi", "pathlib", "os", "io", "socket", "requests"}
