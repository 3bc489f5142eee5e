"""The simulator's sensor models with realistic traffic, and the whole simulator with all three.

Everything runs on the default site (``deploy/sites/us75-lincoln.yaml``: a 64 x 2048 LiDAR at
20 Hz, a 1200 x 1200 camera at 10 Hz, a radar at 15 Hz, on one mast at station 980 m). libsumo
allows one simulation per process and loads heavy libraries, so each part runs in a child
process of its own (``python -m benchmarks.sensors MODE ...``) that writes its result as JSON
to a file; this process (the runner's) loads neither libsumo nor open3d.

``frames`` (child)
    Traffic: :class:`~wz_simulator.traffic.world.TrafficWorld` at ``FRAMES_VEHICLES_PER_HOUR``
    (seed 42), stepped for at least ``FRAMES_WARMUP_S`` and on until ``FRAMES_IN_RANGE``
    vehicles are within the LiDAR's maximum range; the truths of the next ``steps`` steps
    (0.05 s each, one LiDAR period) are kept and libsumo is closed. Then, on that sequence
    (frame ``i`` on the truth of step ``i``, a few untimed frames first):

    - the static scene (``static_scene(site)``) is built once and timed;
    - LiDAR (:class:`LidarModel`, ``scan`` with the truth's stamp, exactly as the rig calls it)
      in day, fog and rain: the model's one-off build (static mesh, every ray cast once), then
      wall and CPU time per frame, returns and points labelled as vehicles;
    - camera (:class:`CameraModel`) in day, dusk, rain and fog: the model's one-off build
      (background), then per frame ``vehicle_boxes`` of the vehicles the rig would pass (within
      ``CAMERA_CULL_STATION_M`` of the camera along the road), ``render``, and ``encode_jpeg``
      at the simulator's default quality, each timed on its own;
    - radar (:class:`RadarModel`) in day and rain: ``scan``.

``loop`` (child)
    The simulator's own loop, :func:`wz_simulator.node.run_loop`, in process, with a
    :class:`SensorRig` (day) and publish callbacks that encode exactly as the node does
    (``GroundTruth`` JSON, LiDAR and camera envelopes, radar JSON) but put nothing on a bus.
    ``LOOP_VEHICLES_PER_HOUR``, seed 42; ``loop_warmup_s`` of traffic without sensors, then a
    window of ``duration_s`` simulated seconds timed as a whole, in which the world is seen
    from the window's start (time from 0, so the rig's frames are numbered from 0 there) and
    each part is timed where it is called: the SUMO step (``TrafficWorld.step``), each
    ``SensorRig.capture`` by sensor kind, the rig's ``encode_jpeg`` (wrapped for this run),
    and the encodes in the callbacks. What is left (building the ``GroundTruth`` message, the
    rig's schedule, the loop) is the remainder.

``node`` (this process starts it)
    The simulator node as a real process (``python -m wz_simulator.node``,
    ``WZ_SIM_REALTIME_FACTOR=0``, ``WZ_SIM_DURATION_S`` = warm-up + window, same demand and
    seed as ``loop``), publishing on a real Zenoh bus (default config, shared memory on) to a
    counting process (``count`` mode: a peer listening on a free loopback port, multicast off,
    one callback subscription on ``raw/**`` and one on the truth, each sample stamped with its
    arrival time). The node fires its sensors from t = 0 (it has no warm-up); the window's
    simulation rate is read from the arrival times of the truth messages stamped at the
    window's start and end. Frame counts are checked per sensor: every index from 0 exactly
    once, ``duration x rate + 1`` frames over the run (the frame at t = 0 and the one at the
    last step both fire), ``window x rate`` in ``[start, end)``.
"""

from __future__ import annotations

import argparse
import gc
import json
import logging
import math
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections import defaultdict
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from benchmarks.common import ROOT, free_port, listener_settings, summarize

if TYPE_CHECKING:
    from wz_shared.messages import VehicleTruth
    from wz_shared.site import SensorMount, Site

log = logging.getLogger(__name__)

