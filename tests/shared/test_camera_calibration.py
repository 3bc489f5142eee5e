"""Camera calibration files (OpenCV FileStorage and ROS camera_info YAML) into the site's camera."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from wz_shared.camera_calibration import CalibrationError, read_calibration
from wz_shared.camera_geometry import PinholeCamera, camera_at_size
from wz_shared.site import DEFAULT_SITE_PATH, SiteFileError, load_site

#: A 1920x1080 camera with a real lens's barrel distortion, OpenCV's conventions.
K = np.array([[1412.5, 0.0, 951.3], [0.0, 1408.9, 547.2], [0.0, 0.0, 1.0]])
DIST = np.array([-0.31, 0.11, 0.0008, -0.0005, -0.018])


def _ros_yaml(path: Path, model: str = "plumb_bob", dist: list[float] | None = None) -> Path:
    path.write_text(
        yaml.safe_dump(
            {
                "image_width": 1920,
                "image_height": 1080,
                "camera_name": "mast_cam",
                "camera_matrix": {"rows": 3, "cols": 3, "data": K.ravel().tolist()},
                "distortion_model": model,
                "distortion_coefficients": {
                    "rows": 1,
                    "cols": 5,
                    "data": dist if dist is not None else DIST.tolist(),
                },
                "rectification_matrix": {"rows": 3, "cols": 3, "data": np.eye(3).ravel().tolist()},
            }
        ),
        encoding="utf-8",
    )
    return path


def _opencv_yaml(path: Path) -> Path:
    """Written by OpenCV's own FileStorage, as its calibration sample does."""
    storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    storage.write("image_width", 1920)
    storage.write("image_height", 1080)
    storage.write("camera_matrix", K)
    storage.write("distortion_coefficients", DIST.reshape(5, 1))
    storage.release()
    return path


@pytest.mark.parametrize("writer", [_ros_yaml, _opencv_yaml])
def test_both_formats_read_to_the_same_intrinsics(tmp_path: Path, writer) -> None:  # type: ignore[no-untyped-def]
    calibration = read_calibration(writer(tmp_path / "cam.yaml"))
    assert (calibration.width_px, calibration.height_px) == (1920, 1080)
    assert (calibration.fx_px, calibration.fy_px) == (1412.5, 1408.9)
    # OpenCV's pixel centres are integers; ours are half-integers.
    assert (calibration.cx_px, calibration.cy_px) == (951.8, 547.7)
    assert calibration.distortion == pytest.approx(DIST.tolist())


def _site_with_calibration(tmp_path: Path, calibration_file: str, **extra: object) -> Path:
    raw = yaml.safe_load(DEFAULT_SITE_PATH.read_text(encoding="utf-8"))
    for sensor in raw["sensors"]:
        if sensor["intrinsics"]["kind"] == "camera":
            sensor["intrinsics"] = {"kind": "camera", "calibration_file": calibration_file, **extra}
    path = tmp_path / "site.yaml"
    path.write_text(yaml.safe_dump(raw), encoding="utf-8")
    return path


def test_the_site_camera_projects_as_opencv_does(tmp_path: Path) -> None:
    _opencv_yaml(tmp_path / "mast-cam.yaml")
    site = load_site(_site_with_calibration(tmp_path, "mast-cam.yaml"))
    mount = next(m for m in site.sensors if m.kind == "camera")
    camera = PinholeCamera(mount)
    assert camera.width_px == 1920 and camera.height_px == 1080
    # Road points 20-120 m ahead: our projection against cv2.projectPoints with the same K,
    # distortion and pose (OpenCV's pixel centres are 0.5 px left/up of ours).
    rng = np.random.default_rng(0)
    ahead = camera.position_m + np.array([0.0, -1.0, 0.0]) * rng.uniform(20, 120, (50, 1))
    points = ahead + np.column_stack([rng.uniform(-6, 6, 50), np.zeros(50), np.zeros(50)])
    points[:, 2] = 0.0
    uv, depth = camera.project(points)
    inside = (depth > 0) & (uv[:, 0] > 0) & (uv[:, 0] < 1920) & (uv[:, 1] > 0) & (uv[:, 1] < 1080)
    assert inside.sum() > 10
    rotation = camera.rotation_site_from_camera.T
    rvec, _ = cv2.Rodrigues(rotation)
    tvec = -rotation @ camera.position_m
    expected, _ = cv2.projectPoints(points[inside], rvec, tvec, K, DIST)
    assert uv[inside] - 0.5 == pytest.approx(expected.reshape(-1, 2), abs=1e-6)
    # And back: the pixel's ray meets the road at the point.
    assert camera.ground_point(uv[inside])[:, :2] == pytest.approx(points[inside, :2], abs=1e-4)


def test_a_scaled_stream_keeps_the_geometry_another_aspect_is_refused(tmp_path: Path) -> None:
    _ros_yaml(tmp_path / "cam.yaml")
    site = load_site(_site_with_calibration(tmp_path, "cam.yaml"))
    mount = next(m for m in site.sensors if m.kind == "camera")
    full = PinholeCamera(mount)
    half = camera_at_size(mount, 960, 540)
    point = full.camera_to_site(np.array([[1.5, 2.0, 40.0]]))
    assert half.project(point)[0] == pytest.approx(full.project(point)[0] / 2.0, abs=1e-9)
    with pytest.raises(CalibrationError, match=r"640x480 frame does not fit .* 1920x1080"):
        camera_at_size(mount, 640, 480)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"distortion_model": "equidistant"}, "equidistant.*not supported"),
        ({"distortion_coefficients": {"data": [0.1, 0.0, 0.0, 0.0, 0.0, 0.2]}}, "beyond k1"),
        ({"camera_matrix": {"data": [1000, 3, 960, 0, 1000, 540, 0, 0, 1]}}, "no skew"),
        ({"camera_matrix": {"data": [0, 0, 960, 0, 1000, 540, 0, 0, 1]}}, "focal length <= 0"),
        ({"camera_matrix": {"data": [1000, 0, ".nan", 0, 1000, 540, 0, 0, 1]}}, "not finite"),
        ({"camera_matrix": {"data": [1000, 0, 960]}}, "must hold 9 numbers"),
        ({"image_width": None}, "image_width must be a positive integer"),
    ],
)
def test_a_bad_calibration_is_an_error_naming_the_file_and_field(
    tmp_path: Path, change: dict[str, object], message: str
) -> None:
    path = _ros_yaml(tmp_path / "cam.yaml")
    raw = yaml.safe_load(path.read_text(encoding="utf-8")) | change
    if raw["camera_matrix"]["data"][2] == ".nan":
        raw["camera_matrix"]["data"][2] = float("nan")
    path.write_text(yaml.safe_dump(raw), encoding="utf-8")
    with pytest.raises(CalibrationError, match=message) as info:
        read_calibration(path)
    assert str(path) in str(info.value)


def test_the_site_file_and_its_calibration_must_agree(tmp_path: Path) -> None:
    _ros_yaml(tmp_path / "cam.yaml")
    with pytest.raises(SiteFileError, match="width_px 1280 but its calibration says 1920"):
        load_site(_site_with_calibration(tmp_path, "cam.yaml", width_px=1280))
    with pytest.raises(SiteFileError, match="cannot be read"):
        load_site(_site_with_calibration(tmp_path, "missing.yaml"))
    (tmp_path / "junk.yaml").write_bytes(b"\x00\xff: [")
    with pytest.raises(SiteFileError, match=r"junk\.yaml"):
        load_site(_site_with_calibration(tmp_path, "junk.yaml"))
