"""The camera-radar detector node's per-frame handler, in process: frames rendered by the
simulator's mast camera at 400 x 400 (same field of view), JPEG-encoded; radar scans by the
simulator's radar of the same vehicles. Also: a garbage JPEG, and the yolo backend's start-up
errors."""

from __future__ import annotations

import math
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from wz_camera_detector.background import BackgroundSubtractionSettings
from wz_camera_detector.node import CameraDetector, build_detector
from wz_camera_detector.settings import (
    DEFAULT_MODEL_PATH,
    SIMULATION_MODEL_PATH,
    CameraDetectorSettings,
    camera_mount,
    radar_mount,
)
from wz_camera_detector.yolo import ModelLoadError
from wz_shared.messages import (
    CalibrationState,
    CameraFrameMeta,
    DetectionBatch,
    ServiceState,
    VehicleClass,
    VehicleTruth,
)
from wz_shared.site import DEFAULT_SITE_PATH, CameraIntrinsics, SensorMount, load_site
from wz_simulator.sensors.camera import CameraModel, encode_jpeg
from wz_simulator.sensors.radar import RadarModel
from wz_simulator.sensors.scene import WEATHER_PRESETS, static_scene, vehicle_boxes

SITE = load_site(DEFAULT_SITE_PATH)
SIDE_PX = 400
WARM_UP = 15
PERIOD_S = 0.1
SPEED_MPS = 20.0
# Pixel areas scaled from the 1200 x 1200 defaults by (400 / 1200)^2 (as test_background.py).
SETTINGS = CameraDetectorSettings(
    backend="background-subtraction",
    background=BackgroundSubtractionSettings(
        min_blob_area_px=16, score_area_scale_px=170.0, close_kernel_px=5, warm_up_frames=WARM_UP
    ),
)


def vehicle(
    vehicle_id: str, x_m: float, y_m: float, lwh_m: tuple[float, float, float]
) -> VehicleTruth:
    length, width, height = lwh_m
    return VehicleTruth(
        vehicle_id=vehicle_id,
        vehicle_class="truck" if length > 7.5 else "car",
        x_m=x_m,
        y_m=y_m,
        heading_rad=math.pi / 2,
        speed_mps=SPEED_MPS,
        accel_mps2=0.0,
        length_m=length,
        width_m=width,
        height_m=height,
        lane_index=0,
        station_m=0.0,
        offset_m=0.0,
        driver_profile="normal",
    )


# Upstream of the mast (7.5, 980), which looks south; the boxes do not touch in the image.
VEHICLES = (
    vehicle("car-left", -1.83, 960.0, (4.6, 1.8, 1.5)),
    vehicle("truck-right", 1.83, 935.0, (16.5, 2.6, 4.0)),
    vehicle("car-right", 1.83, 958.0, (4.6, 1.8, 1.5)),
)


@pytest.fixture(scope="module")
def small_camera() -> tuple[CameraModel, SensorMount]:
    mount = camera_mount(SITE, None)
    assert isinstance(mount.intrinsics, CameraIntrinsics)
    small = mount.model_copy(
        update={
            "intrinsics": mount.intrinsics.model_copy(
                update={"width_px": SIDE_PX, "height_px": SIDE_PX}
            )
        }
    )
    model = CameraModel.from_scene(small, static_scene(SITE), WEATHER_PRESETS["day"], seed=7)
    return model, small


def frame(model: CameraModel, index: int, traffic: bool) -> tuple[CameraFrameMeta, bytes]:
    stamp = index * PERIOD_S
    vehicles = VEHICLES if traffic else ()
    rendered = model.render(
        vehicle_boxes(vehicles) if vehicles else [], [v.vehicle_id for v in vehicles], stamp
    )
    meta = CameraFrameMeta(
        site=SITE.site_id,
        source_id=model_id(),
        stamp=stamp,
        frame_index=index,
        width_px=SIDE_PX,
        height_px=SIDE_PX,
    )
    return meta, encode_jpeg(rendered.image)


def model_id() -> str:
    return camera_mount(SITE, None).sensor_id


def make_detector(
    mount: SensorMount, with_radar: bool
) -> tuple[CameraDetector, list[tuple[str, str]]]:
    reports: list[tuple[str, str]] = []
    radar = radar_mount(SITE, None) if with_radar else None
    detector = CameraDetector(
        SITE,
        mount,
        radar,
        SETTINGS,
        report=lambda r, d: reports.append((r, d)),
    )
    return detector, reports


def run_frames(
    detector: CameraDetector, model: CameraModel, radar: RadarModel | None, count: int
) -> list[DetectionBatch]:
    batches = []
    for index in range(count):
        traffic = index >= WARM_UP
        meta, jpeg = frame(model, index, traffic)
        if radar is not None and traffic:
            detector.radar_scan(radar.scan(VEHICLES, meta.stamp, index).scan)
        if index < WARM_UP:
            assert detector.state == ServiceState.STARTING
        batch = detector.handle(meta, jpeg, time.monotonic())
        if batch is not None:
            batches.append(batch)
    return batches