#: Demand of the per-frame measurements [veh/h]: a queue forms upstream of the taper.
FRAMES_VEHICLES_PER_HOUR = 2200.0
#: Least warm-up before the kept truths [s] (vehicles reach the mast after about 30 s).
FRAMES_WARMUP_S = 90.0
#: Vehicles within the LiDAR's maximum range when the kept truths start.
FRAMES_IN_RANGE = 20
#: Give up waiting for them after this much simulated time [s].
MAX_WARMUP_S = 600.0
#: Demand of the whole-simulator runs [veh/h] (the simulator's default is 1400).
LOOP_VEHICLES_PER_HOUR = 1800.0
SEED = 42
#: Simulation step [s] (the truth rate's period: 20 Hz).
STEP_S = 0.05
#: Frames built but not timed before each timed series (caches, first-call costs).
UNTIMED_FRAMES = 3
LIDAR_WEATHERS = ("day", "fog", "rain")
CAMERA_WEATHERS = ("day", "dusk", "rain", "fog")
RADAR_WEATHERS = ("day", "rain")
#: Targets of the issue, per frame [ms], and of the whole simulator [simulated s / wall s].
TARGETS = {"lidar_frame_ms": 10.0, "camera_render_ms": 25.0, "radar_scan_ms": 1.0, "sim_rate": 2.0}
#: Longest wait for the counting process to start or go quiet [s].
COUNTER_TIMEOUT_S = 30.0


def _plan(quick: bool) -> dict[str, Any]:
    """How many samples each part takes (quick: a smoke test)."""
    return {
        "steps": 60 if quick else 200,
        "lidar_frames": 60 if quick else 200,
        "camera_frames": 30 if quick else 100,
        "radar_scans": 200 if quick else 1000,
        "loop_warmup_s": 60.0 if quick else 90.0,
        "duration_s": 20.0 if quick else 60.0,
    }


def _mount(site: Site, kind: str) -> SensorMount:
    return next(mount for mount in site.sensors if mount.kind == kind)


def _ms(seconds: Sequence[float]) -> dict[str, float]:
    return summarize([1e3 * value for value in seconds])


def _counts(values: Sequence[int]) -> dict[str, float]:
    return {"min": min(values), "median": statistics.median(values), "max": max(values)}


class _FullCollections:
    """Counts Python's full (generation 2) garbage collections while installed (``with``)."""

    def __init__(self) -> None:
        self.count = 0

    def __call__(self, phase: str, info: dict[str, int]) -> None:
        if phase == "start" and info["generation"] == 2:
            self.count += 1

    def __enter__(self) -> _FullCollections:
        gc.callbacks.append(self)
        return self

    def __exit__(self, *exc: object) -> None:
        gc.callbacks.remove(self)


def _gc_split(times_s: Sequence[float], full_gc: Sequence[bool]) -> dict[str, Any]:
    """How many timed calls a full collection fell in, and the slowest call without one [ms]."""
    without = [t for t, collected in zip(times_s, full_gc, strict=True) if not collected]
    return {
        "calls_with_full_gc": sum(full_gc),
        "max_ms_without_full_gc": 1e3 * max(without) if without else float("nan"),
    }


# --- frames (child) ----------------------------------------------------------------------------


def _in_lidar_range(site: Site, vehicles: Sequence[VehicleTruth]) -> int:
    mount = _mount(site, "lidar")
    max_range_m = getattr(mount.intrinsics, "max_range_m", 0.0)
    pose = mount.pose
    return sum(
        math.dist((pose.x_m, pose.y_m, pose.z_m), (v.x_m, v.y_m, v.z_m)) <= max_range_m
        for v in vehicles
    )


def _traffic(
    site: Site, steps: int, work_dir: Path
) -> tuple[list[list[VehicleTruth]], dict[str, Any]]:
    """Warm up, then keep the truths of ``steps`` steps (libsumo closed on return)."""
    from wz_simulator.settings import SimulatorSettings
    from wz_simulator.traffic.world import TrafficWorld

    settings = SimulatorSettings(
        vehicles_per_hour=FRAMES_VEHICLES_PER_HOUR,
        seed=SEED,
        realtime_factor=0.0,
        step_s=STEP_S,
        work_dir=work_dir,
    )
    start = time.perf_counter()
    with TrafficWorld(site, settings) as world:
        in_range = 0
        while world.sim_time_s < MAX_WARMUP_S and (
            world.sim_time_s < FRAMES_WARMUP_S or in_range < FRAMES_IN_RANGE
        ):
            in_range = _in_lidar_range(site, world.step())
        warmup_sim_s = world.sim_time_s
        sequence: list[list[VehicleTruth]] = []
        stamps: list[float] = []
        for _ in range(steps):
            sequence.append(world.step())
            stamps.append(world.sim_time_s)
    info = {
        "vehicles_per_hour": FRAMES_VEHICLES_PER_HOUR,
        "seed": SEED,
        "warmup_sim_s": warmup_sim_s,
        "warmup_wall_s": time.perf_counter() - start,
        "target_in_lidar_range": FRAMES_IN_RANGE,
        "step_s": STEP_S,
        "steps": steps,
        "first_stamp_s": stamps[0],
        "vehicles_on_road": _counts([len(v) for v in sequence]),
        "vehicles_in_lidar_range": _counts([_in_lidar_range(site, v) for v in sequence]),
    }
    return sequence, {"stamps": stamps, **info}


