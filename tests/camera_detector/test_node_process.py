"""The camera-radar detector node as its own process on real Zenoh, with the shipped YOLO model:
rendered frames and radar scans in, fused detections out, bad input counted, the node alive."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.camera_detector.test_node import vehicle
from wz_camera_detector.settings import camera_mount, radar_mount
from wz_shared.bus import Bus, Subscription
from wz_shared.codec import encode_camera_frame
from wz_shared.messages import (
    CalibrationState,
    CameraFrameMeta,
    DetectionBatch,
    PoseCorrection,
    RadarScan,
    SensorCalibration,
    ServiceState,
    ServiceStatus,
    VehicleTruth,
)
from wz_shared.settings import BusSettings
from wz_shared.site import DEFAULT_SITE_PATH, load_site
from wz_simulator.sensors.camera import CameraModel, encode_jpeg
from wz_simulator.sensors.radar import RadarModel
from wz_simulator.sensors.scene import WEATHER_PRESETS, static_scene, vehicle_boxes

ROOT = Path(__file__).resolve().parents[2]
SITE = load_site(DEFAULT_SITE_PATH)
CAMERA = camera_mount(SITE, None)
RADAR = radar_mount(SITE, None)
PERIOD_S = 0.1
# Upstream of the mast (7.5, 980), looking south: 40-75 m out, whole in the picture.
VEHICLES = (
    vehicle("car-left", -1.83, 925.0, (4.6, 1.8, 1.5)),
    vehicle("truck-right", 1.83, 895.0, (16.5, 2.6, 4.0)),
    vehicle("car-right", 1.83, 935.0, (4.6, 1.8, 1.5)),
)


def traffic_at(stamp_s: float) -> list[VehicleTruth]:
    """The test's three vehicles driving north at their speed, at ``stamp_s``."""
    return [
        vehicle(
            v.vehicle_id, v.x_m, v.y_m + v.speed_mps * stamp_s, (v.length_m, v.width_m, v.height_m)
        )
        for v in VEHICLES
    ]


def wait_status(
    status: Subscription[ServiceStatus], condition: Callable[[ServiceStatus], bool], what: str
) -> ServiceStatus:
    deadline = time.monotonic() + 20.0
    while time.monotonic() < deadline:
        message = status.recv(0.5)
        if message is not None and condition(message):
            return message
    pytest.fail(f"timed out waiting for the node's status to show {what}")


