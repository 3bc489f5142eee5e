"""The edge box's budget (issue 41): the camera node at 30 fps on one core, and the whole stack
with a 30 fps camera, this code side by side with the code before it, in one run.

"Before" is the commit :data:`BASELINE_COMMIT` (the detector on every frame, ONNX Runtime on
two threads, a ring of one frame), checked out in a temporary ``git worktree`` and run from
there (its source folders first on ``PYTHONPATH``; the same virtual environment). "Now" is the
working tree. Both run on the same recorded frames, the same site files, one after the other.

Cases: the default site's camera (1200 x 1200) and the camera of a generated site that draws a
1920 x 1080 one (:data:`GENERATED_SEED`), each set to 30 fps, 1800 veh/h with 20 % trucks, day;
frames rendered once (SUMO and the simulator's camera and radar models), after a 40 s warm-up.

- **Per frame, one core**: a process pinned to one CPU runs
  :meth:`~wz_camera_detector.node.CameraDetector.handle` on every frame in order (radar scans
  in between); CPU time per frame (``time.process_time``): median, p99, mean, and the share of
  one core the camera's 30 fps costs (the sum over the frames' span).
- **The node on the bus**: the node as its own process (``python -m
  wz_camera_detector.node``) pinned to one CPU, this process on the other, on real Zenoh;
  frames published at 30 fps and radar scans at their rate in wall-clock time; how many frames
  came back as batches (none may be missing) and the end-to-end latency (frame published to
  its batch received): median, p99.
- **The whole stack**: ``wz up`` in real time on the default site with its camera at 30 fps
  (LiDAR 20 Hz, radar 15 Hz, as the site file says); after a warm-up, each process's CPU over
  a window in % of one core (``psutil``).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import pickle
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import psutil
import yaml

from benchmarks import camera_models
from benchmarks.camera_detection import record, stats_ms
from benchmarks.camera_models import process_cpu_s
from benchmarks.common import ROOT, free_port

#: The code before issue 41's budget work: what "before" runs.
BASELINE_COMMIT = "b8e5cc3"
#: The camera's frame rate in every case [Hz].
CAMERA_FPS = 30.0
#: A generated site whose camera is 1920 x 1080 (the generator's second format).
GENERATED_SEED = 20000
CODES = ("before", "now")


def _site_30fps(site: Any) -> Any:
    """The site with its first camera at :data:`CAMERA_FPS`."""
    camera = next(mount for mount in site.sensors if mount.intrinsics.kind == "camera")
    sensors = [
        mount.model_copy(update={"rate_hz": CAMERA_FPS})
        if mount.sensor_id == camera.sensor_id
        else mount
        for mount in site.sensors
    ]
    return site.model_copy(update={"sensors": sensors})


def _sites() -> dict[str, Any]:
    from wz_shared.site import DEFAULT_SITE_PATH, load_site
    from wz_shared.site_generator import generate_site

    return {
        "default site, 1200x1200": _site_30fps(load_site(DEFAULT_SITE_PATH)),
        f"generated site {GENERATED_SEED}, 1920x1080": _site_30fps(generate_site(GENERATED_SEED)),
    }


@contextlib.contextmanager
def baseline_tree() -> Iterator[Path]:
    """:data:`BASELINE_COMMIT` checked out in a temporary worktree (removed after)."""
    folder = Path(tempfile.mkdtemp(prefix="wz-budget-before-"))
    tree = folder / "tree"
    subprocess.run(
        ["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree), BASELINE_COMMIT],
        check=True,
        capture_output=True,
    )
    try:
        yield tree
    finally:
        subprocess.run(
            ["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)],
            check=False,
            capture_output=True,
        )
        with contextlib.suppress(OSError):
            folder.rmdir()


def _environment(tree: Path) -> dict[str, str]:
    """The environment that runs ``tree``'s code: its source folders first on the path, no
    ``WZ_`` settings of ours."""
    sources = sorted(str(path) for path in tree.glob("*/src")) + sorted(
        str(path) for path in tree.glob("*/*/src")
    )
    env = {k: v for k, v in os.environ.items() if not k.startswith("WZ_")}
    env["PYTHONPATH"] = os.pathsep.join([*sources, str(ROOT)])
    return env


def _pinned_cpus() -> tuple[int, int]:
    """Two CPUs this process may use: the node's, and the feeder's (the same on one CPU)."""
    cpus = sorted(os.sched_getaffinity(0))
    return cpus[-1], cpus[0]


def _stats_ms(values_s: list[float]) -> dict[str, float]:
    """:func:`~benchmarks.camera_detection.stats_ms` and the mean [ms]."""
    return {**stats_ms(values_s), "mean_ms": 1e3 * statistics.fmean(values_s)}


def per_frame_worker(events_path: Path, site_path: Path) -> dict[str, Any]:
    """In a process pinned to one CPU: each frame through ``CameraDetector.handle``."""
    import cv2

    from wz_camera_detector.node import CameraDetector
    from wz_camera_detector.settings import CameraDetectorSettings, camera_mount, radar_mount
    from wz_shared.site import load_site

    cv2.setNumThreads(1)
    site = load_site(site_path)
    events = pickle.loads(events_path.read_bytes())
    settings = CameraDetectorSettings.model_validate({})
    detector = CameraDetector(
        site,
        camera_mount(site, None),
        radar_mount(site, None),
        settings,
        report=lambda reason, detail: None,
        rendered=True,
    )
    cpu_s: list[float] = []
    published = detections = 0
    for _, kind, payload in events:
        if kind == "radar":
            detector.radar_scan(payload)
            continue
        meta, jpeg = payload
        started = time.process_time()
        batch = detector.handle(meta, jpeg, time.monotonic())
        cpu_s.append(time.process_time() - started)
        if batch is not None:
            published += 1
            detections += len(batch.detections)
    span_s = events[-1][0] - events[0][0]
    return {
        "frames": len(cpu_s),
        "batches": published,
        "detections_per_batch": detections / max(1, published),
        "cpu": _stats_ms(cpu_s),
        "share_of_one_core": sum(cpu_s) / span_s if span_s > 0 else float("nan"),
    }


def per_frame(tree: Path, events_path: Path, site_path: Path) -> dict[str, Any]:
    """:func:`per_frame_worker` run with ``tree``'s code, pinned to one CPU."""
    cpu, _ = _pinned_cpus()
    command = ["taskset", "-c", str(cpu), sys.executable, "-m", "benchmarks.camera_budget"]
    command += ["--worker", str(events_path), str(site_path)]
    done = subprocess.run(
        command, cwd=ROOT, env=_environment(tree), capture_output=True, text=True, check=False
    )
    if done.returncode != 0:
        raise RuntimeError(f"per-frame worker failed:\n{done.stderr[-3000:]}")
    result: dict[str, Any] = json.loads(done.stdout.strip().splitlines()[-1])
    return result


