"""Image box to ground position: the near-face correction against known vehicle boxes whose
corners are projected with the pinhole model (no rendering)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.purity import top_level_imports
from wz_camera_detector import world
from wz_camera_detector.world import (
    PIXEL_EDGE_INSET_PX,
    VehicleShape,
    box_bottom_centre_px,
    box_to_ground,
    fit_box_to_ground,
    paper_box_to_ground,
    vehicle_image_boxes,
)
from wz_shared.camera_geometry import LensDistortion, PinholeCamera, backproject_to_ground
from wz_shared.site import CameraIntrinsics, Pose, SensorMount

LENGTH_M, WIDTH_M, HEIGHT_M = 4.6, 1.9, 1.5  # a passenger car


def site_camera_mount() -> SensorMount:
    """The site's default camera at the origin looking east (down the road, +x)."""
    return SensorMount(
        sensor_id="camera-mast",
        pose=Pose(x_m=0.0, y_m=0.0, z_m=6.2, yaw_deg=0.0, pitch_deg=-14.0),
        intrinsics=CameraIntrinsics(width_px=1200, height_px=1200, horizontal_fov_deg=90.0),
        rate_hz=10.0,
    )


def vehicle_box_px(
    camera: PinholeCamera, centre_xy_m: tuple[float, float], heading_rad: float
) -> np.ndarray:
    """Pixel bounding box ``(x1, y1, x2, y2)`` of the 8 corners of a vehicle's 3D box."""
    heading = np.array([math.cos(heading_rad), math.sin(heading_rad)])
    across = np.array([-heading[1], heading[0]])
    corners = [
        [*(np.asarray(centre_xy_m) + a * LENGTH_M / 2 * heading + b * WIDTH_M / 2 * across), z]
        for a in (-1.0, 1.0)
        for b in (-1.0, 1.0)
        for z in (0.0, HEIGHT_M)
    ]
    uv, depth = camera.project(np.array(corners))
    assert (depth > 0).all()
    assert ((uv >= 0) & (uv <= 1200)).all(), "the vehicle is inside the image"
    return np.array([uv[:, 0].min(), uv[:, 1].min(), uv[:, 0].max(), uv[:, 1].max()])


@pytest.mark.parametrize("distortion", [None, LensDistortion(k1=-0.1, k2=0.01)])
@pytest.mark.parametrize("lateral_m", [-2.0, -5.5, 3.5])
@pytest.mark.parametrize("distance_m", [20.0, 40.0, 80.0, 150.0])
def test_approaching_car_centre_is_recovered_from_its_box(
    distance_m: float, lateral_m: float, distortion: LensDistortion | None
) -> None:
    camera = PinholeCamera(site_camera_mount(), distortion)
    truth = np.array([distance_m, lateral_m])
    heading = math.pi  # along the road, towards the camera
    box = vehicle_box_px(camera, (distance_m, lateral_m), heading)

    estimate = np.array(box_to_ground(camera, box, heading, LENGTH_M, WIDTH_M))
    raw = backproject_to_ground(camera, box_bottom_centre_px(box)[None, :])[0, :2]

    error_m = float(np.linalg.norm(estimate - truth))
    raw_error_m = float(np.linalg.norm(raw - truth))
    assert error_m < 0.5
    # The raw bottom-centre is on the near (front) face: about half a length short.
    assert raw_error_m == pytest.approx(LENGTH_M / 2, abs=0.25)
    assert raw[0] < distance_m, "the raw point is between the camera and the car"
    assert error_m < 0.25 * raw_error_m


