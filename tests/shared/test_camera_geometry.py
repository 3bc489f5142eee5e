"""Shared camera geometry: the paper's Eq. 1-2 against hand-computed values, pinhole round trips
on the road with and without lens distortion, distortion against OpenCV and its inverse."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from tests.purity import top_level_imports
from wz_shared import camera_geometry
from wz_shared.camera_geometry import (
    LensDistortion,
    PinholeCamera,
    backproject_to_ground,
    paper_flat_road_ground_point,
    paper_pixel_angles,
)
from wz_shared.site import CameraIntrinsics, Pose, SensorMount
from wz_simulator.sensors import camera as simulator_camera

HEIGHT_M = 6.2
PITCH_DEG = -14.0
MODERATE = LensDistortion(k1=-0.1, k2=0.01)


def site_camera_mount(
    *, x: float = 0.0, y: float = 0.0, yaw: float = 0.0, roll: float = 0.0
) -> SensorMount:
    """The site's default camera (1200 x 1200 px, 90 deg, 6.2 m up, pitched 14 deg down)."""
    return SensorMount(
        sensor_id="camera-mast",
        pose=Pose(x_m=x, y_m=y, z_m=HEIGHT_M, yaw_deg=yaw, pitch_deg=PITCH_DEG, roll_deg=roll),
        intrinsics=CameraIntrinsics(width_px=1200, height_px=1200, horizontal_fov_deg=90.0),
        rate_hz=10.0,
    )


# --- the paper's Eq. 1-2 by hand ------------------------------------------------------------------
# W = H = 1200, alpha_h = 90 deg so tan(alpha_h / 2) = 1 and tan(alpha_v / 2) = H / W * 1 = 1;
# theta = -14 deg; h = 6.2 m; the camera at the origin looking east (yaw 0), so x is forward
# and y is the lateral offset (left positive).
#   Eq. 1:  x_phi = atan((1200 - 2 u) / 1200),   y_phi = atan((1200 - 2 v) / 1200) + theta
#   omega = -y_phi;  forward = h / tan(omega);  lateral = h / sin(omega) tan(x_phi) cos(y_phi - theta)
THETA = math.radians(PITCH_DEG)

HAND_COMPUTED = [
    # Image centre (600, 600): x_phi = atan(0) = 0, y_phi = atan(0) - 14 deg, omega = 14 deg;
    # forward = 6.2 / tan(14 deg) = 24.866... m, lateral = 6.2 / sin(14 deg) * 0 * cos(0) = 0.
    ((600.0, 600.0), (0.0, -math.radians(14.0)), (6.2 / math.tan(math.radians(14.0)), 0.0)),
    # Bottom-centre (600, 1200): x_phi = 0, y_phi = atan(-1) - 14 deg = -59 deg, omega = 59 deg;
    # forward = 6.2 / tan(59 deg) = 3.725... m, lateral = 0.
    ((600.0, 1200.0), (0.0, -math.radians(59.0)), (6.2 / math.tan(math.radians(59.0)), 0.0)),
    # (900, 900): x_phi = atan(-600 / 1200) = -atan(1/2) (right of the axis),
    # y_phi = -atan(1/2) - 14 deg, omega = atan(1/2) + 14 deg = 40.565... deg;
    # y_phi - theta = -atan(1/2), cos(-atan(1/2)) = 2 / sqrt(5), tan(x_phi) = -1/2:
    # forward = 6.2 / tan(omega) = 7.24... m,
    # lateral = 6.2 / sin(omega) * (-1/2) * 2 / sqrt(5) = -6.2 / (sqrt(5) sin(omega)) = -4.26... m.
    (
        (900.0, 900.0),
        (-math.atan(0.5), -math.atan(0.5) - math.radians(14.0)),
        (
            6.2 / math.tan(math.atan(0.5) + math.radians(14.0)),
            -6.2 / (math.sqrt(5.0) * math.sin(math.atan(0.5) + math.radians(14.0))),
        ),
    ),
]


@pytest.mark.parametrize(("uv", "angles", "ground"), HAND_COMPUTED)
def test_paper_eq_1_2_match_hand_computed_values(
    uv: tuple[float, float], angles: tuple[float, float], ground: tuple[float, float]
) -> None:
    mount = site_camera_mount()
    assert isinstance(mount.intrinsics, CameraIntrinsics)
    x_phi, y_phi = paper_pixel_angles([uv], mount.intrinsics, THETA)
    assert x_phi[0] == pytest.approx(angles[0], abs=1e-12)
    assert y_phi[0] == pytest.approx(angles[1], abs=1e-12)
    point = paper_flat_road_ground_point(mount, [uv])[0]
    np.testing.assert_allclose(point, [ground[0], ground[1], 0.0], atol=1e-9)
    # Without roll Eq. 1-2 are exact: the full pinhole model agrees.
    np.testing.assert_allclose(
        backproject_to_ground(PinholeCamera(mount), [uv])[0], point, atol=1e-9
    )


