"""Fusion tracker: time per cycle with 200 tracks fed by three asynchronous sensors.

200 vehicles drive at 20-35 m/s in 8 lanes over 1.6 km (so they never leave), seen by three
sensors with their own rates and noise: a LiDAR at 20 Hz (0.2 m), a camera at 10 Hz (1.0 m along
its line of sight, 0.3 m across) and a radar at 15 Hz (0.5 m, with speed), each detecting 95 %
of the vehicles each frame. The tracker (:class:`MultiTargetTracker`, default settings, the road
heading hooks of a straight road, for one point and for many, as the node has them) takes the
batches in stamp order. After a 5 s warm-up (every vehicle has a confirmed track), each batch's
``add`` (predict, gate, assign, update, start, merge) is timed, and the 10 Hz snapshot
``tracks(t)`` that the node publishes. The result: the median and p99 of a cycle, per sensor
and over all.

The batches come in stamp order, so the tracker runs with no reorder window: each ``add``
processes exactly its own batch, and a cycle's time is that batch's. With the node's 150 ms
window an ``add`` processes the batches released by it (none, one or two), so per call the
times mix batches; that run is reported too (``windowed``), with its mean per call, which is
the same work.

``queue_300``: the must-show of issue 40, a three-lane queue: 300 vehicles in 3 lanes, 7.5 m
apart (jam spacing, 750 m of queue), creeping at 2-2.1 m/s (a wider spread would drive
them through each other), the same three sensors; the cycle's
median and p99 (no reorder window), the snapshot too.

``bias_map_correction``: what the node adds before the tracker when it is given a lateral bias
map (``WZ_FUSION_BIAS_MAP``): :meth:`LateralBiasCorrector.correct` on one sensor's batch of 10
and of 200 detections on the default site's road, 60-1100 m, with the shipped map.
"""

from __future__ import annotations

import statistics
import time
from typing import Any

import numpy as np

from wz_fusion_tracker.calibration import LateralBiasCorrector, load_bias_map
from wz_fusion_tracker.settings import TrackerSettings
from wz_fusion_tracker.tracker import MultiTargetTracker
from wz_fusion_tracker.types import Measurement
from wz_shared.site import DEFAULT_SITE_PATH, load_site

VEHICLES = 200
LANES = 8
SENSORS = {  # id: (rate [Hz], std along x [m], std along y [m], has speed)
    "lidar": (20.0, 0.2, 0.2, False),
    "camera": (10.0, 1.0, 0.3, False),
    "radar": (15.0, 0.5, 0.5, True),
}


#: The three-lane queue: vehicles, lanes, spacing along a lane [m], speeds [m/s].
QUEUE = (300, 3, 7.5, (2.0, 2.1))