def _time_lidar(
    site: Site, scene: Any, sequence: list[list[VehicleTruth]], stamps: list[float], frames: int
) -> dict[str, Any]:
    from wz_simulator.sensors.lidar import LidarModel
    from wz_simulator.sensors.scene import WEATHER_PRESETS, vehicle_boxes

    mount = _mount(site, "lidar")
    results: dict[str, Any] = {}
    for weather in LIDAR_WEATHERS:
        start = time.perf_counter()
        model = LidarModel.from_scene(
            mount,
            scene,
            WEATHER_PRESETS[weather],
            SEED,
            boxes_for=vehicle_boxes,
            site_id=site.site_id,
        )
        build_s = time.perf_counter() - start
        wall_s: list[float] = []
        cpu_s: list[float] = []
        returns: list[int] = []
        vehicle_points: list[int] = []
        vehicles_hit: list[int] = []
        full_gc: list[bool] = []
        for i in range(-UNTIMED_FRAMES, frames):
            step = i % len(sequence)
            with _FullCollections() as collections:
                cpu_0, wall_0 = time.process_time(), time.perf_counter()
                scan = model.scan(
                    sequence[step], stamps[step], max(i, 0), truth_stamp_s=stamps[step]
                )
                wall_1, cpu_1 = time.perf_counter(), time.process_time()
            if i < 0:
                continue
            full_gc.append(collections.count > 0)
            wall_s.append(wall_1 - wall_0)
            cpu_s.append(cpu_1 - cpu_0)
            returns.append(int(np.count_nonzero(np.isfinite(scan.points[:, 0]))))
            vehicle_points.append(int(np.count_nonzero(scan.labels > 0)))
            vehicles_hit.append(sum(box.num_points > 0 for box in scan.boxes))
        results[weather] = {
            "model_build_s": build_s,
            "rays": model.num_rays,
            "frame_ms": _ms(wall_s),
            "frame_gc": _gc_split(wall_s, full_gc),
            "cpu_per_wall": sum(cpu_s) / sum(wall_s),
            "returns": _counts(returns),
            "vehicle_points": _counts(vehicle_points),
            "vehicles_hit": _counts(vehicles_hit),
        }
    return results


def _time_camera(
    site: Site, scene: Any, sequence: list[list[VehicleTruth]], stamps: list[float], frames: int
) -> dict[str, Any]:
    from wz_simulator.sensors.camera import CameraModel, encode_jpeg
    from wz_simulator.sensors.rig import CAMERA_CULL_STATION_M
    from wz_simulator.sensors.scene import WEATHER_PRESETS, vehicle_boxes
    from wz_simulator.settings import SimulatorSettings

    quality = SimulatorSettings.model_fields["jpeg_quality"].default
    mount = _mount(site, "camera")
    station_m = float(site.road_frame.to_road(mount.pose.x_m, mount.pose.y_m)[0])
    results: dict[str, Any] = {}
    for weather in CAMERA_WEATHERS:
        start = time.perf_counter()
        model = CameraModel.from_scene(mount, scene, WEATHER_PRESETS[weather], SEED)
        build_s = time.perf_counter() - start
        boxes_s: list[float] = []
        render_s: list[float] = []
        render_cpu_s: list[float] = []
        jpeg_s: list[float] = []
        jpeg_bytes: list[int] = []
        passed: list[int] = []
        drawn: list[int] = []
        full_gc: list[bool] = []
        for i in range(-UNTIMED_FRAMES, frames):
            step = i % len(sequence)
            seen = [
                v for v in sequence[step] if abs(v.station_m - station_m) < CAMERA_CULL_STATION_M
            ]
            ids, classes = [v.vehicle_id for v in seen], [v.vehicle_class for v in seen]
            t0 = time.perf_counter()
            boxes = vehicle_boxes(seen)
            t_boxes = time.perf_counter()
            with _FullCollections() as collections:
                t1, cpu_1 = time.perf_counter(), time.process_time()
                frame = model.render(boxes, ids, stamps[step], classes)
                t2, cpu_2 = time.perf_counter(), time.process_time()
            t_jpeg = time.perf_counter()
            jpeg = encode_jpeg(frame.image, quality)
            t3 = time.perf_counter()
            if i < 0:
                continue
            boxes_s.append(t_boxes - t0)
            full_gc.append(collections.count > 0)
            render_s.append(t2 - t1)
            render_cpu_s.append(cpu_2 - cpu_1)
            jpeg_s.append(t3 - t_jpeg)
            jpeg_bytes.append(len(jpeg))
            passed.append(len(seen))
            drawn.append(sum(label.box_xyxy_px is not None for label in frame.labels))
        results[weather] = {
            "model_build_s": build_s,
            "width_px": model.camera.width_px,
            "height_px": model.camera.height_px,
            "vehicle_boxes_ms": _ms(boxes_s),
            "render_ms": _ms(render_s),
            "render_gc": _gc_split(render_s, full_gc),
            "render_cpu_per_wall": sum(render_cpu_s) / sum(render_s),
            "jpeg_ms": _ms(jpeg_s),
            "jpeg_quality": quality,
            "jpeg_bytes_median": statistics.median(jpeg_bytes),
            "vehicles_passed": _counts(passed),
            "vehicles_drawn": _counts(drawn),
        }
    return results


