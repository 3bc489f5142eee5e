"""Camera-radar detector: YOLO inference per frame, the whole per-frame work, and the node on the bus.

Frames come from the simulated work zone (default site, camera 1200 x 1200 at 10 Hz, radar at
15 Hz, 1800 veh/h with 20 % trucks, day), rendered once before measuring:

- inference: the shipped model through :class:`YoloOnnxDetector` (ROI crop and letterbox,
  ONNX Runtime with 2 threads, decode and NMS), median and p90 per step;
- per frame: :meth:`CameraDetector.handle` (JPEG decode, detection, image tracking, ranging,
  radar fusion, the message), median and p99;
- service: the node as its own process on real Zenoh (this process listens on a free loopback
  port, the node connects), camera frames published at 10 Hz and radar scans at 15 Hz on their
  recorded schedule in wall-clock time; how many frames came back as detection batches, the
  node's own latency (frame taken from the queue to publication) and the end-to-end latency
  (publication of the frame to receipt of its batch).
"""

from __future__ import annotations

import logging
import os
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from benchmarks.common import ROOT, free_port
from wz_camera_detector.node import CameraDetector, make_backend
from wz_camera_detector.settings import (
    SIMULATION_MODEL_PATH,
    CameraDetectorSettings,
    camera_mount,
    radar_mount,
)
from wz_camera_detector.yolo import YoloOnnxDetector
from wz_shared.bus import Bus
from wz_shared.codec import encode_camera_frame
from wz_shared.messages import CameraFrameMeta, DetectionBatch, RadarScan
from wz_shared.settings import BusSettings
from wz_shared.site import DEFAULT_SITE_PATH, Site, load_site
from wz_simulator.sensors.rig import CameraOutput, RadarOutput, SensorRig
from wz_simulator.sensors.scene import WEATHER_PRESETS
from wz_simulator.settings import SimulatorSettings
from wz_simulator.traffic.world import TrafficWorld

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Recorded:
    """Camera frames and radar scans in firing order: (stamp, kind, payload)."""

    events: list[tuple[float, str, Any]]

    def frames(self) -> list[tuple[CameraFrameMeta, bytes]]:
        return [payload for _, kind, payload in self.events if kind == "camera"]


def record(
    duration_s: float, warmup_s: float = 40.0, seed: int = 5, site: Site | None = None
) -> Recorded:
    """The camera's frames and the radar's scans of ``site`` (default: the default site)."""
    site = site if site is not None else load_site(DEFAULT_SITE_PATH)
    camera, radar = camera_mount(site, None), radar_mount(site, None)
    settings = SimulatorSettings.model_validate(
        {
            "seed": seed,
            "realtime_factor": 0.0,
            "sensors_enabled": False,
            "vehicles_per_hour": 1800.0,
            "truck_share": 0.2,
            "duration_s": warmup_s + duration_s + 0.5,
        }
    )
    sensor_ids = [camera.sensor_id] + ([radar.sensor_id] if radar is not None else [])
    rig = SensorRig(site, WEATHER_PRESETS["day"], seed, sensor_ids=sensor_ids)
    events: list[tuple[float, str, Any]] = []
    with TrafficWorld(site, settings) as world:
        while not world.finished:
            vehicles = world.step()
            for output in rig.fire(vehicles, world.sim_time_s):
                if isinstance(output, CameraOutput) and output.meta.stamp >= warmup_s:
                    events.append((output.meta.stamp, "camera", (output.meta, output.jpeg)))
                elif isinstance(output, RadarOutput) and output.result.scan.stamp >= warmup_s:
                    events.append((output.result.scan.stamp, "radar", output.result.scan))
    return Recorded(events)


def stats_ms(values_s: list[float]) -> dict[str, float]:
    ordered = sorted(values_s)
    return {
        "p50_ms": 1e3 * statistics.median(ordered),
        "p90_ms": 1e3 * ordered[int(0.9 * (len(ordered) - 1))],
        "p99_ms": 1e3 * ordered[int(0.99 * (len(ordered) - 1))],
        "max_ms": 1e3 * ordered[-1],
    }


def _inference(recorded: Recorded) -> dict[str, Any]:
    # The simulator's frames: the model the node takes for rendered frames.
    settings = CameraDetectorSettings(model_path=SIMULATION_MODEL_PATH)
    assert settings.model_path is not None
    site = load_site(DEFAULT_SITE_PATH)
    detector = make_backend(settings, site, camera_mount(site, None))
    assert isinstance(detector, YoloOnnxDetector)
    images = [
        cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
        for _, jpeg in recorded.frames()
    ]
    for image in images[:5]:
        detector.detect(image)  # warm-up
    steps: dict[str, list[float]] = {
        "preprocess": [],
        "inference": [],
        "postprocess": [],
        "total": [],
    }
    for image in images:
        _, timings = detector.detect_with_timings(image)
        steps["preprocess"].append(timings.preprocess_s)
        steps["inference"].append(timings.inference_s)
        steps["postprocess"].append(timings.postprocess_s)
        steps["total"].append(timings.total_s)
    return {
        "model": settings.model_path.name,
        "input_size_px": list(detector.input_size),
        "roi_xyxy_px": list(detector.roi_xyxy_px) if detector.roi_xyxy_px else None,
        "tiles_xyxy_px": [list(tile) for tile in detector.tiles_xyxy_px],
        "frames": len(images),
        "steps": {name: stats_ms(values) for name, values in steps.items()},
    }


