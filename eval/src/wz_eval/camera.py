"""``wz eval-camera``: camera ranging against truth by distance, Eq. 1-2 vs calibrated vs radar.

Runs the simulated work zone (SUMO, the camera and the radar of the site, one weather) and the
camera-radar detector's own per-frame code (:meth:`CameraDetector.process_frame`: YOLO where
due, optical flow between, image
tracker, ranging, radar fusion) in one process, on simulation time, with no bus. Each published
image track is matched to the vehicle it shows by image box (IoU >= 0.5 with the vehicle's
visible truth box), and three position estimates of that vehicle at the frame's time are
compared with its true centre, in the road frame (longitudinal = station, lateral = offset):

- ``paper_eq12``: the box's bottom centre through the paper's Eq. 1-2 (angles from field of
  view and tilt, flat road), used as the position, as published;
- ``calibrated``: the full pinhole model (intrinsics, extrinsics, lens distortion) with the
  contact-point correction to the vehicle's centre (class size, road heading);
- ``camera_radar``: what the detector publishes: the radar's range (carried to the frame's time,
  moved from the echo on the near face to the centre) along the camera's bearing; a track the
  radar did not pair stays at its calibrated position. ``radar_paired`` gives the share paired.
  On a frame the model skipped the node publishes nothing (``publish_followed``): no
  ``camera_radar`` position is scored there.

Errors are reported by true ground range from the camera (bins of 25 m to 150 m): count, RMSE
and median absolute error per axis, plus the signed mean (the bias: Eq. 1-2 puts vehicles about
half a length too near the camera). Writes ``camera-eval.json`` and ``camera-eval.md`` in
``--out``.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
import time
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wz_camera_detector.node import CameraDetector
from wz_camera_detector.settings import (
    SIMULATION_MODEL_PATH,
    CameraDetectorSettings,
    camera_mount,
    radar_mount,
)
from wz_camera_detector.tracker import ImageTrack
from wz_camera_detector.world import paper_box_to_ground
from wz_camera_detector.yolo import box_iou
from wz_eval import camera_video
from wz_shared.camera_geometry import camera_intrinsics
from wz_shared.logs import configure_logging
from wz_shared.messages import VehicleTruth
from wz_shared.site import Site, load_site
from wz_simulator.sensors.camera import CameraTruthLabel
from wz_simulator.sensors.rig import CameraOutput, RadarOutput, SensorRig, moved
from wz_simulator.sensors.scene import WEATHER_PRESETS
from wz_simulator.settings import SimulatorSettings
from wz_simulator.traffic.world import TrafficWorld

log = logging.getLogger("wz_eval.camera")

DEFAULT_OUT = Path("runs/camera-eval")

METHODS = ("paper_eq12", "calibrated", "camera_radar")
RANGE_BINS_M: tuple[tuple[float, float], ...] = (
    (0, 25),
    (25, 50),
    (50, 75),
    (75, 100),
    (100, 150),
)
#: Least IoU between a track's box and a vehicle's visible truth box to score the track.
MATCH_IOU = 0.5
#: The published image tracks are scored against the vehicles at least this tall [px] and at
#: least :data:`MIN_VISIBLE` visible, whose box centre lies in the detector's region of interest;
#: an unmatched track box smaller than that, or overlapping (IoU >= :data:`IGNORED_IOU`) a
#: vehicle not scored, is neither true nor false.
MIN_HEIGHT_PX = 20.0
MIN_VISIBLE = 0.5
IGNORED_IOU = 0.3


@dataclass(frozen=True)
class CameraEvalOptions:
    site_file: Path
    model_path: Path | None
    seed: int = 7
    duration_s: float = 120.0
    warmup_s: float = 60.0
    weather: str = "day"
    vehicles_per_hour: float = 1400.0
    work_dir: Path | None = None
    #: The camera's frame rate [Hz]; None: the site file's.
    camera_fps: float | None = None
    #: The detector on every frame, no optical flow (the node before issue 41).
    every_frame: bool = False


@dataclass
class Errors:
    """Signed errors (estimate - truth) per axis [m]."""

    longitudinal: list[float]
    lateral: list[float]

    def summary(self) -> dict[str, float | int]:
        lon, lat = np.asarray(self.longitudinal), np.asarray(self.lateral)
        if lon.size == 0:
            return {"n": 0}
        return {
            "n": int(lon.size),
            "rmse_longitudinal_m": float(np.sqrt(np.mean(lon**2))),
            "rmse_lateral_m": float(np.sqrt(np.mean(lat**2))),
            "median_abs_longitudinal_m": float(np.median(np.abs(lon))),
            "median_abs_lateral_m": float(np.median(np.abs(lat))),
            "bias_longitudinal_m": float(np.mean(lon)),
            "bias_lateral_m": float(np.mean(lat)),
        }


def range_bin(range_m: float) -> str | None:
    for lo, hi in RANGE_BINS_M:
        if lo <= range_m < hi:
            return f"{lo:g}-{hi:g}"
    return None


def match_tracks(
    track_boxes: list[tuple[float, float, float, float]], labels: tuple[CameraTruthLabel, ...]
) -> list[str | None]:
    """The vehicle id each track box shows (greedy by IoU >= :data:`MATCH_IOU`), or None."""
    candidates = [
        (label.vehicle_id, label.box_xyxy_px) for label in labels if label.box_xyxy_px is not None
    ]
    if not candidates or not track_boxes:
        return [None] * len(track_boxes)
    truth = np.array([box for _, box in candidates], dtype=np.float64)
    ious = np.stack([box_iou(np.array(box, dtype=np.float64), truth) for box in track_boxes])
    out: list[str | None] = [None] * len(track_boxes)
    taken: set[int] = set()
    for flat in np.argsort(-ious, axis=None):
        t, v = np.unravel_index(flat, ious.shape)
        if ious[t, v] < MATCH_IOU:
            break
        if out[t] is None and int(v) not in taken:
            out[t] = candidates[int(v)][0]
            taken.add(int(v))
    return out


def evaluate(site: Site, options: CameraEvalOptions) -> dict[str, object]:
    """Run the simulation and the detector; the report as a dict (module docstring)."""
    camera = camera_mount(site, None)
    radar = radar_mount(site, None)
    if radar is None:
        raise ValueError(f"site {site.site_id} has no radar: camera+radar cannot be evaluated")
    settings_kwargs: dict[str, object] = {"backend": "yolo", "radar_id": radar.sensor_id}
    if options.every_frame:
        settings_kwargs |= {"detection_period_s": 0.0, "flow": {"enabled": False}}
    if options.camera_fps is not None:
        sensors = [
            m.model_copy(update={"rate_hz": options.camera_fps})
            if m.sensor_id == camera.sensor_id
            else m
            for m in site.sensors
        ]
        site = site.model_copy(update={"sensors": sensors})
        camera = camera_mount(site, camera.sensor_id)
    if options.model_path is not None:
        settings_kwargs["model_path"] = options.model_path
    settings = CameraDetectorSettings.model_validate(settings_kwargs)
    problems: dict[str, int] = defaultdict(int)

    def report(reason: str, detail: str) -> None:
        problems[reason] += 1

    detector = CameraDetector(site, camera, radar, settings, report, rendered=True)
    sim_kwargs: dict[str, object] = {
        "seed": options.seed,
        "realtime_factor": 0.0,
        "sensors_enabled": False,
        "vehicles_per_hour": options.vehicles_per_hour,
        "duration_s": options.warmup_s + options.duration_s + 1.0,
    }
    if options.work_dir is not None:
        sim_kwargs["work_dir"] = options.work_dir
    rig = SensorRig(
        site,
        WEATHER_PRESETS[options.weather],
        options.seed,
        sensor_ids=[camera.sensor_id, radar.sensor_id],
    )
    errors: dict[str, dict[str, Errors]] = {m: defaultdict(lambda: Errors([], [])) for m in METHODS}
    paired = tracked = matched = on_bus = 0
    images = {"vehicles": 0, "found": 0, "tracks": 0, "false": 0}
    frames = 0
    detect_s: list[float] = []
    start_detecting_s = max(0.0, options.warmup_s - 3.0)  # let image tracks confirm first
    road = site.road_frame
    cam_xy = (camera.pose.x_m, camera.pose.y_m)
    with TrafficWorld(site, SimulatorSettings.model_validate(sim_kwargs)) as world:
        while not world.finished:
            vehicles = world.step()
            now_s = world.sim_time_s
            for output in rig.fire(vehicles, now_s):
                if isinstance(output, RadarOutput):
                    detector.radar_scan(output.result.scan)
                    continue
                if not isinstance(output, CameraOutput) or output.meta.stamp < start_detecting_s:
                    continue
                stamp_s = output.meta.stamp
                started = time.perf_counter()
                result = detector.process_frame(output.jpeg, stamp_s, output.meta.frame_index)
                detect_s.append(time.perf_counter() - started)
                if result is None or stamp_s < options.warmup_s:
                    continue
                frames += 1
                truth = {v.vehicle_id: v for v in moved(vehicles, stamp_s - now_s)}
                ids = match_tracks([t.box_xyxy_px for t in result.tracks], output.frame.labels)
                _score_images(result.tracks, ids, output.frame.labels, detector, images)
                objects = {o.local_id: o for o in result.camera_objects}
                fused = {
                    f.camera_local_id: f for f in result.fused if f.camera_local_id is not None
                }
                for track, vehicle_id in zip(result.tracks, ids, strict=True):
                    tracked += 1
                    if vehicle_id is None or track.local_id not in objects:
                        continue
                    vehicle: VehicleTruth = truth[vehicle_id]
                    bin_label = range_bin(
                        math.hypot(vehicle.x_m - cam_xy[0], vehicle.y_m - cam_xy[1])
                    )
                    if bin_label is None:
                        continue
                    matched += 1
                    obj = objects[track.local_id]
                    estimates = {
                        "paper_eq12": paper_box_to_ground(camera, track.box_xyxy_px),
                        "calibrated": (obj.x_m, obj.y_m),
                    }
                    out = fused.get(track.local_id)  # none on a flow frame (not published)
                    if out is not None:
                        on_bus += 1
                        paired += out.source == "camera+radar"
                        estimates["camera_radar"] = (out.x_m, out.y_m)
                    true_s, true_d = road.to_road(vehicle.x_m, vehicle.y_m)
                    for method, (x_m, y_m) in estimates.items():
                        if not (math.isfinite(x_m) and math.isfinite(y_m)):
                            continue
                        s_m, d_m = road.to_road(x_m, y_m)
                        errors[method][bin_label].longitudinal.append(float(s_m - true_s))
                        errors[method][bin_label].lateral.append(float(d_m - true_d))
    bins = [f"{lo:g}-{hi:g}" for lo, hi in RANGE_BINS_M]
    table = {
        method: {b: errors[method][b].summary() for b in bins}
        | {
            "all": Errors(
                [e for b in bins for e in errors[method][b].longitudinal],
                [e for b in bins for e in errors[method][b].lateral],
            ).summary()
        }
        for method in METHODS
    }
    return {
        "site": site.site_id,
        "camera": camera.sensor_id,
        "radar": radar.sensor_id,
        "model": str(settings.model_path or SIMULATION_MODEL_PATH),
        "seed": options.seed,
        "weather": options.weather,
        "duration_s": options.duration_s,
        "frames": frames,
        "tracks_published": tracked,
        "tracks_scored": matched,
        "radar_paired": paired / on_bus if on_bus else math.nan,
        "detector_problems": dict(problems),
        "process_image_ms_median": float(np.median(detect_s)) * 1e3 if detect_s else math.nan,
        "camera_fps": camera.rate_hz,
        "every_frame": options.every_frame,
        "frames_processed": len(detect_s),
        "detector_runs": detector.detections_run,
        "image_tracks": {
            **images,
            "recall": images["found"] / images["vehicles"] if images["vehicles"] else math.nan,
            "precision": (
                (images["tracks"] - images["false"]) / images["tracks"]
                if images["tracks"]
                else math.nan
            ),
        },
        "errors_by_range_m": table,
    }


def _score_images(
    tracks: list[ImageTrack],
    ids: list[str | None],
    labels: tuple[CameraTruthLabel, ...],
    detector: CameraDetector,
    counts: dict[str, int],
) -> None:
    """Count one frame's published image tracks against the vehicles in view (recall and
    precision of the boxes, :data:`MIN_HEIGHT_PX`, :data:`MIN_VISIBLE`)."""
    intrinsics = camera_intrinsics(detector.camera_mount)
    width, height = intrinsics.width_px, intrinsics.height_px
    roi = getattr(detector.backend, "roi_xyxy_px", None) or (0, 0, width, height)
    scored: set[str] = set()
    ignored: list[tuple[float, float, float, float]] = []
    for label in labels:
        box = label.box_xyxy_px
        if box is None:
            continue
        u, v = (box[0] + box[2]) / 2.0, (box[1] + box[3]) / 2.0
        visible = label.visible_pixels / max(1, label.silhouette_pixels)
        if (
            box[3] - box[1] >= MIN_HEIGHT_PX
            and visible >= MIN_VISIBLE
            and roi[0] <= u <= roi[2]
            and roi[1] <= v <= roi[3]
        ):
            scored.add(label.vehicle_id)
        else:
            ignored.append(box)
    found = {vehicle_id for vehicle_id in ids if vehicle_id in scored}
    counts["vehicles"] += len(scored)
    counts["found"] += len(found)
    for track, vehicle_id in zip(tracks, ids, strict=True):
        if vehicle_id in scored:
            counts["tracks"] += 1
            continue
        box = np.clip(np.array(track.box_xyxy_px), 0.0, [width, height, width, height])
        small = box[3] - box[1] < MIN_HEIGHT_PX
        if vehicle_id is not None or small:
            continue  # a vehicle not scored (far, hidden), or too small to judge
        if ignored and float(box_iou(box, np.array(ignored)).max()) >= IGNORED_IOU:
            continue
        counts["tracks"] += 1
        counts["false"] += 1


def markdown(report: dict[str, object]) -> str:
    """The report's error table in Markdown."""
    table = report["errors_by_range_m"]
    assert isinstance(table, dict)
    images = report["image_tracks"]
    assert isinstance(images, dict)
    lines = [
        f"Published image tracks ({report['camera_fps']:g} fps, detector on "
        f"{report['detector_runs']} frames{', every frame' if report['every_frame'] else ''}): "
        f"recall {images['recall']:.3f} of {images['vehicles']} vehicle-frames in view (at "
        f"least {MIN_HEIGHT_PX:g} px tall, {MIN_VISIBLE:.0%} visible), precision "
        f"{images['precision']:.3f} ({images['false']} false of {images['tracks']}).",
        "",
        f"Camera ranging on `{report['site']}` ({report['weather']}, seed {report['seed']}, "
        f"{report['duration_s']:g} s, {report['frames']} frames, {report['tracks_scored']} scored "
        f"track positions, radar paired {100 * float(report['radar_paired']):.0f} %).",  # type: ignore[arg-type]
        "",
        "| range [m] | n | Eq. 1-2 lon / lat RMSE [m] | calibrated lon / lat | camera+radar lon / lat |",
        "|---|---|---|---|---|",
    ]
    for b in [*[f"{lo:g}-{hi:g}" for lo, hi in RANGE_BINS_M], "all"]:
        cells = []
        n = table["calibrated"][b].get("n", 0)
        for method in METHODS:
            row = table[method][b]
            cells.append(
                "-"
                if not row.get("n")
                else f"{row['rmse_longitudinal_m']:.2f} / {row['rmse_lateral_m']:.2f}"
            )
        lines.append(f"| {b} | {n} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "| range [m] | Eq. 1-2 lon bias | calibrated lon bias | camera+radar lon bias |",
        "|---|---|---|---|",
    ]
    for b in [*[f"{lo:g}-{hi:g}" for lo, hi in RANGE_BINS_M], "all"]:
        cells = [
            "-" if not table[m][b].get("n") else f"{table[m][b]['bias_longitudinal_m']:+.2f}"
            for m in METHODS
        ]
        lines.append(f"| {b} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="wz eval-camera",
        description=__doc__.split("\n")[0]
        + "; with --video and --truth: the detector on real video (wz_eval.camera_video).",
    )
    parser.add_argument("--site", type=Path, default=SimulatorSettings().site_file)
    camera_video.add_arguments(parser)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--duration-s", type=float, default=120.0)
    parser.add_argument("--warmup-s", type=float, default=60.0)
    parser.add_argument("--weather", default="day", choices=sorted(WEATHER_PRESETS))
    parser.add_argument("--vehicles-per-hour", type=float, default=1400.0)
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    parser.add_argument(
        "--camera-fps",
        type=float,
        default=None,
        help="the camera's rate [Hz] (default: the site's)",
    )
    parser.add_argument(
        "--every-frame",
        action="store_true",
        help="the detector on every frame, no optical flow (the node before issue 41)",
    )
    args = parser.parse_args(argv)
    if args.video is not None:
        if args.out == DEFAULT_OUT:
            args.out = Path("runs/camera-video-eval")
        return camera_video.run(args)
    site = load_site(args.site)
    configure_logging(service="eval-camera", site=site.site_id)
    options = CameraEvalOptions(
        site_file=args.site,
        model_path=args.model,
        seed=args.seed,
        duration_s=args.duration_s,
        warmup_s=args.warmup_s,
        weather=args.weather,
        vehicles_per_hour=args.vehicles_per_hour,
        camera_fps=args.camera_fps,
        every_frame=args.every_frame,
    )
    if args.camera_fps is not None and not 0.0 < args.camera_fps <= 60.0:
        sys.stderr.write("wz eval-camera: --camera-fps in (0, 60]\n")
        return 2
    report = evaluate(site, options)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "camera-eval.json").write_text(json.dumps(report, indent=2) + "\n")
    text = markdown(report)
    (args.out / "camera-eval.md").write_text(text)
    sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