def nearest_errors(batch: DetectionBatch) -> list[float]:
    """Distance [m] from each vehicle to the nearest detection."""
    xy = np.array([(d.x_m, d.y_m) for d in batch.detections])
    return [float(np.min(np.hypot(xy[:, 0] - v.x_m, xy[:, 1] - v.y_m))) for v in VEHICLES]


def test_camera_only_detections_at_the_vehicles(
    small_camera: tuple[CameraModel, SensorMount],
) -> None:
    model, mount = small_camera
    detector, reports = make_detector(mount, with_radar=False)
    batches = run_frames(detector, model, None, WARM_UP + 5)

    assert detector.state == ServiceState.RUNNING
    assert [b.frame_index for b in batches] == list(range(WARM_UP, WARM_UP + 5))
    last = batches[-1]
    assert last.source_id == model_id() and last.stamp == pytest.approx((WARM_UP + 4) * PERIOD_S)
    # Confirmed after min_hits (3) frames: one detection per vehicle.
    assert len(last.detections) == len(VEHICLES)
    car_left, truck, car_right = nearest_errors(last)
    # The background backend cannot classify, so the truck is ranged as a car: the car cuboid
    # that best fits its box lands about (16.5 - 4.6) / 2 m short, measured 6.9.
    assert max(car_left, car_right) < 1.0, (car_left, car_right)
    assert 4.0 < truck < 7.5, truck
    assert all(d.speed_mps is None for d in last.detections)
    assert all(d.local_track_id is not None for d in last.detections)
    assert reports == []
    # A camera flagged as knocked: the node is degraded while it learns its pose again.
    detector.calibration.log.enter(CalibrationState.BUMPED, last.stamp, "test: turned")
    assert detector.state == ServiceState.DEGRADED


def test_fused_detections_carry_the_radar_speed(
    small_camera: tuple[CameraModel, SensorMount],
) -> None:
    model, mount = small_camera
    detector, reports = make_detector(mount, with_radar=True)
    radar_site_mount = radar_mount(SITE, None)
    assert radar_site_mount is not None
    radar = RadarModel(radar_site_mount, WEATHER_PRESETS["day"], seed=3, site_id=SITE.site_id)
    batches = run_frames(detector, model, radar, WARM_UP + 5)

    last = batches[-1]
    car_left, truck, car_right = nearest_errors(last)
    # Fused position = the radar's range along the camera's bearing, and the radar ranges the
    # near face: measured 1.66 and 2.21 m for the cars (about half a car length), 8.2 m for the
    # truck (half its length).
    assert max(car_left, car_right) < 2.5, (car_left, car_right)
    assert truck < 9.0, truck
    speeds = [abs(d.speed_mps) for d in last.detections if d.speed_mps is not None]
    assert speeds, last.detections
    assert all(speed == pytest.approx(SPEED_MPS, abs=2.0) for speed in speeds), speeds
    assert reports == []


def test_a_new_run_starts_the_image_tracker_and_the_radar_again(
    small_camera: tuple[CameraModel, SensorMount],
) -> None:
    """A restarted simulation: the frames' stamps start again. Two frames are out of order;
    from the third, a new run: detections again, fused with the new run's radar scans, local
    ids after the old ones."""
    model, mount = small_camera
    detector, reports = make_detector(mount, with_radar=True)
    radar_site_mount = radar_mount(SITE, None)
    assert radar_site_mount is not None
    radar = RadarModel(radar_site_mount, WEATHER_PRESETS["day"], seed=3, site_id=SITE.site_id)
    old = run_frames(detector, model, radar, WARM_UP + 5)  # stamps 0 to 1.9 s
    old_ids = {d.local_track_id for d in old[-1].detections}
    assert old_ids and detector.runs == 1
    new: list[DetectionBatch | None] = []
    for index in range(6):  # stamps 0.05 to 0.55 s
        meta, jpeg = frame(model, WARM_UP + index, traffic=True)
        meta = meta.model_copy(update={"stamp": 0.05 + index * PERIOD_S})
        detector.radar_scan(radar.scan(VEHICLES, meta.stamp, 100 + index).scan)
        new.append(detector.handle(meta, jpeg, time.monotonic()))
    assert new[:2] == [None, None]
    assert [reason for reason, _ in reports] == ["out_of_order", "out_of_order"]
    assert detector.runs == 2 and detector.last_stamp_s == pytest.approx(0.55)
    last = new[-1]
    assert last is not None and last.stamp == pytest.approx(0.55)
    assert len(last.detections) == len(VEHICLES)  # confirmed again after min_hits frames
    new_ids = {d.local_track_id for d in last.detections}
    assert min(i for i in new_ids if i is not None) > max(i for i in old_ids if i is not None)
    assert any(d.speed_mps is not None for d in last.detections)  # the new run's radar