def test_paper_eq_1_2_agree_with_the_pinhole_on_the_site_camera() -> None:
    mount = site_camera_mount(x=7.5, y=980.2, yaw=-95.0)
    u, v = np.meshgrid(np.linspace(0.0, 1200.0, 13), np.linspace(700.0, 1200.0, 11))
    uv = np.column_stack([u.ravel(), v.ravel()])
    np.testing.assert_allclose(
        paper_flat_road_ground_point(mount, uv),
        backproject_to_ground(PinholeCamera(mount), uv),
        atol=1e-9,
    )


def test_pixels_above_the_horizon_have_no_ground_point() -> None:
    mount = site_camera_mount()
    # Row 0 looks 45 deg above the axis, 31 deg above the horizon.
    assert np.isnan(paper_flat_road_ground_point(mount, [[600.0, 0.0]])).all()
    assert np.isnan(backproject_to_ground(PinholeCamera(mount), [[600.0, 0.0]])).all()


# --- pinhole round trips on the road --------------------------------------------------------------


def road_grid() -> np.ndarray:
    """Ground points 10-150 m ahead of the camera at the origin, lanes and shoulders across."""
    forward, lateral = np.meshgrid(np.linspace(10.0, 150.0, 29), np.linspace(-7.0, 7.0, 8))
    return np.column_stack([forward.ravel(), lateral.ravel(), np.zeros(forward.size)])


@pytest.mark.parametrize("distortion", [None, MODERATE], ids=["ideal", "k1=-0.1,k2=0.01"])
def test_ground_points_survive_projection_and_back_projection(
    distortion: LensDistortion | None,
) -> None:
    cam = PinholeCamera(site_camera_mount(), distortion)
    points = road_grid()
    uv, depth = cam.project(points)
    assert (depth > 0).all()
    assert ((uv >= 0) & (uv <= 1200)).all(), "the grid is inside the image"
    back = backproject_to_ground(cam, uv)
    assert np.abs(back - points).max() < 0.01
    # In practice it is exact to round-off (the iteration converges far below a pixel).
    np.testing.assert_allclose(back, points, atol=1e-6)


def test_distortion_moves_pixels_as_opencv_does() -> None:
    cam = PinholeCamera(site_camera_mount(yaw=30.0), MODERATE)
    points = road_grid()
    uv, _ = cam.project(points)
    rvec, _ = cv2.Rodrigues(cam.rotation_site_from_camera.T)
    tvec = -cam.rotation_site_from_camera.T @ cam.position_m
    expected, _ = cv2.projectPoints(points, rvec, tvec, cam.K, MODERATE.coefficients)
    np.testing.assert_allclose(uv, expected.reshape(-1, 2), atol=1e-6)
    # Barrel distortion (k1 < 0) pulls off-axis pixels towards the centre.
    ideal, _ = PinholeCamera(site_camera_mount(yaw=30.0)).project(points)
    centre = np.array([600.0, 600.0])
    assert (np.linalg.norm(uv - centre, axis=1) <= np.linalg.norm(ideal - centre, axis=1)).all()


@pytest.mark.parametrize(
    "distortion", [MODERATE, LensDistortion(k1=0.05, k2=-0.01, p1=1e-3, p2=-5e-4, k3=1e-3)]
)
def test_undistort_inverts_distort_to_a_micro_pixel(distortion: LensDistortion) -> None:
    cam = PinholeCamera(site_camera_mount(), distortion)
    u, v = np.meshgrid(np.linspace(0.0, 1200.0, 25), np.linspace(0.0, 1200.0, 25))
    pixels = np.column_stack([u.ravel(), v.ravel()])  # the whole image, corners included
    distorted = (pixels - 600.0) / cam.focal_px
    # Pixel -> ideal -> pixel.
    np.testing.assert_allclose(
        600.0 + cam.focal_px * cam.distort(cam.undistort(distorted)), pixels, atol=1e-6
    )
    # Ideal -> pixel -> ideal, from ideal coordinates spanning the image, in pixels.
    ideal = distorted
    np.testing.assert_allclose(
        cam.focal_px * cam.undistort(cam.distort(ideal)), cam.focal_px * ideal, atol=1e-6
    )


def test_zero_distortion_is_the_ideal_pinhole_bit_for_bit() -> None:
    mount = site_camera_mount(x=7.5, y=980.2, yaw=-95.0, roll=1.5)
    ideal, zero = PinholeCamera(mount), PinholeCamera(mount, LensDistortion())
    assert zero.distortion is None
    points = road_grid()
    np.testing.assert_array_equal(zero.project(points)[0], ideal.project(points)[0])
    uv = ideal.project(points)[0]
    np.testing.assert_array_equal(zero.pixel_to_ray(uv), ideal.pixel_to_ray(uv))
    np.testing.assert_array_equal(LensDistortion().distort(uv), uv)
    np.testing.assert_array_equal(LensDistortion().undistort(uv), uv)


def test_simulator_re_exports_the_shared_geometry() -> None:
    assert simulator_camera.PinholeCamera is PinholeCamera
    assert simulator_camera.backproject_to_ground is backproject_to_ground
    assert simulator_camera.paper_flat_road_ground_point is paper_flat_road_ground_point
    assert simulator_camera.paper_pixel_angles is paper_pixel_angles


def test_camera_geometry_is_pure_numpy() -> None:
    assert top_level_imports(camera_geometry) <= {
        "__future__",
        "math",
        "dataclasses",
        "numpy",
        "wz_shared",
    }
