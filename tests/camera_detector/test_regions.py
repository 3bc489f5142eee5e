"""The detector's region of interest and far-field tiles from the road's geometry (issue 25)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from wz_camera_detector.node import (
    CALIBRATED_MARGIN_DEG,
    SETUP_MARGIN_DEG,
    CameraDetector,
    cut_by_view,
    make_backend,
)
from wz_camera_detector.regions import camera_at_size, detector_regions
from wz_camera_detector.settings import CameraDetectorSettings
from wz_camera_detector.yolo import YoloOnnxDetector
from wz_shared.messages import CalibrationState
from wz_shared.site import DEFAULT_SITE_PATH, SensorMount, Site, load_site
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
    # until its pose is learned, for any aim a technician's set-up leaves
    expected = detector_regions(site, mount, max(backend.input_size), margin_deg=SETUP_MARGIN_DEG)
    assert backend.roi_xyxy_px == expected.roi_xyxy_px
    assert backend.tiles_xyxy_px == expected.tiles_xyxy_px
    image = np.zeros((720, 1280, 3), np.uint8)
    assert backend.detect(image) == []  # runs on this format (the old ROI refused it)
    settings = CameraDetectorSettings(roi_xyxy_px=(0, 0, 640, 360), tiles_xyxy_px=())
    overridden = make_backend(settings, site, mount)
    assert isinstance(overridden, YoloOnnxDetector)
    assert overridden.roi_xyxy_px == (0, 0, 640, 360) and overridden.tiles_xyxy_px == ()


def _turned(mount: SensorMount, yaw_deg: float, pitch_deg: float) -> SensorMount:
    pose = mount.pose.model_copy(
        update={
            "yaw_deg": mount.pose.yaw_deg + yaw_deg,
            "pitch_deg": mount.pose.pitch_deg + pitch_deg,
        }
    )
    return mount.model_copy(update={"pose": pose})


def _far_road_px(site: Site, mount: SensorMount) -> np.ndarray:
    """Where a car's sides (at the ground and a truck's roof) 100-150 m upstream on each lane
    fall in the frame of a camera at ``mount`` (its true pose)."""
    camera = camera_at_size(mount, mount.intrinsics.width_px, mount.intrinsics.height_px)
    station, _ = site.road_frame.to_road(mount.pose.x_m, mount.pose.y_m)
    points = []
    for upstream in (100.0, 125.0, 150.0):
        for lane in site.lanes:
            for side in (-0.9, 0.9):
                offset = lane.center_offset_m + side
                x, y = site.road_frame.to_site(float(station) - upstream, offset)
                points += [[float(x), float(y), 0.0], [float(x), float(y), 4.0]]
    uv, _ = camera.project(np.array(points))
    return uv


def _holds(box: tuple[int, int, int, int] | None, uv: np.ndarray, inset_px: float) -> bool:
    assert box is not None
    x0, y0, x1, y1 = box
    across = (uv[:, 0] >= x0 + inset_px) & (uv[:, 0] <= x1 - inset_px)
    return bool((across & (uv[:, 1] >= y0) & (uv[:, 1] <= y1)).all())


@pytest.mark.parametrize("seed", [None, 3, 8])
def test_with_a_margin_the_regions_hold_the_road_for_a_camera_turned_off_its_site_pose(
    seed: int | None,
) -> None:
    """A camera turned a degree or two off its site file's aim (what a technician leaves) sees
    the far road elsewhere: regions drawn with the set-up margin still hold it, with room for
    a car's half width, where regions drawn for the nominal aim alone do not."""
    site = load_site(DEFAULT_SITE_PATH) if seed is None else generate_site(seed)
    mount = camera_of(site)
    wide = detector_regions(site, mount, INPUT_PX, margin_deg=SETUP_MARGIN_DEG)
    tight = detector_regions(site, mount, INPUT_PX)
    cut_somewhere = False
    for yaw, pitch in ((-2.5, 0.0), (2.5, 0.0), (-1.0, 1.2), (1.0, -1.2), (2.9, 1.4)):
        uv = _far_road_px(site, _turned(mount, yaw, pitch))
        assert _holds(wide.roi_xyxy_px, uv, 3.0), (yaw, pitch, uv, wide.roi_xyxy_px)
        cut_somewhere |= not _holds(tight.roi_xyxy_px, uv, 3.0)
    assert cut_somewhere
    x0, y0, x1, y1 = tight.roi_xyxy_px or (0, 0, 0, 0)
    wx0, wy0, wx1, wy1 = wide.roi_xyxy_px or (0, 0, 0, 0)
    assert wx0 <= x0 and wy0 <= y0 and wx1 >= x1 and wy1 >= y1
    with pytest.raises(ValueError, match="margin_deg"):
        detector_regions(site, mount, INPUT_PX, margin_deg=(-1.0, 0.0))


