"""Image box to ground position: the near-face correction against known vehicle boxes whose
corners are projected with the pinhole model (no rendering)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.purity import top_level_imports
from wz_camera_detector import world
from wz_camera_detector.world import box_bottom_centre_px, box_to_ground, paper_box_to_ground
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


def test_world_core_depends_on_the_shared_library_only() -> None:
    imported = top_level_imports(world)
    assert "wz_simulator" not in imported
    assert not imported & {"zenoh", "fastapi", "pathlib", "os", "io", "socket", "requests"}