def _time_radar(
    site: Site, sequence: list[list[VehicleTruth]], stamps: list[float], scans: int
) -> dict[str, Any]:
    from wz_simulator.sensors.radar import RadarModel
    from wz_simulator.sensors.scene import WEATHER_PRESETS

    mount = _mount(site, "radar")
    results: dict[str, Any] = {}
    for weather in RADAR_WEATHERS:
        model = RadarModel(mount, WEATHER_PRESETS[weather], SEED, site_id=site.site_id)
        scan_s: list[float] = []
        in_view: list[int] = []
        visible: list[int] = []
        targets: list[int] = []
        for i in range(-UNTIMED_FRAMES, scans):
            step = i % len(sequence)
            t0 = time.perf_counter()
            result = model.scan(sequence[step], stamps[step], max(i, 0))
            t1 = time.perf_counter()
            if i < 0:
                continue
            scan_s.append(t1 - t0)
            targets.append(len(result.scan.targets))
            if i < len(sequence):  # once per distinct truth
                echoes = model.echoes(sequence[step])
                in_view.append(int(np.count_nonzero(echoes.in_fov & echoes.in_range)))
                visible.append(int(np.count_nonzero(echoes.visible)))
        results[weather] = {
            "scan_ms": _ms(scan_s),
            "vehicles_in_view": _counts(in_view),
            "vehicles_visible": _counts(visible),
            "targets": _counts(targets),
        }
    return results


def measure_frames(quick: bool, work_dir: Path) -> dict[str, Any]:
    """Traffic, then each sensor model on its truths (runs in the child)."""
    import cv2
    import open3d

    from wz_shared.site import DEFAULT_SITE_PATH, load_site
    from wz_simulator.sensors.scene import static_scene

    plan = _plan(quick)
    site = load_site(DEFAULT_SITE_PATH)
    sequence, traffic = _traffic(site, plan["steps"], work_dir)
    stamps = traffic.pop("stamps")
    start = time.perf_counter()
    scene = static_scene(site)
    scene_build_s = time.perf_counter() - start
    return {
        "traffic": traffic,
        "static_scene": {
            "build_s": scene_build_s,
            "boxes": len(scene.boxes),
            "ground_polygons": len(scene.ground),
        },
        "lidar": _time_lidar(site, scene, sequence, stamps, plan["lidar_frames"]),
        "camera": _time_camera(site, scene, sequence, stamps, plan["camera_frames"]),
        "radar": _time_radar(site, sequence, stamps, plan["radar_scans"]),
        "untimed_frames": UNTIMED_FRAMES,
        "versions": {"open3d": open3d.__version__, "opencv": cv2.__version__},
        "threads": {"cores": os.cpu_count(), "opencv": cv2.getNumThreads()},
    }


# --- the simulator's loop (child) --------------------------------------------------------------


def _expected_frames(duration_s: float, rate_hz: float) -> int:
    """Firings at n / rate for n = 0 .. duration x rate (both ends fire)."""
    return math.floor(duration_s * rate_hz + 1e-9) + 1


def _index_check(indices: Sequence[int], expected: int) -> dict[str, Any]:
    """Count, duplicates and gaps of frame indices that should be exactly 0 .. expected - 1."""
    unique = set(indices)
    return {
        "frames": len(indices),
        "expected": expected,
        "duplicates": len(indices) - len(unique),
        "missing": len(set(range(expected)) - unique),
        "extra": len(unique - set(range(expected))),
        "exact": sorted(indices) == list(range(expected)),
    }


