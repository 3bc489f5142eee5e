"""The simulator core's step time: :class:`~wz_simulator.traffic.world.TrafficWorld` on libsumo.

libsumo allows one simulation per process, so each measurement runs in a child process of its
own (``python -m benchmarks.sumo_step MODE ...``) that writes its result as JSON to a file.

``steps``
    Default site, demand raised until about 60 vehicles are on the road, ``realtime_factor=0``.
    Warm up until ``target`` vehicles are present, then time ``steps`` calls of
    :meth:`TrafficWorld.step` (SUMO step plus building the :class:`VehicleTruth` messages). Out
    of the timed call, each step also re-measures parts of it on the same vehicles: the road-frame
    projection (``site.road_frame.to_road``), validating the :class:`VehicleTruth` messages again
    with pydantic, building them with ``model_construct`` (no validation); and what the simulator
    node adds: building and encoding the :class:`GroundTruth` it publishes.
``duration``
    A whole run of ``duration_s`` simulated seconds, end to end: start-up (network build in a
    fresh folder, libsumo start), every step, close.
"""

from __future__ import annotations

import argparse
import json
import logging
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import ROOT, summarize

log = logging.getLogger(__name__)

#: Demand of the step-time measurement [veh/h]: enough for ~60 vehicles after a few minutes.
STEP_VEHICLES_PER_HOUR = 2400.0
#: Vehicles on the road before the timed steps start.
TARGET_VEHICLES = 60
#: Give up warming up after this much simulated time [s].
MAX_WARMUP_S = 900.0
#: Simulation step [s] (the truth rate's period: 20 Hz).
STEP_S = 0.05


def _world(vehicles_per_hour: float, work_dir: Path, duration_s: float = 0.0) -> Any:
    # Imported here, in the child, so that the runner's process never loads libsumo.
    from wz_shared.site import DEFAULT_SITE_PATH, load_site
    from wz_simulator.settings import SimulatorSettings
    from wz_simulator.traffic.world import TrafficWorld

    site = load_site(DEFAULT_SITE_PATH)
    settings = SimulatorSettings(
        vehicles_per_hour=vehicles_per_hour,
        realtime_factor=0.0,
        step_s=STEP_S,
        duration_s=duration_s,
        work_dir=work_dir,
    )
    return TrafficWorld(site, settings)


def measure_steps(
    vehicles_per_hour: float, steps: int, target: int, work_dir: Path
) -> dict[str, Any]:
    """Warm up to ``target`` vehicles, then time ``steps`` steps (runs in the child)."""
    from wz_shared import codec
    from wz_shared.messages import GroundTruth, VehicleTruth

    start = time.perf_counter()
    with _world(vehicles_per_hour, work_dir) as world:
        startup_s = time.perf_counter() - start
        vehicles = 0
        while vehicles < target and world.sim_time_s < MAX_WARMUP_S:
            vehicles = len(world.step())
        warmup_vehicles = vehicles
        warmup_sim_s = world.sim_time_s
        warmup_wall_s = time.perf_counter() - start - startup_s

        step_ms: list[float] = []
        counts: list[int] = []
        to_road_ms: list[float] = []
        validate_ms: list[float] = []
        construct_ms: list[float] = []
        ground_truth_ms: list[float] = []
        ground_truth_bytes: list[int] = []
        for _ in range(steps):
            t0 = time.perf_counter()
            truths = world.step()
            t1 = time.perf_counter()
            step_ms.append(1e3 * (t1 - t0))
            counts.append(len(truths))

            fields = [dict(truth) for truth in truths]
            x_m = np.array([truth.x_m for truth in truths])
            y_m = np.array([truth.y_m for truth in truths])
            t_road = time.perf_counter()
            world.site.road_frame.to_road(x_m, y_m)
            t2 = time.perf_counter()
            for values in fields:
                VehicleTruth(**values)
            t3 = time.perf_counter()
            for values in fields:
                VehicleTruth.model_construct(**values)
            t4 = time.perf_counter()
            payload = codec.encode(
                GroundTruth(
                    site=world.site.site_id,
                    source_id="simulator",
                    stamp=world.sim_time_s,
                    step_index=world.step_index,
                    vehicles=truths,
                )
            )
            t5 = time.perf_counter()
            to_road_ms.append(1e3 * (t2 - t_road))
            validate_ms.append(1e3 * (t3 - t2))
            construct_ms.append(1e3 * (t4 - t3))
            ground_truth_ms.append(1e3 * (t5 - t4))
            ground_truth_bytes.append(len(payload))
        counters = world.counters
    vehicle_steps = sum(counts)
    return {
        "vehicles_per_hour": vehicles_per_hour,
        "step_s": STEP_S,
        "startup_s": startup_s,
        "target_vehicles": target,
        "warmup_vehicles": warmup_vehicles,
        "warmup_sim_s": warmup_sim_s,
        "warmup_wall_s": warmup_wall_s,
        "steps": steps,
        "step_ms": summarize(step_ms),
        "vehicles": {
            "min": min(counts),
            "median": statistics.median(counts),
            "max": max(counts),
        },
        "realtime_factor_median": STEP_S / (1e-3 * statistics.median(step_ms)),
        "realtime_factor_overall": steps * STEP_S / (1e-3 * sum(step_ms)),
        "per_vehicle_step_us": 1e3 * sum(step_ms) / vehicle_steps if vehicle_steps else 0.0,
        "to_road_ms": summarize(to_road_ms),
        "vehicle_truth_validate_ms": summarize(validate_ms),
        "vehicle_truth_construct_ms": summarize(construct_ms),
        "ground_truth_build_encode_ms": summarize(ground_truth_ms),
        "ground_truth_bytes_median": statistics.median(ground_truth_bytes),
        "collisions": counters.collisions,
        "teleports": counters.teleports,
    }


