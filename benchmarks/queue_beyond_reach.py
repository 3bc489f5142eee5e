"""A queue's back beyond the mast's reach, bounded by the upstream point speed sensors.

On the 12 congested out-of-sample sites of issue 40 (``traffic_sites``' congested set: site
seeds from 10100, a demand ramp peaking at 1.05-1.3 of the closure's capacity, the weather
cycling), SUMO alone runs 300 s after 60 s of warm-up with each generated site's point sensors
as induction loops (:mod:`wz_simulator.traffic.loops`). The mast's tracks are the truth where
the site's sensors see a car in that weather (perfect tracking: what is measured here is the
point sensors' part, not the tracker's), and :func:`wz_eval.queue_report.queue_report` scores
the back at every second the estimate had it beyond the reach against the truth's back on the
whole approach (every vehicle, seen or not).

Per site: the seconds beyond the reach, the share of them the point sensors bounded (one read
the lane free upstream of the queue), the share with the true back inside the bounds (15 m
either side), the bounds' median width, and, for comparison, the median distance from the
reach (all a back beyond it was before: "at least this far") to the true back. The whole
pipeline with these sensors is ``traffic_sites``; this one needs no rendering (about a minute
a site).
"""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

from wz_eval.alerts import truth_batches
from wz_eval.coverage_report import weather_coverage
from wz_eval.pipeline import ramp_settings
from wz_eval.queue_report import queue_report, seen_frames
from wz_eval.sites import plan_jobs
from wz_shared.messages import PointSensorReading, VehicleTruth
from wz_shared.site_generator import generate_site
from wz_simulator.settings import SimulatorSettings
from wz_simulator.traffic.world import TrafficWorld

FIRST_SEED, COUNT, DURATION_S, WARMUP_S = 10100, 12, 300.0, 60.0
QUICK = (1, 120.0, 60.0)
#: Truth frames kept for the mast's "tracks": every 4th step (5 Hz; the queue is sampled at
#: 1 Hz).
FRAME_STRIDE = 4


def _site_row(job: Any, duration_s: float, warmup_s: float, work_dir: Path) -> dict[str, Any]:
    site = generate_site(job.seed)
    settings = SimulatorSettings.model_validate(
        {
            "seed": job.seed,
            "realtime_factor": 0.0,
            "sensors_enabled": False,
            "demand_ratio": job.demand_ratio,
            "demand_profile": job.demand_profile,
            "work_zone_headways": True,
            **ramp_settings(warmup_s, duration_s),
            "truck_share": job.truck_share,
            "duration_s": warmup_s + duration_s,
            "work_dir": work_dir,
        }
    )
    frames: list[tuple[float, list[VehicleTruth]]] = []
    readings: list[PointSensorReading] = []
    started = time.perf_counter()
    with TrafficWorld(site, settings) as world:
        while not world.finished:
            vehicles = world.step()
            readings += world.point_readings()
            if world.sim_time_s >= warmup_s and world.step_index % FRAME_STRIDE == 0:
                frames.append((world.sim_time_s, vehicles))
    coverage = weather_coverage(site, job.weather)
    tracks, _ = truth_batches(site, seen_frames(frames, coverage))
    report = queue_report(site, tracks, frames, warmup_s, warmup_s + duration_s, coverage, readings)
    beyond = report["beyond_reach"]
    seconds = beyond["seconds"]
    return {
        "site": site.site_id,
        "weather": job.weather,
        "demand_ratio": job.demand_ratio,
        "point_sensors": len(site.point_sensors),
        "interval_s": site.point_sensors[0].interval_s if site.point_sensors else None,
        "reach_m": {k: v["reach_station_m"] for k, v in report["lanes"].items()},
        "beyond_s": seconds,
        "bounded_share": round(beyond["bounded_s"] / seconds, 3) if seconds else None,
        "within_share": round(beyond["truth_within_bounds_s"] / beyond["bounded_s"], 3)
        if beyond["bounded_s"]
        else None,
        "bound_width_median_m": beyond["bound_width_m"]["median"],
        "outside_by_p90_m": beyond["outside_by_m"]["p90"],
        "reach_to_back_median_m": beyond["reach_to_back_m"]["median"],
        "wall_s": round(time.perf_counter() - started, 1),
    }


def run(quick: bool) -> dict[str, Any]:
    count, duration_s, warmup_s = QUICK if quick else (COUNT, DURATION_S, WARMUP_S)
    rows = []
    with tempfile.TemporaryDirectory(prefix="wz-bench-beyond-") as tmp:
        jobs = plan_jobs(count, FIRST_SEED, duration_s, warmup_s, Path(tmp), traffic="congested")
        for job in jobs:
            rows.append(_site_row(job, duration_s, warmup_s, Path(tmp) / "sumo"))
    beyond = [r for r in rows if r["beyond_s"]]
    within = [r["within_share"] for r in beyond if r["within_share"] is not None]
    return {
        "first_seed": FIRST_SEED,
        "duration_s": duration_s,
        "warmup_s": warmup_s,
        "sites_with_back_beyond": len(beyond),
        "within_share_median": round(statistics.median(within), 3) if within else None,
        "rows": rows,
    }