def measure_loop(quick: bool, work_dir: Path) -> dict[str, Any]:
    """``run_loop`` with the rig over a window after a warm-up, timed by part (in the child)."""
    from unittest import mock

    from wz_shared import codec
    from wz_shared.messages import GroundTruth
    from wz_shared.site import DEFAULT_SITE_PATH, load_site
    from wz_shared.timebase import Pacer, SimClock
    from wz_simulator.node import run_loop
    from wz_simulator.sensors import rig as rig_module
    from wz_simulator.sensors.camera import encode_jpeg
    from wz_simulator.sensors.rig import CameraOutput, LidarOutput, SensorOutput, SensorRig
    from wz_simulator.sensors.scene import WEATHER_PRESETS
    from wz_simulator.settings import SimulatorSettings
    from wz_simulator.traffic.world import TrafficWorld

    plan = _plan(quick)
    warmup_s: float = plan["loop_warmup_s"]
    duration_s: float = plan["duration_s"]
    site = load_site(DEFAULT_SITE_PATH)
    settings = SimulatorSettings(
        vehicles_per_hour=LOOP_VEHICLES_PER_HOUR,
        seed=SEED,
        realtime_factor=0.0,
        step_s=STEP_S,
        work_dir=work_dir,
    )
    spent: dict[str, float] = defaultdict(float)
    kind_of_sensor = {mount.sensor_id: mount.kind for mount in site.sensors}
    rates = {mount.sensor_id: mount.rate_hz for mount in site.sensors}

    class TimedRig(SensorRig):
        """The site's rig; each capture's wall time is added to its sensor kind."""

        def capture(
            self,
            sensor_id: str,
            index: int,
            fire_s: float,
            vehicles: Sequence[VehicleTruth],
            truth_stamp_s: float,
        ) -> SensorOutput:
            start = time.perf_counter()
            output = super().capture(sensor_id, index, fire_s, vehicles, truth_stamp_s)
            spent[kind_of_sensor[sensor_id]] += time.perf_counter() - start
            return output

    class WindowWorld:
        """The traffic world seen from the window's start: time from 0, done after the window."""

        def __init__(self, world: TrafficWorld) -> None:
            self.world = world
            self.site = world.site
            self.origin_s = world.sim_time_s
            self.origin_step = world.step_index
            self.vehicles: list[int] = []

        def step(self) -> list[VehicleTruth]:
            start = time.perf_counter()
            vehicles = self.world.step()
            spent["sumo_step"] += time.perf_counter() - start
            self.vehicles.append(len(vehicles))
            return vehicles

        @property
        def sim_time_s(self) -> float:
            return self.world.sim_time_s - self.origin_s

        @property
        def step_index(self) -> int:
            return self.world.step_index - self.origin_step

        @property
        def finished(self) -> bool:
            return self.sim_time_s >= duration_s - 1e-9

    def timed_jpeg(image: Any, quality: int = 90) -> bytes:
        start = time.perf_counter()
        jpeg = encode_jpeg(image, quality)
        spent["jpeg"] += time.perf_counter() - start
        return jpeg

    indices: dict[str, list[int]] = defaultdict(list)
    payload_bytes: dict[str, int] = defaultdict(int)
    truths = [0]

    def publish_truth(message: GroundTruth) -> None:
        start = time.perf_counter()
        payload = codec.encode(message)
        spent["truth_encode"] += time.perf_counter() - start
        payload_bytes["truth"] += len(payload)
        truths[0] += 1

    def publish_sensor(output: SensorOutput) -> None:
        start = time.perf_counter()
        if isinstance(output, LidarOutput):
            index = output.scan.meta.frame_index
            payload = codec.encode_lidar_frame(output.scan.meta, output.scan.points)
        elif isinstance(output, CameraOutput):
            index = output.meta.frame_index
            payload = codec.encode_camera_frame(output.meta, output.jpeg)
        else:
            index = output.result.scan.scan_index
            payload = codec.encode(output.result.scan)
        kind = kind_of_sensor[output.sensor_id]
        spent[f"{kind}_encode"] += time.perf_counter() - start
        indices[output.sensor_id].append(index)
        payload_bytes[output.sensor_id] += len(payload)

    start = time.perf_counter()
    with TrafficWorld(site, settings) as traffic:
        while traffic.sim_time_s < warmup_s - 1e-9:
            traffic.step()
        warmup_wall_s = time.perf_counter() - start
        built = time.perf_counter()
        rig = TimedRig(site, WEATHER_PRESETS["day"], SEED, jpeg_quality=settings.jpeg_quality)
        rig_build_s = time.perf_counter() - built
        window = WindowWorld(traffic)
        with mock.patch.object(rig_module, "encode_jpeg", timed_jpeg):
            cpu_0, wall_0 = time.process_time(), time.perf_counter()
            steps = run_loop(
                window,
                publish_truth,
                SimClock(),
                Pacer(0.0),
                threading.Event(),  # type: ignore[arg-type]
                rig,
                publish_sensor,
            )
            wall_s, cpu_s = time.perf_counter() - wall_0, time.process_time() - cpu_0
        simulated_s = window.sim_time_s
    # Captures include their JPEG encode; split it out.
    spent["camera"] -= spent["jpeg"]
    parts = {
        "sumo_step": "SUMO step + `VehicleTruth`s (`TrafficWorld.step`)",
        "lidar": "LiDAR frames (`LidarModel.scan` via `SensorRig.capture`)",
        "camera": "camera frames without JPEG (culling, `vehicle_boxes`, `render`, metadata)",
        "jpeg": "JPEG encode (`encode_jpeg`)",
        "radar": "radar scans (`RadarModel.scan`, moving the truths to the firing time)",
        "truth_encode": "`GroundTruth` encode (JSON)",
        "lidar_encode": "LiDAR envelope (`encode_lidar_frame`, 2 MB copy)",
        "camera_encode": "camera envelope (`encode_camera_frame`)",
        "radar_encode": "radar scan encode (JSON)",
    }
    split: dict[str, dict[str, Any]] = {
        name: {"what": what, "s": spent[name]} for name, what in parts.items()
    }
    split["other"] = {
        "what": "the rest: building `GroundTruth` (validation), the rig's schedule, the loop",
        "s": wall_s - sum(spent[name] for name in parts),
    }
    for entry in split.values():
        entry["share"] = entry["s"] / wall_s
    return {
        "vehicles_per_hour": LOOP_VEHICLES_PER_HOUR,
        "seed": SEED,
        "weather": "day",
        "warmup_sim_s": warmup_s,
        "warmup_wall_s": warmup_wall_s,
        "rig_build_s": rig_build_s,
        "duration_s": simulated_s,
        "steps": steps,
        "wall_s": wall_s,
        "cpu_per_wall": cpu_s / wall_s,
        "sim_per_wall": simulated_s / wall_s,
        "vehicles_on_road": _counts(window.vehicles),
        "split": split,
        "truth_messages": truths[0],
        "frames": {
            sensor_id: {
                "kind": kind_of_sensor[sensor_id],
                "rate_hz": rates[sensor_id],
                "mb_per_sim_s": payload_bytes[sensor_id] / 1e6 / simulated_s,
                **_index_check(indices[sensor_id], _expected_frames(simulated_s, rate)),
            }
            for sensor_id, rate in rates.items()
        },
    }