def _batches(
    duration_s: float,
    seed: int = 1,
    vehicles: int = VEHICLES,
    lanes: int = LANES,
    spacing_m: float = 60.0,
    speeds_mps: tuple[float, float] = (20.0, 35.0),
) -> list[tuple[float, str, list[Measurement]]]:
    rng = np.random.default_rng(seed)
    lane_y = (np.arange(vehicles) % lanes) * 3.6
    start_x = np.repeat(np.arange(vehicles // lanes), lanes) * spacing_m + rng.uniform(
        0, spacing_m / 3.0, vehicles
    )
    speed = rng.uniform(*speeds_mps, vehicles)
    events = []
    for sensor, (rate, sx, sy, has_speed) in SENSORS.items():
        phase = rng.uniform(0, 1.0 / rate)
        for k in range(int(duration_s * rate)):
            t = phase + k / rate
            seen = rng.random(vehicles) < 0.95
            cov = np.diag([sx**2, sy**2])
            x = start_x + speed * t + rng.normal(0, sx, vehicles)
            y = lane_y + rng.normal(0, sy, vehicles)
            measurements = [
                Measurement(
                    x_m=float(x[i]),
                    y_m=float(y[i]),
                    covariance_m2=cov,
                    object_class="car",
                    length_m=4.6,
                    width_m=1.8,
                    speed_mps=float(speed[i] + rng.normal(0, 0.3)) if has_speed else None,
                )
                for i in np.flatnonzero(seen)
            ]
            events.append((t, sensor, measurements))
    return sorted(events, key=lambda e: e[0])


def _stats(values_s: list[float]) -> dict[str, float]:
    ordered = sorted(values_s)
    return {
        "median_ms": 1e3 * statistics.median(ordered),
        "mean_ms": 1e3 * statistics.fmean(ordered),
        "p99_ms": 1e3 * ordered[int(0.99 * (len(ordered) - 1))],
        "max_ms": 1e3 * ordered[-1],
        "samples": len(ordered),
    }


def run(quick: bool) -> dict[str, Any]:
    duration_s = 12.0 if quick else 40.0
    events = _batches(duration_s)
    result = _run_tracker(events, duration_s, TrackerSettings(reorder_window_s=0.0))
    # as the node runs it: the default 150 ms window, an add processing what it releases
    windowed = _run_tracker(events, duration_s, TrackerSettings())
    result["windowed"] = {"cycle": windowed["cycle"], "snapshot": windowed["snapshot"]}
    # the IMM option (not the default) on the same batches: what its second model costs
    imm = _run_tracker(
        events, duration_s, TrackerSettings(motion_model="imm", reorder_window_s=0.0)
    )
    result["imm"] = {
        "cycle": imm["cycle"],
        "snapshot": imm["snapshot"],
        "confirmed_tracks_median": imm["confirmed_tracks_median"],
    }
    # issue 40: a three-lane queue of 300 vehicles, creeping alike
    vehicles, lanes, spacing_m, speeds = QUEUE
    queue = _run_tracker(
        _batches(duration_s, 2, vehicles, lanes, spacing_m, speeds),
        duration_s,
        TrackerSettings(reorder_window_s=0.0),
    )
    result["queue_300"] = {
        "vehicles": vehicles,
        "lanes": lanes,
        "spacing_m": spacing_m,
        "cycle": queue["cycle"],
        "snapshot": queue["snapshot"],
        "confirmed_tracks_median": queue["confirmed_tracks_median"],
    }
    result["bias_map_correction"] = _bias_map_correction(repeats=200 if quick else 1000)
    return result


def _bias_map_correction(repeats: int) -> dict[str, Any]:
    site = load_site(DEFAULT_SITE_PATH)
    corrector = LateralBiasCorrector(
        site, load_bias_map(DEFAULT_SITE_PATH.with_suffix(".bias-map.json"))
    )
    rng = np.random.default_rng(2)
    out: dict[str, Any] = {}
    for size in (10, 200):
        stations = rng.uniform(60.0, 1100.0, size)
        offsets = rng.choice([-1.83, 1.83], size) + rng.normal(0.0, 0.2, size)
        x, y = site.road_frame.to_site(stations, offsets)
        batch = [
            Measurement(
                x_m=float(x[i]),
                y_m=float(y[i]),
                covariance_m2=np.eye(2) * 0.04,
                sensor_id="lidar-mast",
            )
            for i in range(size)
        ]
        times = []
        for _ in range(repeats):
            started = time.perf_counter()
            corrector.correct("lidar-mast", batch)
            times.append(time.perf_counter() - started)
        out[f"batch_of_{size}"] = _stats(times)
    return out


def _run_tracker(
    events: list[tuple[float, str, list[Measurement]]], duration_s: float, settings: TrackerSettings
) -> dict[str, Any]:
    warmup_s = 5.0
    # the road's heading at a point and, as the node gives it too, for many points at once
    tracker = MultiTargetTracker(
        settings, heading_at=lambda x, y: 0.0, headings_at=lambda x, y: np.zeros(np.shape(x))
    )
    per_sensor: dict[str, list[float]] = {sensor: [] for sensor in SENSORS}
    snapshots: list[float] = []
    next_snapshot = 0.0
    confirmed_counts = []
    for stamp, sensor, measurements in events:
        started = time.perf_counter()
        tracker.add(sensor, stamp, measurements)
        elapsed = time.perf_counter() - started
        if stamp >= warmup_s:
            per_sensor[sensor].append(elapsed)
        while next_snapshot <= stamp - tracker.settings.reorder_window_s:
            started = time.perf_counter()
            states = tracker.tracks(max(next_snapshot, tracker.last_processed_stamp_s or 0.0))
            elapsed = time.perf_counter() - started
            if stamp >= warmup_s:
                snapshots.append(elapsed)
                confirmed_counts.append(sum(1 for s in states if s.status != "tentative"))
            next_snapshot += 0.1
    all_cycles = [v for values in per_sensor.values() for v in values]
    return {
        "vehicles": VEHICLES,
        "sensors": {k: {"rate_hz": v[0]} for k, v in SENSORS.items()},
        "duration_s": duration_s,
        "confirmed_tracks_median": statistics.median(confirmed_counts) if confirmed_counts else 0,
        "tracks_started": tracker.counters.tracks_started,
        "cycle": _stats(all_cycles),
        "per_sensor": {sensor: _stats(values) for sensor, values in per_sensor.items()},
        "snapshot": _stats(snapshots),
    }