@pytest.mark.parametrize("distance_m", [20.0, 60.0])
def test_receding_and_crossing_cars_are_corrected_too(distance_m: float) -> None:
    camera = PinholeCamera(site_camera_mount())
    for heading, half_extent in ((0.0, LENGTH_M / 2), (math.pi / 2, WIDTH_M / 2)):
        box = vehicle_box_px(camera, (distance_m, -3.0), heading)
        estimate = np.array(box_to_ground(camera, box, heading, LENGTH_M, WIDTH_M))
        raw = backproject_to_ground(camera, box_bottom_centre_px(box)[None, :])[0, :2]
        truth = np.array([distance_m, -3.0])
        assert np.linalg.norm(estimate - truth) < 0.5
        assert np.linalg.norm(raw - truth) == pytest.approx(half_extent, abs=0.25)


@pytest.mark.parametrize("distance_m", [20.0, 80.0])
def test_paper_ranging_is_the_uncorrected_bottom_centre(distance_m: float) -> None:
    mount = site_camera_mount()
    camera = PinholeCamera(mount)
    box = vehicle_box_px(camera, (distance_m, -2.0), math.pi)
    paper = np.array(paper_box_to_ground(mount, box))
    raw = backproject_to_ground(camera, box_bottom_centre_px(box)[None, :])[0, :2]
    # Without roll Eq. 1-2 are the exact flat-road back-projection.
    np.testing.assert_allclose(paper, raw, atol=1e-9)
    corrected = np.array(box_to_ground(camera, box, math.pi, LENGTH_M, WIDTH_M))
    # The correction moves the point half a length away from the camera, along the road.
    assert corrected[0] - paper[0] == pytest.approx(LENGTH_M / 2, abs=0.1)


def test_bottom_centre_and_degenerate_inputs() -> None:
    np.testing.assert_array_equal(box_bottom_centre_px([10.0, 20.0, 30.0, 60.0]), [20.0, 60.0])
    camera = PinholeCamera(site_camera_mount())
    above_horizon = [500.0, 0.0, 700.0, 10.0]
    assert all(math.isnan(c) for c in box_to_ground(camera, above_horizon, 0.0, 4.6, 1.9))
    assert all(math.isnan(c) for c in paper_box_to_ground(camera.mount, above_horizon))
    with pytest.raises(ValueError, match="must not be negative"):
        box_to_ground(camera, [500.0, 700.0, 700.0, 900.0], 0.0, -4.6, 1.9)


TRUCK = VehicleShape(16.5, 2.6, 4.0, clearance_m=0.5, wheel_inset_m=0.3)
CAR_BOX = VehicleShape(LENGTH_M, WIDTH_M, HEIGHT_M)
CAR_ON_WHEELS = VehicleShape(LENGTH_M, WIDTH_M, HEIGHT_M, clearance_m=0.28, wheel_inset_m=0.53)


def labelled_box(
    camera: PinholeCamera, centre_xy_m: tuple[float, float], heading_rad: float, shape: VehicleShape
) -> np.ndarray:
    """The box a label around the vehicle's pixels has: its exact box grown by half a pixel."""
    exact = vehicle_image_boxes(camera, [centre_xy_m], heading_rad, shape)[0]
    return exact + PIXEL_EDGE_INSET_PX * np.array([-1.0, -1.0, 1.0, 1.0])


def test_a_box_shape_has_the_box_of_its_corners() -> None:
    camera = PinholeCamera(site_camera_mount(), LensDistortion(k1=-0.1, k2=0.01))
    box = vehicle_image_boxes(camera, [(40.0, -3.0)], math.pi, CAR_BOX)[0]
    np.testing.assert_allclose(box, vehicle_box_px(camera, (40.0, -3.0), math.pi), atol=1e-9)


def test_a_raised_body_ends_higher_in_the_image_than_its_wheels_foot() -> None:
    """Seen from a mast, the foot of a car's front wheels (0.53 m behind the bumper, on the
    road) is lower in the image than the bumper's underside (0.28 m up): the box's bottom."""
    camera = PinholeCamera(site_camera_mount())
    on_wheels = vehicle_image_boxes(camera, [(60.0, -3.0)], math.pi, CAR_ON_WHEELS)[0]
    as_box = vehicle_image_boxes(camera, [(60.0, -3.0)], math.pi, CAR_BOX)[0]
    wheel_foot = camera.project([[60.0 - 0.5 * LENGTH_M + 0.53, -3.0 - 0.5 * WIDTH_M, 0.0]])[0][0]
    assert on_wheels[3] == pytest.approx(wheel_foot[1], abs=1e-9)
    assert on_wheels[3] < as_box[3], "higher in the image than a body reaching the road"
    np.testing.assert_allclose(on_wheels[[0, 1, 2]], as_box[[0, 1, 2]], atol=1.0)