# --- the node as a process, and its counting subscriber ---------------------------------------


def count_frames(port: int, out: Path) -> None:
    """Count what arrives on ``raw/**`` and the truth until stdin closes (the ``count`` child).

    Writes per key the (index, stamp, arrival time) of every sample to ``out``.
    """
    from wz_shared import codec
    from wz_shared.bus import Bus
    from wz_shared.messages import CameraFrameMeta, GroundTruth, LidarFrameMeta, RadarScan
    from wz_shared.site import DEFAULT_SITE_PATH, load_site

    site = load_site(DEFAULT_SITE_PATH)
    arrivals: dict[str, list[tuple[int, float, float]]] = defaultdict(list)
    lock = threading.Lock()
    last_arrival = [time.monotonic()]

    def on_sample(key: str, payload: bytes) -> None:
        arrival = time.monotonic()
        index: int
        if "/raw/lidar/" in key:
            lidar = codec.decode_frame(payload, LidarFrameMeta).meta
            index, stamp = lidar.frame_index, lidar.stamp
        elif "/raw/camera/" in key:
            camera = codec.decode_frame(payload, CameraFrameMeta).meta
            index, stamp = camera.frame_index, camera.stamp
        elif "/raw/radar/" in key:
            scan = codec.decode_json(payload, RadarScan)
            index, stamp = scan.scan_index, scan.stamp
        else:
            truth = codec.decode_json(payload, GroundTruth)
            index, stamp = truth.step_index, truth.stamp
        with lock:
            arrivals[key].append((index, stamp, arrival))
            last_arrival[0] = arrival

    with Bus.open(listener_settings(port, shm=True), site=site.site_id, service="bench") as bus:
        bus.on_raw(bus.keys.raw_all, on_sample)
        bus.on_raw(bus.keys.truth, on_sample)
        sys.stdout.write("ready\n")
        sys.stdout.flush()
        sys.stdin.read()  # the runner closes it once the node has exited
        deadline = time.monotonic() + COUNTER_TIMEOUT_S
        while time.monotonic() - last_arrival[0] < 0.5 and time.monotonic() < deadline:
            time.sleep(0.1)  # let the last samples in flight arrive
        with lock:
            out.write_text(json.dumps({"arrivals": arrivals, "invalid": bus.stats.snapshot()}))