def node_on_bus(tree: Path, events: list[Any], site: Any, site_path: Path) -> dict[str, Any]:
    """The node process (``tree``'s code) pinned to one CPU, fed at the sensors' rates."""
    from wz_shared.bus import Bus
    from wz_shared.codec import encode_camera_frame
    from wz_shared.messages import CameraFrameMeta, DetectionBatch, RadarScan
    from wz_shared.settings import BusSettings

    node_cpu, feeder_cpu = _pinned_cpus()
    port = free_port()
    settings = BusSettings(listen_endpoints=[f"tcp/127.0.0.1:{port}"], connect_endpoints=[])
    env = _environment(tree)
    env.update(
        WZ_SITE_FILE=str(site_path),
        WZ_BUS_CONNECT_ENDPOINTS=f"tcp/127.0.0.1:{port}",
        WZ_BUS_LISTEN_ENDPOINTS="",
        WZ_LOG_FORMAT="json",
        WZ_LOG_LEVEL="WARNING",
        WZ_CAMERA_CALIBRATION__ENABLED="false",  # no LiDAR here to learn against
    )
    frames = [payload for _, kind, payload in events if kind == "camera"]
    camera_id = frames[0][0].source_id
    radar_id = next((p.source_id for _, kind, p in events if kind == "radar"), None)
    affinity = os.sched_getaffinity(0)
    os.sched_setaffinity(0, {feeder_cpu})
    try:
        with Bus.open(settings, site=site.site_id, service="bench-camera-budget") as bus:
            frames_pub = bus.publisher(bus.keys.raw_camera(camera_id), CameraFrameMeta, block=True)
            radar_pub = (
                bus.publisher(bus.keys.raw_radar(radar_id), RadarScan, block=True)
                if radar_id is not None
                else None
            )
            batches = bus.subscribe(
                bus.keys.detections(camera_id), DetectionBatch, capacity=100_000
            )
            node = subprocess.Popen(
                ["taskset", "-c", str(node_cpu), sys.executable, "-m", "wz_camera_detector.node"],
                cwd=tree,
                env=env,
            )
            sent_at: dict[int, float] = {}
            received: dict[int, float] = {}
            listening = threading.Event()
            listening.set()

            def listen() -> None:  # stamps each batch as it arrives, apart from the feeding
                while listening.is_set():
                    batch = batches.recv(0.05)
                    if batch is not None:
                        received.setdefault(batch.frame_index, time.monotonic())

            listener = threading.Thread(target=listen, daemon=True)
            listener.start()
            try:
                if not frames_pub.wait_for_subscribers(90.0):
                    raise RuntimeError("the camera detector node never subscribed")
                time.sleep(2.0)  # its radar subscription too, and the model's first run
                process = psutil.Process(node.pid)
                cpu_before = process_cpu_s(process)
                start_wall = time.monotonic()
                first_stamp = events[0][0]
                for stamp, kind, payload in events:
                    delay = start_wall + (stamp - first_stamp) - time.monotonic()
                    if delay > 0:
                        time.sleep(delay)
                    if kind == "radar":
                        if radar_pub is not None:
                            radar_pub.put(payload)
                    else:
                        meta, jpeg = payload
                        sent_at[meta.frame_index] = time.monotonic()
                        frames_pub.put_bytes(encode_camera_frame(meta, jpeg))
                fed_s = time.monotonic() - start_wall
                cpu_share = (process_cpu_s(process) - cpu_before) / fed_s
                deadline = time.monotonic() + 5.0
                while len(received) < len(sent_at) and time.monotonic() < deadline:
                    time.sleep(0.1)
            finally:
                listening.clear()
                listener.join(5.0)
                node.terminate()
                node.wait(30.0)
    finally:
        os.sched_setaffinity(0, affinity)
    latency = [at - sent_at[index] for index, at in received.items() if index in sent_at]
    return {
        "frames_sent": len(sent_at),
        "batches_received": len(received),
        "frames_missing": len(sent_at) - len(received),
        "end_to_end": _stats_ms(latency) if latency else None,
        "node_share_of_one_core": cpu_share,
    }