def test_node_process_detects_fuses_and_survives_bad_input(port: int) -> None:
    assert RADAR is not None
    camera = CameraModel.from_scene(CAMERA, static_scene(SITE), WEATHER_PRESETS["day"], seed=3)
    radar = RadarModel(RADAR, WEATHER_PRESETS["day"], seed=4, site_id=SITE.site_id)
    settings = BusSettings(listen_endpoints=[f"tcp/127.0.0.1:{port}"], connect_endpoints=[])
    env = {k: v for k, v in os.environ.items() if not k.startswith("WZ_")}
    env.update(
        WZ_BUS_CONNECT_ENDPOINTS=f"tcp/127.0.0.1:{port}",
        WZ_BUS_LISTEN_ENDPOINTS="",
        WZ_STATUS_PERIOD_S="0.2",
        WZ_LOG_FORMAT="json",
    )
    with Bus.open(settings, site=SITE.site_id, service="node-test") as bus:
        raw_key = bus.keys.raw_camera(CAMERA.sensor_id)
        radar_key = bus.keys.raw_radar(RADAR.sensor_id)
        frames = bus.publisher(raw_key, CameraFrameMeta, block=True)
        scans = bus.publisher(radar_key, RadarScan, block=True)
        detections = bus.subscribe(bus.keys.detections(CAMERA.sensor_id), DetectionBatch)
        status = bus.subscribe(
            bus.keys.status("camera-detector"), ServiceStatus, mode="ring", capacity=1
        )
        calibrations = bus.subscribe(bus.keys.calibration_all, SensorCalibration)
        node = subprocess.Popen(
            [sys.executable, "-m", "wz_camera_detector.node"], cwd=ROOT, env=env
        )
        try:
            assert frames.wait_for_subscribers(60.0), "the node never subscribed"
            assert scans.wait_for_subscribers(10.0), "the node never subscribed to the radar"
            index = 0

            def send(stamp_s: float, jpeg: bytes | None = None, size: int = 1200) -> None:
                nonlocal index
                truth = traffic_at(stamp_s)
                scans.put(radar.scan(truth, stamp_s, index).scan)
                if jpeg is None:
                    image = camera.render(
                        vehicle_boxes(truth), [v.vehicle_id for v in truth], stamp_s
                    ).image
                    jpeg = encode_jpeg(image)
                meta = CameraFrameMeta(
                    site=SITE.site_id,
                    source_id=CAMERA.sensor_id,
                    stamp=stamp_s,
                    frame_index=index,
                    width_px=size,
                    height_px=size,
                    rendered=True,  # the simulator's model for its renders
                )
                frames.put_bytes(encode_camera_frame(meta, jpeg))
                index += 1

            # Frames one at a time (the node keeps the newest); tracks confirm on the third.
            batch = None
            for step in range(8):
                send(step * PERIOD_S)
                batch = detections.recv(15.0)
                assert batch is not None, f"no batch for frame {step}"
            assert batch is not None
            truth = traffic_at(batch.stamp)
            assert len(batch.detections) == len(truth)
            for v in truth:
                nearest = min(
                    batch.detections, key=lambda d: np.hypot(d.x_m - v.x_m, d.y_m - v.y_m)
                )
                assert np.hypot(nearest.x_m - v.x_m, nearest.y_m - v.y_m) < 1.5, (v, nearest)
                assert nearest.object_class == v.vehicle_class
                assert nearest.speed_mps == pytest.approx(v.speed_mps, abs=2.0)  # radar paired

            def counted(key: str, reason: str) -> None:
                name = f"{key}|{reason}"
                wait_status(status, lambda s: s.invalid_counts.get(name, 0) >= 1, name)

            stamp = 1.0
            frames.put_bytes(b"\x00 garbage, not a frame")
            counted(raw_key, "bad_magic")
            send(stamp, jpeg=b"\xff\xd8\xff\xe0 corrupt JPEG body")
            counted(raw_key, "bad_image")
            stamp += PERIOD_S
            send(stamp, jpeg=b"")
            counted(raw_key, "bad_jpeg")
            stamp += PERIOD_S
            ok, small = cv2.imencode(".jpg", np.zeros((480, 640, 3), np.uint8))
            assert ok
            send(stamp, jpeg=small.tobytes())  # metadata says 1200 x 1200
            counted(raw_key, "wrong_size")
            stamp += PERIOD_S
            send(stamp, jpeg=small.tobytes(), size=640)  # honest size, but smaller than the ROI
            counted(raw_key, "wrong_size")
            nan_scan = json.loads(radar.scan(traffic_at(stamp), stamp, 99).scan.model_dump_json())
            nan_scan["targets"] = [
                {"range_m": "NaN", "azimuth_rad": 0.1, "radial_speed_mps": -20.0, "rcs_dbsm": 10.0}
            ]
            scans.put_bytes(json.dumps(nan_scan).encode())
            counted(radar_key, "invalid")

            # Still detecting: the next good frame gives a batch with the vehicles.
            for _ in range(4):
                stamp += PERIOD_S
                send(stamp)
                batch = detections.recv(15.0)
                assert batch is not None
            assert batch is not None and len(batch.detections) == len(VEHICLES)
            health = wait_status(status, lambda s: s.state == ServiceState.RUNNING, "running")
            assert health.pid == node.pid
            assert node.poll() is None
            # Each of its sensors' self-calibration went out; with no LiDAR on the bus to learn
            # against, both stay at the site file's pose and clock.
            learned = {m.source_id: m for m in iter(lambda: calibrations.recv(1.0), None)}
            assert set(learned) == {CAMERA.sensor_id, RADAR.sensor_id}
            assert learned[CAMERA.sensor_id].sensor_kind == "camera"
            assert learned[RADAR.sensor_id].sensor_kind == "radar"
            for message in learned.values():
                assert message.state == CalibrationState.PRIOR
                assert message.correction == PoseCorrection()
                assert message.clock_offset_s == 0.0
        finally:
            node.send_signal(signal.SIGTERM)
            assert node.wait(15.0) == 0
