"""Simulated LiDAR frames with truth, for scoring and timing the LiDAR detector.

Run as ``python -m benchmarks.lidar_frames OUT.npz`` (libsumo allows one simulation per
process, so callers run it in a child). The default site's mast LiDAR (64 x 2048) sees traffic
at ``vehicles_per_hour`` after a warm-up; the file holds

- ``learn_points``: (K, N, 4) frames for learning a background (with traffic: a background
  model must cope with vehicles passing), one every ``learn_every_s``;
- ``eval_points``: (M, N, 4) frames to score, one every ``eval_every_s`` after those;
- per eval frame, the truth of every vehicle with points or within 130 m: centre, size and yaw
  in the sensor frame, its points in the frame, and its visibility: points in the frame over
  points when it is scanned alone (other vehicles removed, static scene kept).
"""

from __future__ import annotations

import argparse
import json
import logging
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import ROOT

log = logging.getLogger(__name__)

TRUTH_RANGE_M = 130.0


def generate(
    out: Path,
    *,
    seed: int,
    vehicles_per_hour: float,
    warmup_s: float,
    learn_frames: int,
    learn_every_s: float,
    eval_frames: int,
    eval_every_s: float,
    work_dir: Path,
) -> dict[str, Any]:
    from wz_shared.site import DEFAULT_SITE_PATH, load_site
    from wz_simulator.sensors.lidar import LidarModel
    from wz_simulator.sensors.scene import WEATHER_PRESETS, static_scene, vehicle_boxes
    from wz_simulator.settings import SimulatorSettings
    from wz_simulator.traffic.world import TrafficWorld

    site = load_site(DEFAULT_SITE_PATH)
    mount = next(m for m in site.sensors if m.kind == "lidar")
    model = LidarModel.from_scene(
        mount,
        static_scene(site),
        WEATHER_PRESETS["day"],
        seed,
        boxes_for=vehicle_boxes,
        site_id=site.site_id,
    )
    settings = SimulatorSettings(
        seed=seed,
        realtime_factor=0.0,
        sensors_enabled=False,
        truck_share=0.2,
        vehicles_per_hour=vehicles_per_hour,
        work_dir=work_dir,
        duration_s=warmup_s + learn_frames * learn_every_s + eval_frames * eval_every_s + 1.0,
    )
    times = [warmup_s + k * learn_every_s for k in range(learn_frames)]
    start_eval = warmup_s + learn_frames * learn_every_s
    times += [start_eval + k * eval_every_s for k in range(eval_frames)]
    learn, evaluate, truths = [], [], []
    frame_index = 0
    with TrafficWorld(site, settings) as world:
        for when in times:
            while world.sim_time_s + 1e-9 < when:
                vehicles = world.step()
            now = world.sim_time_s
            scan = model.scan(vehicles, now, frame_index, truth_stamp_s=now)
            frame_index += 1
            if len(learn) < learn_frames:
                learn.append(scan.points)
                continue
            evaluate.append(scan.points)
            frame_truth = []
            for box in scan.boxes:
                horizontal = float(np.hypot(*box.center_sensor_m[:2]))
                if box.num_points == 0 and horizontal > TRUTH_RANGE_M:
                    continue
                alone_vehicle = [v for v in vehicles if v.vehicle_id == box.vehicle_id]
                alone = model.scan(alone_vehicle, now, frame_index + 10_000_000, truth_stamp_s=now)
                alone_points = int((alone.labels == 1).sum())
                frame_truth.append(
                    {
                        "vehicle_id": box.vehicle_id,
                        "center_xyz_m": box.center_sensor_m,
                        "size_lwh_m": box.size_lwh_m,
                        "heading_rad": box.yaw_sensor_rad,
                        "num_points": box.num_points,
                        "visibility": box.num_points / alone_points if alone_points else 0.0,
                    }
                )
            truths.append(frame_truth)
    np.savez_compressed(
        out,
        learn_points=np.stack(learn),
        eval_points=np.stack(evaluate),
        truth_json=np.array(json.dumps(truths)),
        rows=np.array(model.rows),
        columns=np.array(model.columns),
    )
    return {
        "learn_frames": len(learn),
        "eval_frames": len(evaluate),
        "vehicles_scored_candidates": sum(len(t) for t in truths),
    }


def make_frames(quick: bool, seed: int = 11) -> Path:
    """Generate the frames in a child process; return the .npz path (in a temp folder)."""
    folder = Path(tempfile.mkdtemp(prefix="wz-lidar-frames-"))
    out = folder / "frames.npz"
    args = [
        sys.executable,
        "-m",
        "benchmarks.lidar_frames",
        str(out),
        "--seed",
        str(seed),
        "--learn-frames",
        "20" if quick else "40",
        "--eval-frames",
        "10" if quick else "40",
        "--work-dir",
        str(folder / "work"),
    ]
    subprocess.run(args, cwd=ROOT, check=True, timeout=1800)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.lidar_frames")
    parser.add_argument("out", type=Path)
    parser.add_argument("--seed", type=int, default=11)
    parser.add_argument("--vehicles-per-hour", type=float, default=2000.0)
    parser.add_argument("--warmup-s", type=float, default=90.0)
    parser.add_argument("--learn-frames", type=int, default=40)
    parser.add_argument("--learn-every-s", type=float, default=0.5)
    parser.add_argument("--eval-frames", type=int, default=40)
    parser.add_argument("--eval-every-s", type=float, default=1.0)
    parser.add_argument("--work-dir", type=Path, default=Path(tempfile.gettempdir()) / "wz-bench")
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO)
    summary = generate(
        args.out,
        seed=args.seed,
        vehicles_per_hour=args.vehicles_per_hour,
        warmup_s=args.warmup_s,
        learn_frames=args.learn_frames,
        learn_every_s=args.learn_every_s,
        eval_frames=args.eval_frames,
        eval_every_s=args.eval_every_s,
        work_dir=args.work_dir,
    )
    log.info("lidar frames: %s", summary)


if __name__ == "__main__":
    main()