def test_a_garbage_jpeg_is_counted_and_skipped(
    small_camera: tuple[CameraModel, SensorMount],
) -> None:
    model, mount = small_camera
    detector, reports = make_detector(mount, with_radar=False)
    meta, _ = frame(model, 0, traffic=False)
    assert detector.handle(meta, b"\xff\xd8garbage, not a JPEG", time.monotonic()) is None
    assert [reason for reason, _ in reports] == ["bad_image"]
    # The next good frame is processed as usual (warm-up: nothing published yet).
    meta, jpeg = frame(model, 1, traffic=False)
    assert detector.handle(meta, jpeg, time.monotonic()) is None
    assert detector.backend.frames_seen == 1  # type: ignore[attr-defined]
    assert len(reports) == 1


def test_without_a_model_path_the_node_takes_the_shipped_model_for_the_frames_source() -> None:
    mount = camera_mount(SITE, None)
    width, height = mount.intrinsics.width_px, mount.intrinsics.height_px  # type: ignore[union-attr]
    detector = CameraDetector(SITE, mount, None, CameraDetectorSettings(), report=lambda r, d: None)
    assert detector.backend.model_path == DEFAULT_MODEL_PATH  # type: ignore[attr-defined]
    ok, jpeg = cv2.imencode(".jpg", np.full((height, width, 3), 90, dtype=np.uint8))
    assert ok
    backends: set[int] = set()
    sequence = [(True, SIMULATION_MODEL_PATH), (True, SIMULATION_MODEL_PATH)]
    sequence += [(False, DEFAULT_MODEL_PATH), (True, SIMULATION_MODEL_PATH)] * 2
    for index, (rendered, model) in enumerate(sequence):
        meta = CameraFrameMeta(
            site=SITE.site_id,
            source_id=mount.sensor_id,
            stamp=0.1 * (index + 1),
            frame_index=index,
            width_px=width,
            height_px=height,
            rendered=rendered,
        )
        detector.handle(meta, jpeg.tobytes(), time.monotonic())
        assert detector.backend.model_path == model  # type: ignore[attr-defined]
        backends.add(id(detector.backend))
    assert len(backends) == 2  # each model loaded once, however often the source switches
    # A model named in the settings is kept whatever the frames are.
    named = CameraDetectorSettings(model_path=SIMULATION_MODEL_PATH)
    detector = CameraDetector(SITE, mount, None, named, report=lambda r, d: None)
    detector.handle(meta, jpeg.tobytes(), time.monotonic())
    assert detector.backend.model_path == SIMULATION_MODEL_PATH  # type: ignore[attr-defined]


def test_yolo_with_a_missing_model_fails_at_start_up(tmp_path: Path) -> None:
    settings = CameraDetectorSettings(backend="yolo", model_path=tmp_path / "missing.onnx")
    with pytest.raises(ModelLoadError, match=r"missing\.onnx"):
        CameraDetector(SITE, camera_mount(SITE, None), None, settings, report=lambda r, d: None)
    with pytest.raises(SystemExit, match=r"camera-detector: .*missing\.onnx"):
        build_detector(SITE, settings, report=lambda r, d: None)


def test_sensor_selection() -> None:
    assert camera_mount(SITE, None).kind == "camera"
    radar = radar_mount(SITE, None)
    assert radar is not None and radar.kind == "radar"
    assert radar_mount(SITE, "none") is None
    with pytest.raises(ValueError, match="not a radar"):
        radar_mount(SITE, camera_mount(SITE, None).sensor_id)


def test_camera_only_objects_ranged_beyond_max_range_are_not_published() -> None:
    from wz_camera_detector.association import FusedObject

    detector, _ = make_detector(camera_mount(SITE, None), with_radar=True)
    mount = camera_mount(SITE, None).pose
    limit = detector.settings.max_range_m
    heading = math.radians(-90.0)  # down the road, towards approaching traffic

    def at(range_m: float, source: str) -> FusedObject:
        return FusedObject(
            source=source,  # type: ignore[arg-type]
            x_m=mount.x_m + range_m * math.cos(heading),
            y_m=mount.y_m + range_m * math.sin(heading),
            covariance_m2=np.eye(2),
            object_class=VehicleClass.CAR,
            score=0.9,
            speed_mps=None,
            camera_local_id=1,
            radar_target_index=None,
        )

    fused = [at(limit - 1.0, "camera"), at(limit + 1.0, "camera"), at(limit + 1.0, "camera+radar")]
    kept = detector._within_range(fused)
    assert [(o.source, round(math.hypot(o.x_m - mount.x_m, o.y_m - mount.y_m))) for o in kept] == [
        ("camera", round(limit - 1.0)),
        ("camera+radar", round(limit + 1.0)),
    ]