def _per_frame(recorded: Recorded) -> dict[str, Any]:
    site = load_site(DEFAULT_SITE_PATH)
    settings = CameraDetectorSettings.model_validate({})
    camera, radar = camera_mount(site, None), radar_mount(site, None)
    detector = CameraDetector(
        site, camera, radar, settings, report=lambda r, d: None, rendered=True
    )
    times: list[float] = []
    detections = 0
    for _, kind, payload in recorded.events:
        if kind == "radar":
            detector.radar_scan(payload)
            continue
        meta, jpeg = payload
        started = time.perf_counter()
        batch = detector.handle(meta, jpeg, started)
        times.append(time.perf_counter() - started)
        detections += len(batch.detections) if batch is not None else 0
    return {
        "frames": len(times),
        "detections_per_frame": detections / max(1, len(times)),
        **stats_ms(times),
    }


def _service(recorded: Recorded) -> dict[str, Any]:
    """The node process on real Zenoh, fed at the sensors' rates in wall-clock time."""
    port = free_port()
    settings = BusSettings(listen_endpoints=[f"tcp/127.0.0.1:{port}"], connect_endpoints=[])
    site = load_site(DEFAULT_SITE_PATH)
    env = {k: v for k, v in os.environ.items() if not k.startswith("WZ_")}
    env.update(
        WZ_BUS_CONNECT_ENDPOINTS=f"tcp/127.0.0.1:{port}",
        WZ_BUS_LISTEN_ENDPOINTS="",
        WZ_LOG_FORMAT="json",
        WZ_LOG_LEVEL="WARNING",
    )
    camera_id = recorded.frames()[0][0].source_id
    with Bus.open(settings, site=site.site_id, service="bench-camera") as bus:
        frames_pub = bus.publisher(bus.keys.raw_camera(camera_id), CameraFrameMeta, block=True)
        radar_pub = bus.publisher(bus.keys.raw_radar("radar-mast"), RadarScan, block=True)
        batches = bus.subscribe(bus.keys.detections(camera_id), DetectionBatch, capacity=10_000)
        node = subprocess.Popen(
            [sys.executable, "-m", "wz_camera_detector.node"], cwd=ROOT, env=env
        )
        sent_at: dict[int, float] = {}
        received: dict[int, tuple[float, DetectionBatch]] = {}
        try:
            if not frames_pub.wait_for_subscribers(60.0):
                raise RuntimeError("the camera detector node never subscribed")
            time.sleep(1.0)  # its radar subscription too
            start_wall = time.monotonic()
            first_stamp = recorded.events[0][0]
            for stamp, kind, payload in recorded.events:
                delay = start_wall + (stamp - first_stamp) - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                if kind == "radar":
                    radar_pub.put(payload)
                else:
                    meta, jpeg = payload
                    sent_at[meta.frame_index] = time.monotonic()
                    frames_pub.put_bytes(encode_camera_frame(meta, jpeg))
                while (batch := batches.recv(0.0)) is not None:
                    received[batch.frame_index] = (time.monotonic(), batch)
            deadline = time.monotonic() + 5.0
            while len(received) < len(sent_at) and time.monotonic() < deadline:
                batch = batches.recv(0.2)
                if batch is not None:
                    received[batch.frame_index] = (time.monotonic(), batch)
        finally:
            node.terminate()
            node.wait(20.0)
    span_s = recorded.events[-1][0] - recorded.events[0][0]
    radar_scans = sum(1 for _, kind, _ in recorded.events if kind == "radar")
    end_to_end = [at - sent_at[i] for i, (at, _) in received.items() if i in sent_at]
    node_latency = [batch.latency_s for _, batch in received.values()]
    return {
        "span_s": span_s,
        "frames_sent": len(sent_at),
        "radar_scans_sent": radar_scans,
        "batches_received": len(received),
        "frames_missing": len(sent_at) - len(received),
        "output_rate_hz": len(received) / span_s if span_s > 0 else 0.0,
        "node_latency": stats_ms(node_latency),
        "end_to_end_latency": stats_ms(end_to_end),
        "fused_share": (
            sum(1 for _, b in received.values() for d in b.detections if d.speed_mps is not None)
            / max(1, sum(len(b.detections) for _, b in received.values()))
        ),
    }


def run(quick: bool) -> dict[str, Any]:
    recorded = record(duration_s=10.0 if quick else 40.0)
    return {
        "inference": _inference(recorded),
        "per_frame": _per_frame(recorded),
        "service": _service(recorded),
    }