@pytest.mark.parametrize("distortion", [None, LensDistortion(k1=-0.1, k2=0.01)])
@pytest.mark.parametrize("lateral_m", [-9.0, -5.5, 3.5])
@pytest.mark.parametrize("distance_m", [25.0, 40.0, 80.0, 150.0])
def test_fit_recovers_a_truck_the_contact_point_places_across_the_road(
    distance_m: float, lateral_m: float, distortion: LensDistortion | None
) -> None:
    """A semitrailer seen obliquely spans the image from its near front corner to its far rear
    top corner: the middle column is not its bearing. The fit recovers the centre."""
    camera = PinholeCamera(site_camera_mount(), distortion)
    truth = np.array([distance_m, lateral_m])
    box = labelled_box(camera, (distance_m, lateral_m), math.pi, TRUCK)

    fitted = np.array(fit_box_to_ground(camera, box, math.pi, TRUCK))
    contact = np.array(box_to_ground(camera, box, math.pi, TRUCK.length_m, TRUCK.width_m))

    assert np.linalg.norm(fitted - truth) < 0.02
    if distance_m <= 40.0 and abs(lateral_m) > 5.0:
        assert abs(contact[1] - lateral_m) > 0.3, "the contact-point estimate is metres off"


@pytest.mark.parametrize("heading_rad", [math.pi, 0.0, math.pi - 0.15])
@pytest.mark.parametrize("shape", [CAR_BOX, CAR_ON_WHEELS])
def test_fit_recovers_a_car_at_any_heading(heading_rad: float, shape: VehicleShape) -> None:
    camera = PinholeCamera(site_camera_mount())
    box = labelled_box(camera, (60.0, -4.0), heading_rad, shape)
    fitted = fit_box_to_ground(camera, box, heading_rad, shape)
    np.testing.assert_allclose(fitted, (60.0, -4.0), atol=0.02)


def test_fit_falls_back_on_a_box_no_vehicle_of_that_shape_has() -> None:
    """A box cut by an occluder (its right part hidden) fits no car within a few pixels: the
    contact-point estimate is kept rather than a fit dragged metres away."""
    camera = PinholeCamera(site_camera_mount())
    box = labelled_box(camera, (30.0, -4.0), math.pi, CAR_BOX)
    cut = box.copy()
    cut[2] = cut[0] + 0.3 * (cut[2] - cut[0])
    assert fit_box_to_ground(camera, cut, math.pi, CAR_BOX) == box_to_ground(
        camera, cut, math.pi, LENGTH_M, WIDTH_M
    )
    above_horizon = [500.0, 0.0, 700.0, 10.0]
    assert all(math.isnan(c) for c in fit_box_to_ground(camera, above_horizon, 0.0, CAR_BOX))


@pytest.mark.parametrize(
    "bad",
    [dict(height_m=-1.0), dict(clearance_m=-0.1), dict(clearance_m=2.0), dict(wheel_inset_m=2.5)],
)
def test_impossible_shapes_are_refused(bad: dict[str, float]) -> None:
    with pytest.raises(ValueError, match="vehicle shape"):
        VehicleShape(**({"length_m": 4.6, "width_m": 1.8, "height_m": 1.5} | bad))


def test_world_core_depends_on_the_shared_library_only() -> None:
    imported = top_level_imports(world)
    assert "wz_simulator" not in imported
    assert not imported & {"zenoh", "fastapi", "pathlib", "os", "io", "socket", "requests"}