def measure_duration(vehicles_per_hour: float, duration_s: float, work_dir: Path) -> dict[str, Any]:
    """Run ``duration_s`` simulated seconds end to end (runs in the child)."""
    start = time.perf_counter()
    counts: list[int] = []
    with _world(vehicles_per_hour, work_dir, duration_s=duration_s) as world:
        started = time.perf_counter()
        while not world.finished:
            counts.append(len(world.step()))
        stepped = time.perf_counter()
        counters = world.counters
        sim_s = world.sim_time_s
    closed = time.perf_counter()
    return {
        "vehicles_per_hour": vehicles_per_hour,
        "step_s": STEP_S,
        "duration_s": sim_s,
        "steps": len(counts),
        "startup_s": started - start,
        "stepping_s": stepped - started,
        "close_s": closed - stepped,
        "total_s": closed - start,
        "realtime_factor": sim_s / (stepped - started),
        "vehicles": {
            "median": statistics.median(counts),
            "max": max(counts),
        },
        "departed": counters.departed,
        "arrived": counters.arrived,
        "collisions": counters.collisions,
        "teleports": counters.teleports,
    }


def _child(*args: str) -> dict[str, Any]:
    """Run this module as a child process and return what it measured."""
    with tempfile.TemporaryDirectory(prefix="wz-bench-sumo-") as folder:
        out = Path(folder) / "result.json"
        work_dir = Path(folder) / "work"
        command = [sys.executable, "-m", "benchmarks.sumo_step", *args]
        command += ["--out", str(out), "--work-dir", str(work_dir)]
        subprocess.run(command, cwd=ROOT, check=True, timeout=600)
        result: dict[str, Any] = json.loads(out.read_text())
    return result


def run(quick: bool) -> dict[str, Any]:
    """Step time at ~60 vehicles, then whole runs of 10 simulated minutes (2 quick)."""
    steps = 200 if quick else 1000
    duration_s = 120.0 if quick else 600.0
    log.info("sumo_step: %d steps at %.0f veh/h", steps, STEP_VEHICLES_PER_HOUR)
    stepping = _child(
        "steps",
        "--vehicles-per-hour",
        str(STEP_VEHICLES_PER_HOUR),
        "--steps",
        str(steps),
        "--target",
        str(TARGET_VEHICLES),
    )
    runs = []
    for vehicles_per_hour in (1400.0, STEP_VEHICLES_PER_HOUR):
        log.info("sumo_step: %.0f simulated s at %.0f veh/h", duration_s, vehicles_per_hour)
        flow = ("--vehicles-per-hour", str(vehicles_per_hour), "--duration", str(duration_s))
        runs.append(_child("duration", *flow))
    return {"stepping": stepping, "end_to_end": runs}


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.sumo_step")
    parser.add_argument("mode", choices=("steps", "duration"))
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--work-dir", type=Path, required=True)
    parser.add_argument("--vehicles-per-hour", type=float, default=STEP_VEHICLES_PER_HOUR)
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--target", type=int, default=TARGET_VEHICLES)
    parser.add_argument("--duration", type=float, default=600.0)
    args = parser.parse_args()
    if args.mode == "steps":
        result = measure_steps(args.vehicles_per_hour, args.steps, args.target, args.work_dir)
    else:
        result = measure_duration(args.vehicles_per_hour, args.duration, args.work_dir)
    args.out.write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
