"""Dataset export: simulated camera frames with YOLO labels, LiDAR frames with 3D boxes.

``wz dataset --out DIR`` (or ``python -m wz_simulator.dataset``) runs the work zone for each
weather preset, samples the sensors every ``--every-s`` seconds after a warm-up, and writes::

    DIR/data.yaml                     ultralytics dataset file (paths, class names)
    DIR/images/{train,val}/*.jpg      camera frames
    DIR/labels/{train,val}/*.txt      YOLO labels: class cx cy w h (normalised to the image)
    DIR/truth/{train,val}/*.json      per camera frame: every vehicle in view with its class,
                                      visible and full boxes, visibility, ground range from the
                                      camera and road position (for evaluation by distance)
    DIR/lidar/{train,val}/*.npz       points (N,4) sensor frame, labels (N,), truth boxes
    DIR/manifest.json                 site, sensors, seeds, weathers, counts per class

Train/val split by time: the first ``1 - val_share`` of each weather's run is training data,
the rest validation, so near-identical consecutive frames never straddle the split. A camera
label is written for a vehicle whose visible part covers at least ``--min-visibility`` of its
silhouette and is at least ``--min-box-px`` tall; the box is the visible part's box.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wz_shared.camera_geometry import PinholeCamera
from wz_shared.logs import configure_logging
from wz_shared.messages import VehicleClass, VehicleTruth
from wz_shared.site import Site, load_site
from wz_simulator.sensors.camera import CameraTruthLabel
from wz_simulator.sensors.rig import CameraOutput, LidarOutput, SensorRig
from wz_simulator.sensors.scene import WEATHER_PRESETS
from wz_simulator.settings import SimulatorSettings
from wz_simulator.traffic.world import TrafficWorld

log = logging.getLogger(__name__)

#: YOLO class ids, in the order of ``data.yaml``'s names.
YOLO_CLASSES: tuple[VehicleClass, ...] = (
    VehicleClass.CAR,
    VehicleClass.TRUCK,
    VehicleClass.BUS,
    VehicleClass.MOTORCYCLE,
)


@dataclass(frozen=True)
class DatasetOptions:
    out_dir: Path
    seed: int = 1
    weathers: tuple[str, ...] = ("day", "dusk", "rain", "fog")
    duration_s: float = 120.0
    every_s: float = 1.0
    warmup_s: float = 60.0
    val_share: float = 0.2
    vehicles_per_hour: float = 1800.0
    truck_share: float = 0.2
    min_visibility: float = 0.3
    min_box_px: float = 6.0
    lidar: bool = True
    jpeg_quality: int = 92


def yolo_lines(
    labels: tuple[CameraTruthLabel, ...],
    width_px: int,
    height_px: int,
    min_visibility: float,
    min_box_px: float,
) -> list[str]:
    """YOLO label lines (class cx cy w h, normalised) of the visible enough vehicles."""
    lines = []
    for label in labels:
        box = label.box_xyxy_px
        if box is None or label.visibility < min_visibility:
            continue
        x0, y0, x1, y1 = box
        if y1 - y0 < min_box_px or x1 - x0 < 2.0:
            continue
        class_id = YOLO_CLASSES.index(label.vehicle_class)
        cx, cy = 0.5 * (x0 + x1) / width_px, 0.5 * (y0 + y1) / height_px
        w, h = (x1 - x0) / width_px, (y1 - y0) / height_px
        lines.append(f"{class_id} {cx:.6f} {cy:.6f} {w:.6f} {h:.6f}")
    return lines


def in_frame_fraction(
    camera: PinholeCamera, vehicle: VehicleTruth, width_px: int, height_px: int
) -> float:
    """Share of a vehicle's projected box inside the frame: 1 in full view, 0 when a corner is
    behind the camera. (The renderer's visibility counts only pixels inside the frame, so a
    car mostly out of the picture would otherwise look fully visible.)"""
    c, s = math.cos(vehicle.heading_rad), math.sin(vehicle.heading_rad)
    corners = [
        (vehicle.x_m + dx * c - dy * s, vehicle.y_m + dx * s + dy * c, z)
        for dx in (-vehicle.length_m / 2, vehicle.length_m / 2)
        for dy in (-vehicle.width_m / 2, vehicle.width_m / 2)
        for z in (vehicle.z_m, vehicle.z_m + vehicle.height_m)
    ]
    uv, depth = camera.project(np.array(corners))
    if np.any(depth <= 0.0) or not np.all(np.isfinite(uv)):
        return 0.0
    x0, y0 = uv.min(axis=0)
    x1, y1 = uv.max(axis=0)
    area = (x1 - x0) * (y1 - y0)
    inside = max(0.0, min(x1, width_px) - max(x0, 0.0)) * max(
        0.0, min(y1, height_px) - max(y0, 0.0)
    )
    return float(inside / area) if area > 0 else 0.0


def truth_records(
    output: CameraOutput, vehicles: list[VehicleTruth], camera: PinholeCamera
) -> list[dict[str, object]]:
    """One record per vehicle that shows in the frame (a visible box), for evaluation.

    ``visibility`` is the renderer's (unoccluded share of the silhouette inside the frame);
    ``in_frame`` the share of the projected box inside the frame; ``visible_fraction`` their
    product, the share of the vehicle one can see.
    """
    camera_xy_m = (float(camera.position_m[0]), float(camera.position_m[1]))
    width_px, height_px = output.meta.width_px, output.meta.height_px
    by_id = {vehicle.vehicle_id: vehicle for vehicle in vehicles}
    records: list[dict[str, object]] = []
    for label in output.frame.labels:
        if label.box_xyxy_px is None:
            continue
        vehicle = by_id[label.vehicle_id]  # the rig culls: the label index is not ours
        in_frame = in_frame_fraction(camera, vehicle, width_px, height_px)
        records.append(
            {
                "vehicle_id": label.vehicle_id,
                "class": label.vehicle_class.value,
                "box_xyxy_px": [round(v, 2) for v in label.box_xyxy_px],
                "full_box_xyxy_px": (
                    None
                    if label.full_box_xyxy_px is None
                    else [round(v, 2) for v in label.full_box_xyxy_px]
                ),
                "visibility": round(label.visibility, 4),
                "in_frame": round(in_frame, 4),
                "visible_fraction": round(label.visibility * in_frame, 4),
                "range_m": round(
                    math.hypot(vehicle.x_m - camera_xy_m[0], vehicle.y_m - camera_xy_m[1]), 3
                ),
                "station_m": round(vehicle.station_m, 3),
                "offset_m": round(vehicle.offset_m, 3),
            }
        )
    return records


def _write_lidar(path: Path, output: LidarOutput) -> None:
    scan = output.scan
    boxes = scan.boxes
    np.savez_compressed(
        path,
        points=scan.points,
        labels=scan.labels,
        vehicle_ids=np.array(scan.vehicle_ids, dtype=str),
        box_labels=np.array([b.label for b in boxes], dtype=np.int32),
        box_vehicle_ids=np.array([b.vehicle_id for b in boxes], dtype=str),
        box_centers_sensor_m=np.array([b.center_sensor_m for b in boxes]).reshape(-1, 3),
        box_yaws_sensor_rad=np.array([b.yaw_sensor_rad for b in boxes]),
        box_centers_site_m=np.array([b.center_site_m for b in boxes]).reshape(-1, 3),
        box_yaws_site_rad=np.array([b.yaw_site_rad for b in boxes]),
        box_sizes_lwh_m=np.array([b.size_lwh_m for b in boxes]).reshape(-1, 3),
        box_num_points=np.array([b.num_points for b in boxes], dtype=np.int32),
        stamp_s=np.array(scan.meta.stamp),
    )


def export(site: Site, options: DatasetOptions, work_dir: Path | None = None) -> dict[str, object]:
    """Run the simulation per weather and write the dataset; return the manifest."""
    out = options.out_dir
    for split in ("train", "val"):
        for folder in ("images", "labels", "truth"):
            (out / folder / split).mkdir(parents=True, exist_ok=True)
        if options.lidar:
            (out / "lidar" / split).mkdir(parents=True, exist_ok=True)
    cameras = [m.sensor_id for m in site.sensors if m.kind == "camera"]
    lidars = [m.sensor_id for m in site.sensors if m.kind == "lidar"] if options.lidar else []
    if not cameras and not lidars:
        raise ValueError(f"site {site.site_id} has no camera or LiDAR to export")
    counts: Counter[str] = Counter()
    cameras_by_id: dict[str, PinholeCamera] = {}
    class_counts: Counter[str] = Counter()
    samples = max(1, round(options.duration_s / options.every_s))
    train_samples = math.floor(samples * (1.0 - options.val_share))
    for run, weather_name in enumerate(options.weathers):
        seed = options.seed + run
        settings_kwargs: dict[str, object] = {
            "seed": seed,
            "realtime_factor": 0.0,
            "sensors_enabled": False,
            "vehicles_per_hour": options.vehicles_per_hour,
            "truck_share": options.truck_share,
            "duration_s": options.warmup_s + options.duration_s + 1.0,
        }
        if work_dir is not None:
            settings_kwargs["work_dir"] = work_dir
        settings = SimulatorSettings.model_validate(settings_kwargs)
        rig = SensorRig(
            site,
            WEATHER_PRESETS[weather_name],
            seed,
            sensor_ids=cameras + lidars,
            jpeg_quality=options.jpeg_quality,
        )
        with TrafficWorld(site, settings) as world:
            sample = 0
            next_sample_s = options.warmup_s
            while sample < samples and not world.finished:
                vehicles = world.step()
                now_s = world.sim_time_s
                if now_s + 1e-9 < next_sample_s:
                    continue
                split = "train" if sample < train_samples else "val"
                name = f"{weather_name}-s{seed}-{sample:05d}"
                for sensor_id in cameras + lidars:
                    output = rig.capture(sensor_id, sample, now_s, vehicles, now_s)
                    stem = f"{name}-{sensor_id}"
                    if isinstance(output, CameraOutput):
                        (out / "images" / split / f"{stem}.jpg").write_bytes(output.jpeg)
                        lines = yolo_lines(
                            output.frame.labels,
                            output.meta.width_px,
                            output.meta.height_px,
                            options.min_visibility,
                            options.min_box_px,
                        )
                        (out / "labels" / split / f"{stem}.txt").write_text(
                            "".join(line + "\n" for line in lines)
                        )
                        camera = cameras_by_id.setdefault(
                            sensor_id, PinholeCamera(site.sensor(sensor_id))
                        )
                        records = truth_records(output, vehicles, camera)
                        (out / "truth" / split / f"{stem}.json").write_text(
                            json.dumps(
                                {"stamp_s": now_s, "sensor_id": sensor_id, "vehicles": records}
                            )
                        )
                        counts[f"images_{split}"] += 1
                        for line in lines:
                            class_counts[YOLO_CLASSES[int(line.split()[0])].value] += 1
                    elif isinstance(output, LidarOutput):
                        _write_lidar(out / "lidar" / split / f"{stem}.npz", output)
                        counts[f"lidar_{split}"] += 1
                sample += 1
                next_sample_s += options.every_s
        log.info("weather %s (seed %d): %d samples", weather_name, seed, sample)
    names = {index: cls.value for index, cls in enumerate(YOLO_CLASSES)}
    (out / "data.yaml").write_text(
        f"# Written by wz dataset for site {site.site_id}\n"
        f"path: {out.resolve()}\ntrain: images/train\nval: images/val\n"
        + "names:\n"
        + "".join(f"  {index}: {name}\n" for index, name in names.items())
    )
    manifest: dict[str, object] = {
        "site_id": site.site_id,
        "sensors": [
            m.model_dump(mode="json") for m in site.sensors if m.sensor_id in cameras + lidars
        ],
        "options": {k: str(v) if isinstance(v, Path) else v for k, v in options.__dict__.items()},
        "counts": dict(counts),
        "camera_labels_per_class": dict(class_counts),
        "yolo_classes": names,
    }
    (out / "manifest.json").write_text(json.dumps(manifest, indent=2))
    return manifest


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="wz dataset",
        description="Export simulated camera frames (YOLO labels) and LiDAR frames (3D boxes).",
    )
    parser.add_argument("--out", type=Path, required=True, help="output folder")
    parser.add_argument("--site", type=Path, default=SimulatorSettings().site_file)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument(
        "--weather",
        default="day,dusk,rain,fog",
        help="comma-separated presets: day, dusk, rain, fog",
    )
    parser.add_argument("--duration-s", type=float, default=120.0)
    parser.add_argument("--every-s", type=float, default=1.0)
    parser.add_argument("--warmup-s", type=float, default=60.0)
    parser.add_argument("--val-share", type=float, default=0.2)
    parser.add_argument("--vehicles-per-hour", type=float, default=1800.0)
    parser.add_argument("--truck-share", type=float, default=0.2)
    parser.add_argument("--min-visibility", type=float, default=0.3)
    parser.add_argument("--no-lidar", action="store_true", help="camera frames only")
    args = parser.parse_args(argv)
    weathers = tuple(w.strip() for w in args.weather.split(",") if w.strip())
    unknown = [w for w in weathers if w not in WEATHER_PRESETS]
    if unknown or not weathers:
        parser.error(f"unknown weather {unknown}; choose from {sorted(WEATHER_PRESETS)}")
    if not 0.0 <= args.val_share < 1.0 or args.every_s <= 0 or args.duration_s <= 0:
        parser.error("need 0 <= --val-share < 1, --every-s > 0 and --duration-s > 0")
    site = load_site(args.site)
    configure_logging(service="dataset", site=site.site_id)
    options = DatasetOptions(
        out_dir=args.out,
        seed=args.seed,
        weathers=weathers,
        duration_s=args.duration_s,
        every_s=args.every_s,
        warmup_s=args.warmup_s,
        val_share=args.val_share,
        vehicles_per_hour=args.vehicles_per_hour,
        truck_share=args.truck_share,
        min_visibility=args.min_visibility,
        lidar=not args.no_lidar,
    )
    manifest = export(site, options)
    sys.stdout.write(
        json.dumps(
            {
                "out": str(args.out),
                **{k: manifest[k] for k in ("counts", "camera_labels_per_class")},
            }
        )
        + "\n"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
