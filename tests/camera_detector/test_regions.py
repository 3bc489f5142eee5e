"""The detector's region of interest and far-field tiles from the road's geometry (issue 25)."""

from __future__ import annotations

import numpy as np
import pytest

from wz_camera_detector.node import make_backend
from wz_camera_detector.regions import camera_at_size, detector_regions
from wz_camera_detector.settings import CameraDetectorSettings
from wz_camera_detector.yolo import YoloOnnxDetector
from wz_shared.site import DEFAULT_SITE_PATH, Site, load_site
from wz_shared.site_generator import generate_site

INPUT_PX = 480


def iou(a: tuple[int, int, int, int], b: tuple[int, int, int, int]) -> float:
    x0, y0 = max(a[0], b[0]), max(a[1], b[1])
    x1, y1 = min(a[2], b[2]), min(a[3], b[3])
    inter = max(0, x1 - x0) * max(0, y1 - y0)
    area = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1])
    return inter / (area - inter)


def camera_of(site: Site):
    return next(m for m in site.sensors if m.kind == "camera")


def test_on_the_default_site_geometry_finds_the_roi_the_model_was_trained_on() -> None:
    """The shipped model's ROI and tile were drawn by hand on the default camera's frame; the
    geometry, which knows nothing of them, lands on nearly the same boxes."""
    site = load_site(DEFAULT_SITE_PATH)
    regions = detector_regions(site, camera_of(site), INPUT_PX)
    assert regions.roi_xyxy_px is not None
    assert iou(regions.roi_xyxy_px, (480, 440, 1200, 1160)) > 0.75
    assert len(regions.tiles_xyxy_px) == 1
    assert iou(regions.tiles_xyxy_px[0], (540, 440, 780, 560)) > 0.6


@pytest.mark.parametrize("seed", range(12))
def test_any_camera_gets_a_roi_that_holds_every_vehicle_on_the_approach(seed: int) -> None:
    site = generate_site(seed)
    mount = camera_of(site)
    regions = detector_regions(site, mount, INPUT_PX)
    camera = camera_at_size(mount, mount.intrinsics.width_px, mount.intrinsics.height_px)
    assert regions.roi_xyxy_px is not None
    x0, y0, x1, y1 = regions.roi_xyxy_px
    assert 0 <= x0 < x1 <= camera.width_px and 0 <= y0 < y1 <= camera.height_px
    station, _ = site.road_frame.to_road(mount.pose.x_m, mount.pose.y_m)
    for upstream in (30.0, 60.0, 100.0, 150.0):
        for lane in site.lanes:
            x, y = site.road_frame.to_site(float(station) - upstream, lane.center_offset_m)
            # a car's bottom and a truck's roof
            corners = np.array([[float(x), float(y), 0.0], [float(x), float(y), 4.0]])
            uv, _ = camera.project(corners)
            inside = (uv[:, 0] >= x0) & (uv[:, 0] <= x1) & (uv[:, 1] >= y0) & (uv[:, 1] <= y1)
            assert inside.all(), (seed, upstream, lane.index, uv, regions.roi_xyxy_px)
    for tile in regions.tiles_xyxy_px:
        assert 0 <= tile[0] < tile[2] <= camera.width_px
        assert 0 <= tile[1] < tile[3] <= camera.height_px
        # magnified, never beyond 4x
        assert max(tile[2] - tile[0], tile[3] - tile[1]) >= INPUT_PX / 4
    # a tile exists exactly when a car 150 m away is small in the letterboxed ROI
    if regions.tile_from_m is not None:
        assert regions.tile_from_m < 200.0


def test_a_camera_that_does_not_see_the_road_gets_no_roi() -> None:
    site = load_site(DEFAULT_SITE_PATH)
    mount = camera_of(site)
    skyward = mount.model_copy(
        update={"pose": mount.pose.model_copy(update={"yaw_deg": 90.0, "pitch_deg": 60.0})}
    )
    regions = detector_regions(site, skyward, INPUT_PX)
    assert regions.roi_xyxy_px is None and regions.tiles_xyxy_px == ()


def test_the_detector_looks_where_the_geometry_says_unless_the_settings_say_otherwise() -> None:
    site = generate_site(3)  # a 1280x720 camera: the model's own ROI is not even in its frame
    mount = camera_of(site)
    backend = make_backend(CameraDetectorSettings(), site, mount)
    assert isinstance(backend, YoloOnnxDetector)
    expected = detector_regions(site, mount, max(backend.input_size))
    assert backend.roi_xyxy_px == expected.roi_xyxy_px
    assert backend.tiles_xyxy_px == expected.tiles_xyxy_px
    image = np.zeros((720, 1280, 3), np.uint8)
    assert backend.detect(image) == []  # runs on this format (the old ROI refused it)
    settings = CameraDetectorSettings(roi_xyxy_px=(0, 0, 640, 360), tiles_xyxy_px=())
    overridden = make_backend(settings, site, mount)
    assert isinstance(overridden, YoloOnnxDetector)
    assert overridden.roi_xyxy_px == (0, 0, 640, 360) and overridden.tiles_xyxy_px == ()
