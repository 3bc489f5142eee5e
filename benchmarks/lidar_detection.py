"""LiDAR detector: both paths on the same simulated frames, scored against truth and timed.

Frames come from :mod:`benchmarks.lidar_frames` (default site, mast LiDAR 64 x 2048, traffic
with trucks). The fast path learns its range-image background from the learning frames (with
traffic in them); the reference path needs none. Both then run on the same evaluation frames:

- accuracy (:mod:`wz_lidar_detector.evaluation`): recall and precision by range bin for
  vehicles within 120 m and at least 30 % visible, and the centre error of paired detections:
  the fast path's completed-box centre against the paper's centroid of points;
- speed: median and p90 per frame, per-step medians of the reference path, and the frame rate
  one core sustains (the service's whole per-frame work, single-threaded: open3d and BLAS
  limited to one thread in a child process).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import ROOT
from benchmarks.lidar_frames import make_frames

log = logging.getLogger(__name__)


def _load(path: Path) -> tuple[list[Any], list[Any], list[list[Any]]]:
    from wz_lidar_detector.detection import PointFrame
    from wz_lidar_detector.evaluation import TruthVehicle

    with np.load(path) as data:
        rows, columns = int(data["rows"]), int(data["columns"])
        learn = [PointFrame(p, rows, columns) for p in data["learn_points"]]
        frames = [PointFrame(p, rows, columns) for p in data["eval_points"]]
        truth_json = json.loads(str(data["truth_json"]))
    truths = [
        [
            TruthVehicle(
                t["vehicle_id"],
                tuple(t["center_xyz_m"]),
                tuple(t["size_lwh_m"]),
                t["heading_rad"],
                t["visibility"],
                t["num_points"],
            )
            for t in frame
        ]
        for frame in truth_json
    ]
    return learn, frames, truths


def _prior() -> float:
    from wz_lidar_detector.node import road_heading_in_sensor_frame
    from wz_shared.site import DEFAULT_SITE_PATH, load_site

    site = load_site(DEFAULT_SITE_PATH)
    return road_heading_in_sensor_frame(site, next(m for m in site.sensors if m.kind == "lidar"))


def _score_and_time(path: Path, repeats: int) -> dict[str, Any]:
    from wz_lidar_detector.background import RangeImageBackground
    from wz_lidar_detector.evaluation import Scorer, percentile
    from wz_lidar_detector.fast import FastPipeline, FastSettings
    from wz_lidar_detector.reference import ReferencePipeline, ReferenceSettings

    learn, frames, truths = _load(path)
    start = time.perf_counter()
    background = RangeImageBackground.learn(learn)
    learn_s = time.perf_counter() - start
    # Scoring runs on a frozen background so both paths see exactly the same task; the heading
    # prior is the site's road direction in the sensor frame, as the node sets it.
    fast = FastPipeline(
        FastSettings(update_background=False, heading_prior_rad=_prior()), background
    )
    reference = ReferencePipeline(ReferenceSettings())
    results: dict[str, Any] = {
        "frames": len(frames),
        "learn_frames": len(learn),
        "background_learn_s": learn_s,
    }
    for name, pipeline in (("reference", reference), ("fast", fast)):
        scorer = Scorer()
        times: list[float] = []
        steps: dict[str, list[float]] = {}
        for frame, truth in zip(frames, truths, strict=True):
            for _ in range(repeats):
                start = time.perf_counter()
                result = pipeline.detect(frame)
                times.append(time.perf_counter() - start)
                for step, seconds in result.timings_s.items():
                    steps.setdefault(step, []).append(seconds)
            scorer.add_frame(result.detections, truth)
        total = scorer.total()
        results[name] = {
            "median_ms": 1e3 * statistics.median(times),
            "p90_ms": 1e3 * float(np.percentile(times, 90)),
            "steps_median_ms": {k: 1e3 * statistics.median(v) for k, v in steps.items()},
            "bins": [
                {
                    "range_m": f"{b.low_m:.0f}-{b.high_m:.0f}",
                    "scored": b.scored,
                    "hits": b.hits,
                    "recall": b.recall,
                    "detections": b.detections,
                    "false_alarms": b.false_alarms,
                    "precision": b.precision,
                    "centre_error_median_m": percentile(b.centre_errors_m, 50),
                    "centre_error_p95_m": percentile(b.centre_errors_m, 95),
                }
                for b in [*scorer.bins, total]
            ],
        }
    results["speedup"] = results["reference"]["median_ms"] / results["fast"]["median_ms"]
    return results


def _one_core_rate(path: Path) -> dict[str, Any]:
    """Frames per second of each path with one thread, in a child process."""
    env = {
        **os.environ,
        "OMP_NUM_THREADS": "1",
        "OPENBLAS_NUM_THREADS": "1",
        "MKL_NUM_THREADS": "1",
    }
    out = path.with_suffix(".onecore.json")
    subprocess.run(
        [
            "taskset",
            "-c",
            "0",
            sys.executable,
            "-m",
            "benchmarks.lidar_detection",
            "one-core",
            str(path),
            str(out),
        ],
        cwd=ROOT,
        env=env,
        check=True,
        timeout=1800,
    )
    result: dict[str, Any] = json.loads(out.read_text())
    return result


def _one_core_child(path: Path, out: Path) -> None:
    import open3d as o3d

    from wz_lidar_detector.background import RangeImageBackground
    from wz_lidar_detector.fast import FastPipeline, FastSettings
    from wz_lidar_detector.reference import ReferencePipeline, ReferenceSettings

    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    learn, frames, _ = _load(path)
    background = RangeImageBackground.learn(learn)
    rates = {}
    for name, pipeline in (
        ("fast", FastPipeline(FastSettings(heading_prior_rad=_prior()), background)),
        ("reference", ReferencePipeline(ReferenceSettings())),
    ):
        start = time.perf_counter()
        for frame in frames:
            pipeline.detect(frame)
        rates[name] = len(frames) / (time.perf_counter() - start)
    out.write_text(json.dumps({"frames_per_s": rates, "points_per_frame": len(frames[0].points)}))


def run(quick: bool) -> dict[str, Any]:
    path = make_frames(quick)
    results = _score_and_time(path, repeats=1 if quick else 3)
    results["one_core"] = _one_core_rate(path)
    return results


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.lidar_detection")
    parser.add_argument("mode", choices=("one-core", "score"))
    parser.add_argument("frames", type=Path)
    parser.add_argument("out", type=Path, nargs="?")
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO)
    if args.mode == "one-core":
        _one_core_child(args.frames, args.out)
    else:
        sys.stdout.write(json.dumps(_score_and_time(args.frames, repeats=1), indent=1) + "\n")


if __name__ == "__main__":
    main()