def stack_cpu(tree: Path, site_path: Path, warmup_s: float, window_s: float) -> dict[str, float]:
    """Each process's CPU [% of one core] under ``wz up`` (``tree``'s code) in real time, and
    the sum of all but the simulator (and SUMO, under the supervisor)."""
    usage = camera_models.stack_cpu(
        None, warmup_s, window_s, env=_environment(tree), cwd=tree, site_path=site_path
    )
    usage["all but the simulator"] = round(
        usage["all"] - usage.get("simulator", 0.0) - usage.get("wz up (supervisor) and SUMO", 0.0),
        1,
    )
    return usage


def run(quick: bool) -> dict[str, Any]:
    from wz_shared.site import site_document

    duration_s = 8.0 if quick else 20.0
    warmup_s, window_s = (25.0, 10.0) if quick else (40.0, 30.0)
    cases: dict[str, Any] = {}
    stack: dict[str, Any] = {}
    with tempfile.TemporaryDirectory(prefix="wz-budget-") as tmp, baseline_tree() as before:
        trees = {"before": before, "now": ROOT}
        for name, site in _sites().items():
            site_path = Path(tmp) / f"{site.site_id}.yaml"
            site_path.write_text(yaml.safe_dump(site_document(site), sort_keys=False))
            events = record(duration_s, site=site).events
            events_path = Path(tmp) / f"{site.site_id}.pkl"
            events_path.write_bytes(pickle.dumps(events))
            camera = next(m for m in site.sensors if m.intrinsics.kind == "camera")
            cases[name] = {
                "camera": f"{camera.intrinsics.width_px}x{camera.intrinsics.height_px}",
                "frames": sum(1 for _, kind, _ in events if kind == "camera"),
                "per_frame": {
                    code: per_frame(tree, events_path, site_path) for code, tree in trees.items()
                },
                "node": {
                    code: node_on_bus(tree, events, site, site_path) for code, tree in trees.items()
                },
            }
            if not stack:
                stack = {
                    code: stack_cpu(tree, site_path, warmup_s, window_s)
                    for code, tree in trees.items()
                }
    return {
        "baseline_commit": BASELINE_COMMIT,
        "camera_fps": CAMERA_FPS,
        "cases": cases,
        "stack_cpu_percent": stack,
        "stack_window_s": window_s,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--worker", nargs=2, type=Path, metavar=("EVENTS", "SITE"))
    args = parser.parse_args()
    if args.worker is None:
        parser.error("run it through `python -m benchmarks.run --only camera_budget`")
    sys.stdout.write(json.dumps(per_frame_worker(*args.worker)) + "\n")


if __name__ == "__main__":
    main()
