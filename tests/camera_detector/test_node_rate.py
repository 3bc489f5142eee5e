"""The node at a camera's full rate: the detector on every fourth frame of 30 fps (each frame of
10 fps), optical flow between, a batch per frame. Frames rendered by the simulator's mast camera
(the default site's, 1200 x 1200) with vehicles moving towards it, detected by the shipped
simulator model."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from wz_camera_detector.following import FollowStep
from wz_camera_detector.node import CameraDetector
from wz_camera_detector.settings import CameraDetectorSettings, camera_mount
from wz_shared.messages import CameraFrameMeta, DetectionBatch, VehicleTruth
from wz_shared.site import DEFAULT_SITE_PATH, load_site
from wz_simulator.sensors.camera import CameraModel, encode_jpeg
from wz_simulator.sensors.scene import WEATHER_PRESETS, static_scene, vehicle_boxes

SITE = load_site(DEFAULT_SITE_PATH)
SPEED_MPS = 20.0
# Upstream of the mast (7.5, 980), which looks south; they drive north, towards it.
START = (
    ("car-left", -1.83, 880.0, (4.6, 1.8, 1.5)),
    ("truck-right", 1.83, 862.0, (16.5, 2.6, 4.0)),
)
SETTINGS = CameraDetectorSettings(calibration={"enabled": False})


def vehicles_at(stamp_s: float) -> list[VehicleTruth]:
    return [
        VehicleTruth(
            vehicle_id=name,
            vehicle_class="truck" if lwh[0] > 7.5 else "car",
            x_m=x,
            y_m=y + SPEED_MPS * stamp_s,
            heading_rad=math.pi / 2,
            speed_mps=SPEED_MPS,
            accel_mps2=0.0,
            length_m=lwh[0],
            width_m=lwh[1],
            height_m=lwh[2],
            lane_index=0,
            station_m=0.0,
            offset_m=0.0,
            driver_profile="normal",
        )
        for name, x, y, lwh in START
    ]


@pytest.fixture(scope="module")
def camera() -> CameraModel:
    return CameraModel.from_scene(
        camera_mount(SITE, None), static_scene(SITE), WEATHER_PRESETS["day"], seed=7
    )


def run(
    camera: CameraModel,
    fps: float,
    frames: int,
    settings: CameraDetectorSettings = SETTINGS,
    tiles: list[bool] | None = None,
) -> tuple[CameraDetector, list[DetectionBatch | None]]:
    """The frames through the node's handler; ``tiles`` gets, for each frame the detector ran
    on, whether its far-field tile ran."""
    mount = camera_mount(SITE, None)
    detector = CameraDetector(SITE, mount, None, settings, report=lambda r, d: None, rendered=True)
    step = detector.images.step

    def watched(image: np.ndarray, stamp_s: float, detect: bool) -> FollowStep:
        result = step(image, stamp_s, detect)
        if tiles is not None and detect:
            tiles.append(result.tiles)
        return result

    detector.images.step = watched  # type: ignore[method-assign]
    batches = []
    for index in range(frames):
        stamp = index / fps
        vehicles = vehicles_at(stamp)
        image = camera.render(
            vehicle_boxes(vehicles), [v.vehicle_id for v in vehicles], stamp
        ).image
        meta = CameraFrameMeta(
            site=SITE.site_id,
            source_id=mount.sensor_id,
            stamp=stamp,
            frame_index=index,
            width_px=image.shape[1],
            height_px=image.shape[0],
            rendered=True,
        )
        batches.append(detector.handle(meta, encode_jpeg(image), time.monotonic()))
    return detector, batches


def errors(batch: DetectionBatch) -> list[float]:
    """Distance [m] from each vehicle to the nearest detection."""
    xy = np.array([(d.x_m, d.y_m) for d in batch.detections]).reshape(-1, 2)
    if len(xy) == 0:
        return [math.inf] * len(START)
    return [
        float(np.min(np.hypot(xy[:, 0] - v.x_m, xy[:, 1] - v.y_m)))
        for v in vehicles_at(batch.stamp)
    ]


def test_at_30_fps_the_detector_runs_on_every_fourth_frame_and_flow_fills_the_rest(
    camera: CameraModel,
) -> None:
    tiles: list[bool] = []
    detector, batches = run(camera, 30.0, 24, tiles=tiles)
    assert detector.detections_run == 6  # frames 0, 4, ..., 20
    assert tiles == [True, False, True, False, True, False]  # the far tile at every second
    assert all(batch is not None for batch in batches)
    # Confirmed at the second detection (frame 4, flow between): from then on each frame the
    # detector ran on puts both vehicles on the road near where they are, within the camera's
    # own range uncertainty at 80-120 m (1 m + 3 % of the range: 3.7-4.6 m); a frame flow
    # filled is published empty (its boxes hold the last detection's ranging error: the
    # fusion tracker would count it again).
    for batch in batches[4:]:
        assert batch is not None
        if batch.frame_index % 4:
            assert batch.detections == []
            continue
        car, truck = errors(batch)
        assert car < 3.0, (batch.frame_index, car)
        assert truck < 4.5, (batch.frame_index, truck)


def test_flow_frames_objects_go_on_the_bus_when_the_settings_ask(camera: CameraModel) -> None:
    """``publish_followed``: every frame's objects, flow's boxes ranged as detections are:
    both vehicles on the road near where they are on each frame from the confirmation on
    (every frame's detections averaged by the image tracker do better, 1.0 and 1.9 m at most
    here: the price of detecting a quarter as often, before radar fusion)."""
    settings = CameraDetectorSettings(calibration={"enabled": False}, publish_followed=True)
    _, batches = run(camera, 30.0, 12, settings)
    for batch in batches[4:]:
        assert batch is not None
        car, truck = errors(batch)
        assert car < 3.0, (batch.frame_index, car)
        assert truck < 4.5, (batch.frame_index, truck)


def test_at_10_fps_the_detector_runs_on_every_frame(camera: CameraModel) -> None:
    tiles: list[bool] = []
    detector, batches = run(camera, 10.0, 6, tiles=tiles)
    assert detector.detections_run == 6
    assert tiles == [True] * 6  # nothing between for flow to carry a far car: the tile each
    last = batches[-1]
    assert last is not None and max(errors(last)) < 4.0


def test_with_a_period_of_zero_the_detector_runs_on_every_frame(camera: CameraModel) -> None:
    every_frame = CameraDetectorSettings(calibration={"enabled": False}, detection_period_s=0.0)
    detector, _ = run(camera, 30.0, 5, every_frame)
    assert detector.detections_run == 5
