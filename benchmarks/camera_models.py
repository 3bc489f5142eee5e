"""The camera detector's two shipped models side by side, on one core, and the stack's CPU.

- **Per frame, one core** (this process pinned to one CPU, ONNX Runtime with 1 thread): the
  detector's ``detect`` (letterbox, inference, decode, NMS) for the simulator-trained
  ``wz-vehicles-pico-480.onnx`` and the COCO-pretrained ``coco-nanodet-g-416-int8.onnx``, on
  the same frames: the default site's rendered 1200 x 1200 frames with the regions its road
  gives (region of interest and far-field tile, what the node runs), and the whole frame of a
  camera the detector knows nothing of at 320 x 240, 1280 x 720 and 1920 x 1080 (the rendered
  frames cropped to the aspect and resized). Median and p99.
- **The whole stack at full sensor rates**: ``wz up`` (router, simulator with LiDAR 10 Hz,
  camera 10 Hz and radar 15 Hz, both detectors, tracker, alert service, gateway) in real time,
  once with each model in the camera detector (``WZ_CAMERA_MODEL_PATH``); after a warm-up,
  each process's CPU over a window, in % of one core (``psutil``; a service's warm standby,
  idle, is counted with it).
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import psutil

from benchmarks.camera_detection import record
from benchmarks.common import ROOT, free_port
from wz_camera_detector.node import make_backend
from wz_camera_detector.settings import (
    DEFAULT_MODEL_PATH,
    SIMULATION_MODEL_PATH,
    CameraDetectorSettings,
    camera_mount,
)
from wz_camera_detector.yolo import YoloOnnxDetector
from wz_shared.arrays import U8
from wz_shared.site import DEFAULT_SITE_PATH, load_site

MODELS = {
    "old (sim-trained pico)": SIMULATION_MODEL_PATH,
    "new (COCO NanoDet int8)": DEFAULT_MODEL_PATH,
}
SIZES = ((320, 240), (1280, 720), (1920, 1080))
#: Module name in a process's command line -> the service's name.
SERVICES = {
    "router": "router",
    "wz_simulator.node": "simulator",
    "wz_lidar_detector.node": "lidar-detector",
    "wz_camera_detector.node": "camera-detector",
    "wz_fusion_tracker.node": "fusion-tracker",
    "wz_alert_service.node": "alert-service",
    "wz_gateway.node": "gateway",
}


def _ms(values: list[float]) -> dict[str, float]:
    ordered = sorted(values)
    return {
        "p50_ms": 1e3 * statistics.median(ordered),
        "p99_ms": 1e3 * ordered[int(0.99 * (len(ordered) - 1))],
    }


def _resized(image: U8, width: int, height: int) -> U8:
    """The frame cropped (centred) to ``width : height`` and resized to it."""
    side_h, side_w = image.shape[:2]
    if width / height > side_w / side_h:
        crop_h = round(side_w * height / width)
        top = (side_h - crop_h) // 2
        image = image[top : top + crop_h]
    else:
        crop_w = round(side_h * width / height)
        left = (side_w - crop_w) // 2
        image = image[:, left : left + crop_w]
    return np.asarray(cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA))


def _time(detector: YoloOnnxDetector, images: list[U8]) -> dict[str, Any]:
    for image in images[:5]:
        detector.detect(image)  # warm-up
    times = []
    for image in images:
        started = time.perf_counter()
        detector.detect(image)
        times.append(time.perf_counter() - started)
    return _ms(times)


def per_frame_one_core(frames: list[U8]) -> dict[str, Any]:
    """Median and p99 per frame, each model, each case (module docstring)."""
    site = load_site(DEFAULT_SITE_PATH)
    mount = camera_mount(site, None)
    results: dict[str, Any] = {}
    for label, path in MODELS.items():
        settings = CameraDetectorSettings(model_path=path)
        on_site = make_backend(settings, site, mount)
        assert isinstance(on_site, YoloOnnxDetector)
        rows = {"default site, ROI + tile": _time(_one_thread(path, on_site), frames)}
        whole = _one_thread(path, None)
        for width, height in SIZES:
            rows[f"whole frame {width}x{height}"] = _time(
                whole, [_resized(f, width, height) for f in frames]
            )
        results[label] = {"model": path.name, "cases": rows}
    return results


def _one_thread(path: Path, like: YoloOnnxDetector | None) -> YoloOnnxDetector:
    """The model on one ONNX Runtime thread; with ``like``, looking where it looks."""
    detector = YoloOnnxDetector(path, threads=1)
    if like is not None:
        detector.set_regions(like.roi_xyxy_px, like.tiles_xyxy_px)
    return detector


def stack_cpu(
    model: Path | None,
    warmup_s: float,
    window_s: float,
    *,
    env: dict[str, str] | None = None,
    cwd: Path = ROOT,
    site_path: Path | None = None,
) -> dict[str, float]:
    """Each service's CPU [% of one core] under ``wz up`` in real time with ``model`` (None:
    the detector's own choice), run in ``cwd`` with ``env`` (default: ours, less ``WZ_``
    settings) on ``site_path`` (default: the default site)."""
    env = dict(env) if env is not None else _without_wz_settings()
    with tempfile.TemporaryDirectory(prefix="wz-camera-bench-") as tmp:
        if model is not None:
            env["WZ_CAMERA_MODEL_PATH"] = str(model)
        env.update(
            WZ_SIM_WORK_DIR=str(Path(tmp) / "sim"),
            WZ_GATEWAY_DATA_DIR=str(Path(tmp) / "gateway"),
            WZ_GATEWAY_PORT=str(free_port()),
        )
        command = [sys.executable, "-m", "wz_cli.main", "up", "--seed", "3"]
        if site_path is not None:
            command += ["--site", str(site_path)]
        command += ["--listen", f"tcp/127.0.0.1:{free_port()}"]
        up = subprocess.Popen(
            command,
            cwd=cwd,
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        try:
            time.sleep(warmup_s)
            supervisor = psutil.Process(up.pid)
            children = [*supervisor.children(recursive=True), supervisor]
            before = {p.pid: process_cpu_s(p) for p in children}
            time.sleep(window_s)
            usage: dict[str, float] = {}
            for process in children:
                name = service_name(process)
                cpu = process_cpu_s(process) - before[process.pid]
                usage[name] = usage.get(name, 0.0) + 100.0 * cpu / window_s
            usage["all"] = sum(usage.values())
            return {name: round(value, 1) for name, value in sorted(usage.items())}
        finally:
            up.terminate()
            up.wait(timeout=60)


def _without_wz_settings() -> dict[str, str]:
    return {k: v for k, v in os.environ.items() if not k.startswith("WZ_")}


def process_cpu_s(process: psutil.Process) -> float:
    try:
        times = process.cpu_times()
    except psutil.NoSuchProcess:
        return 0.0
    return float(times.user + times.system)


def service_name(process: psutil.Process) -> str:
    try:
        command = " ".join(process.cmdline())
    except psutil.NoSuchProcess:
        return "exited"
    for module, name in SERVICES.items():
        if module in command:
            return name
    return "wz up (supervisor) and SUMO" if "sumo" in command or " up " in command else "other"


def run(quick: bool) -> dict[str, Any]:
    recorded = record(duration_s=8.0 if quick else 30.0)
    frames = [
        np.asarray(cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR))
        for _, jpeg in recorded.frames()
    ]
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    try:
        per_frame = per_frame_one_core(frames)
    finally:
        os.sched_setaffinity(0, set(range(os.cpu_count() or 1)))
    warmup_s, window_s = (20.0, 10.0) if quick else (35.0, 30.0)
    stack = {label: stack_cpu(path, warmup_s, window_s) for label, path in MODELS.items()}
    return {
        "frames": len(frames),
        "per_frame_one_core": per_frame,
        "stack_cpu_percent": stack,
        "stack_window_s": window_s,
    }