def _arrival_at(arrivals: list[list[float]], stamp_s: float) -> float:
    """Arrival time of the sample stamped ``stamp_s`` (the nearest stamp)."""
    return min(arrivals, key=lambda row: abs(row[1] - stamp_s))[2]


def _summarize_node(
    raw: dict[str, Any], site: Site, warmup_s: float, duration_s: float, wall: dict[str, float]
) -> dict[str, Any]:
    from wz_shared.keys import Keys

    arrivals: dict[str, list[list[float]]] = raw["arrivals"]
    keys = Keys(site.site_id)
    truth = arrivals.get(keys.truth, [])
    if not truth:
        raise RuntimeError("the counting process received no ground truth from the node")
    end_s = warmup_s + duration_s
    window_wall_s = _arrival_at(truth, end_s) - _arrival_at(truth, warmup_s)
    frames = {}
    for mount in site.sensors:
        key = {"lidar": keys.raw_lidar, "camera": keys.raw_camera, "radar": keys.raw_radar}[
            mount.kind
        ](mount.sensor_id)
        rows = arrivals.get(key, [])
        in_window = [row for row in rows if warmup_s - 1e-9 <= row[1] < end_s - 1e-9]
        frames[mount.sensor_id] = {
            "kind": mount.kind,
            "rate_hz": mount.rate_hz,
            **_index_check([int(row[0]) for row in rows], _expected_frames(end_s, mount.rate_hz)),
            "in_window": len(in_window),
            "in_window_expected": round(duration_s * mount.rate_hz),
        }
    first_truth = min(row[2] for row in truth)
    last_truth = max(row[2] for row in truth)
    return {
        "vehicles_per_hour": LOOP_VEHICLES_PER_HOUR,
        "seed": SEED,
        "weather": "day",
        "warmup_sim_s": warmup_s,
        "duration_s": duration_s,
        "window_wall_s": window_wall_s,
        "sim_per_wall": duration_s / window_wall_s,
        "run_sim_per_wall": (end_s - STEP_S) / (last_truth - first_truth),
        "process_wall_s": wall["process_s"],
        "startup_s": first_truth - wall["started_monotonic"],
        "truth_messages": _index_check(
            [int(row[0]) - 1 for row in truth], round(end_s / STEP_S)
        ),  # step_index counts from 1
        "frames": frames,
        "invalid": raw["invalid"].get("invalid", {}),
    }