def test_a_box_at_the_rois_edge_that_a_tile_holds_whole_is_not_cut() -> None:
    """A far car at the ROI's left edge is whole in the far-field tile: ranged. At the ROI's
    edge outside every tile, or at a tile's edge that the ROI does not hold, it is cut."""
    backend = SimpleNamespace(
        roi_xyxy_px=(550, 450, 1200, 1120), tiles_xyxy_px=((530, 410, 690, 570),)
    )
    assert not cut_by_view((552.0, 470.0, 560.0, 478.0), backend, 1200, 1200)  # in the tile
    assert cut_by_view((552.0, 700.0, 600.0, 740.0), backend, 1200, 1200)  # no tile holds it
    assert cut_by_view((531.0, 470.0, 548.0, 478.0), backend, 1200, 1200)  # tile's edge, out of ROI
    assert not cut_by_view((700.0, 600.0, 760.0, 640.0), backend, 1200, 1200)
    assert cut_by_view((700.0, 1100.0, 800.0, 1119.0), backend, 1200, 1200)  # ROI's bottom
    frame_only = SimpleNamespace(roi_xyxy_px=None, tiles_xyxy_px=())
    assert cut_by_view((0.0, 10.0, 40.0, 40.0), frame_only, 1200, 1200)
    assert not cut_by_view((10.0, 10.0, 40.0, 40.0), frame_only, 1200, 1200)


def test_the_node_draws_its_regions_again_for_the_learned_pose() -> None:
    """Until the camera's pose is learned the detector looks with the set-up margin; once the
    pose is learned (here: 1.2 deg of yaw, 0.3 of pitch) it looks round the learned aim with
    the calibrated margin, which holds the far road as the turned camera sees it."""
    site = load_site(DEFAULT_SITE_PATH)
    mount = camera_of(site)
    width, height = mount.intrinsics.width_px, mount.intrinsics.height_px
    detector = CameraDetector(site, mount, None, CameraDetectorSettings(), report=lambda r, d: None)
    backend = detector.backend
    assert isinstance(backend, YoloOnnxDetector)
    size = max(backend.input_size)
    setup = detector_regions(site, mount, size, margin_deg=SETUP_MARGIN_DEG)
    assert backend.roi_xyxy_px == setup.roi_xyxy_px
    detector.follow_calibration(width, height)  # nothing learned: nothing drawn again
    assert backend.roi_xyxy_px == setup.roi_xyxy_px

    calibration = detector.calibration
    calibration.std = np.full(7, 0.02)
    calibration.take(np.array([-1.2, 0.3, 0.0, 0.0, 0.0, 0.0, 0.06]))
    calibration.log.enter(CalibrationState.CALIBRATED, 100.0, "test")
    detector.follow_calibration(width, height)
    learned = detector_regions(site, detector.camera_mount, size, margin_deg=CALIBRATED_MARGIN_DEG)
    assert detector.camera_mount.pose.yaw_deg == pytest.approx(mount.pose.yaw_deg - 1.2)
    assert backend.roi_xyxy_px == learned.roi_xyxy_px
    assert backend.tiles_xyxy_px == learned.tiles_xyxy_px
    uv = _far_road_px(site, _turned(mount, -1.2, 0.3))
    assert _holds(learned.roi_xyxy_px, uv, 3.0)
    assert _holds(learned.tiles_xyxy_px[0], uv[uv[:, 1] < learned.tiles_xyxy_px[0][3]], 3.0)
    assert not _holds(detector_regions(site, mount, size).roi_xyxy_px, uv, 3.0)

    calibration.log.enter(CalibrationState.BUMPED, 200.0, "test")
    detector.follow_calibration(width, height)  # knocked: the set-up margin again
    assert (
        backend.roi_xyxy_px
        == detector_regions(
            site, detector.camera_mount, size, margin_deg=SETUP_MARGIN_DEG
        ).roi_xyxy_px
    )