def measure_node(quick: bool) -> dict[str, Any]:
    """The node as a real process over Zenoh to a counting process (runs here)."""
    from wz_shared.site import DEFAULT_SITE_PATH, load_site

    plan = _plan(quick)
    warmup_s, duration_s = plan["loop_warmup_s"], plan["duration_s"]
    site = load_site(DEFAULT_SITE_PATH)
    with tempfile.TemporaryDirectory(prefix="wz-bench-sensors-") as folder:
        out = Path(folder) / "arrivals.json"
        node_log = Path(folder) / "node.log"
        port = free_port()
        counter = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "benchmarks.sensors",
                "count",
                "--port",
                str(port),
                "--out",
                str(out),
            ],
            cwd=ROOT,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        try:
            assert counter.stdout is not None and counter.stdin is not None
            if counter.stdout.readline().strip() != "ready":
                raise RuntimeError(f"the counting process exited (rc={counter.wait()})")
            env = {
                **os.environ,
                "WZ_SIM_REALTIME_FACTOR": "0",
                "WZ_SIM_DURATION_S": str(warmup_s + duration_s),
                "WZ_SIM_VEHICLES_PER_HOUR": str(LOOP_VEHICLES_PER_HOUR),
                "WZ_SIM_SEED": str(SEED),
                "WZ_SIM_WEATHER": "day",
                "WZ_SIM_WORK_DIR": str(Path(folder) / "work"),
                "WZ_BUS_MODE": "peer",
                "WZ_BUS_CONNECT_ENDPOINTS": f"tcp/127.0.0.1:{port}",
                "WZ_BUS_LISTEN_ENDPOINTS": "",
                "WZ_BUS_MULTICAST_SCOUTING": "false",
            }
            started_monotonic = time.monotonic()
            with node_log.open("w") as log_file:
                node = subprocess.run(
                    [sys.executable, "-m", "wz_simulator.node"],
                    cwd=ROOT,
                    env=env,
                    stdout=log_file,
                    stderr=subprocess.STDOUT,
                    timeout=600,
                    check=False,
                )
            process_s = time.monotonic() - started_monotonic
            if node.returncode != 0:
                tail = "\n".join(node_log.read_text().splitlines()[-20:])
                raise RuntimeError(f"the simulator node exited with {node.returncode}:\n{tail}")
            counter.stdin.close()
            if counter.wait(COUNTER_TIMEOUT_S + 10.0) != 0:
                raise RuntimeError(f"the counting process exited with {counter.returncode}")
        finally:
            if counter.poll() is None:
                counter.kill()
                counter.wait()
        raw = json.loads(out.read_text())
    wall = {"process_s": process_s, "started_monotonic": started_monotonic}
    return _summarize_node(raw, site, warmup_s, duration_s, wall)


# --- the runner's entry point ------------------------------------------------------------------


def _child(mode: str, quick: bool) -> dict[str, Any]:
    """Run this module as a child process and return what it measured."""
    with tempfile.TemporaryDirectory(prefix="wz-bench-sensors-") as folder:
        out = Path(folder) / "result.json"
        command = [sys.executable, "-m", "benchmarks.sensors", mode, "--out", str(out)]
        command += ["--work-dir", str(Path(folder) / "work")] + (["--quick"] if quick else [])
        subprocess.run(command, cwd=ROOT, check=True, timeout=600)
        result: dict[str, Any] = json.loads(out.read_text())
    return result


def _ratios(frames: dict[str, Any], loop: dict[str, Any], node: dict[str, Any]) -> dict[str, float]:
    """Measured / target: a time meets its target below 1, the simulation rate above 1."""
    return {
        "lidar_frame_ms": frames["lidar"]["day"]["frame_ms"]["p50"] / TARGETS["lidar_frame_ms"],
        "camera_render_ms": frames["camera"]["day"]["render_ms"]["p50"]
        / TARGETS["camera_render_ms"],
        "radar_scan_ms": frames["radar"]["day"]["scan_ms"]["p50"] / TARGETS["radar_scan_ms"],
        "sim_rate_loop": loop["sim_per_wall"] / TARGETS["sim_rate"],
        "sim_rate_node": node["sim_per_wall"] / TARGETS["sim_rate"],
    }


def run(quick: bool) -> dict[str, Any]:
    """Each sensor model on realistic traffic, then the whole simulator in and out of process."""
    log.info("sensors: per-frame times at %.0f veh/h", FRAMES_VEHICLES_PER_HOUR)
    frames = _child("frames", quick)
    log.info("sensors: run_loop in process at %.0f veh/h", LOOP_VEHICLES_PER_HOUR)
    loop = _child("loop", quick)
    log.info("sensors: the simulator node over Zenoh at %.0f veh/h", LOOP_VEHICLES_PER_HOUR)
    node = measure_node(quick)
    exact = all(entry["exact"] for entry in loop["frames"].values()) and all(
        entry["exact"] and entry["in_window"] == entry["in_window_expected"]
        for entry in node["frames"].values()
    )
    return {
        "targets": TARGETS,
        "frames": frames,
        "loop": loop,
        "node": node,
        "frame_counts_exact": exact,
        "ratios": _ratios(frames, loop, node),
    }


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.sensors")
    parser.add_argument("mode", choices=("frames", "loop", "count"))
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--work-dir", type=Path)
    parser.add_argument("--port", type=int)
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING, stream=sys.stderr)
    measure: dict[str, Callable[[], dict[str, Any]]] = {
        "frames": lambda: measure_frames(args.quick, args.work_dir),
        "loop": lambda: measure_loop(args.quick, args.work_dir),
    }
    if args.mode == "count":
        count_frames(args.port, args.out)
    else:
        args.out.write_text(json.dumps(measure[args.mode](), indent=2))


if __name__ == "__main__":
    main()
