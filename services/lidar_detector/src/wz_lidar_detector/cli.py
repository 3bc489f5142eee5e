"""``wz detect-lidar``: run a detection path on LiDAR files, one JSON line per file.

Usage (``python -m wz_lidar_detector.cli``, or ``wz detect-lidar``)::

    wz detect-lidar FILE... [--background FILE] [--path fast|reference]
                    [--frame sensor|site] [--site SITE.yaml] [--sensor ID]

Each input (PCD, PLY or NPZ; see :mod:`wz_shared.pointcloud_files`) gives one line on stdout::

    {"file": "rawdata.pcd", "stamp": 0.0, "path": "reference", "frame": "sensor",
     "rows": 80, "columns": 1800, "points": 95026, "foreground_points": 9731,
     "detections": [{"x": ..., "y": ..., "z": ..., "length": ..., "width": ..., "height": ...,
                     "heading": ..., "class": "car", "points": 412, "score": 1.0,
                     "covariance": [[sxx, sxy], [sxy, syy]]}, ...],
     "timings_ms": {"roi": 1.2, ...}}

or, for a file that cannot be read or processed, ``{"file": ..., "error": "..."}``; the other
files are still processed and the exit code is then 1. Positions are in metres and headings in
radians, in the sensor frame (default) or the site frame (``--frame site``: moved with the pose
of ``--sensor`` in ``--site``). ``stamp`` is the file's own (NPZ ``stamp_s``), else 0.

With ``--background`` the fast path runs: a PCD/PLY/NPZ cloud of background points becomes a
voxel background, an ``.npz`` saved by the node (``WZ_LIDAR_BACKGROUND_FILE``) is loaded as it
is. Without it, the reference path (the paper's pipeline) runs. Parameters come from the
node's settings, so ``WZ_LIDAR_REFERENCE__*`` and ``WZ_LIDAR_FAST__*`` tune them here too.
Logs go to stderr.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
import zipfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from wz_lidar_detector.background import (
    BackgroundFileError,
    VoxelBackground,
    load_background,
)
from wz_lidar_detector.detection import BoxDetection, DetectionResult, PointFrame
from wz_lidar_detector.fast import FastPipeline
from wz_lidar_detector.reference import ReferencePipeline
from wz_lidar_detector.settings import LidarDetectorSettings, lidar_mount
from wz_lidar_detector.transform import box_to_site
from wz_shared.logs import configure_logging
from wz_shared.pointcloud_files import PointCloudFileError, read_point_cloud
from wz_shared.site import LidarIntrinsics, SensorMount, SiteFileError, load_site

log = logging.getLogger("wz_lidar_detector.cli")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="wz detect-lidar",
        description="Detect vehicles in LiDAR files (PCD v0.7 ascii/binary/binary_compressed, "
        "PLY, NPZ) and print one JSON object per file on stdout. With --background the fast "
        "path runs (background subtraction); without it, the reference path (the paper's "
        "pipeline).",
        epilog="Exit codes: 0 every file processed, 1 at least one file failed (its line has an "
        '"error"), 2 usage error. Tune the paths with the node\'s variables, e.g. '
        "WZ_LIDAR_REFERENCE__VOXEL_SIZE_M=0.3 or WZ_LIDAR_FAST__CLUSTER_EPS_M=0.8.",
    )
    parser.add_argument("files", nargs="+", type=Path, metavar="FILE", help="LiDAR frames")
    parser.add_argument(
        "--background",
        type=Path,
        metavar="FILE",
        help="background for the fast path: a PCD/PLY/NPZ cloud of background points, or an "
        ".npz background saved by the node",
    )
    parser.add_argument(
        "--path",
        choices=["fast", "reference"],
        help="detection path (default: fast with --background, else reference)",
    )
    parser.add_argument(
        "--frame",
        choices=["sensor", "site"],
        default="sensor",
        help="frame of the output positions and headings (default sensor)",
    )
    parser.add_argument(
        "--site",
        type=Path,
        help="site file for --frame site (default: WZ_SITE_FILE or the default site)",
    )
    parser.add_argument(
        "--sensor", metavar="ID", help="the LiDAR's id in the site (default: its first LiDAR)"
    )
    return parser


def _number(value: float, digits: int = 4) -> float | None:
    return round(value, digits) if math.isfinite(value) else None


def box_json(box: BoxDetection) -> dict[str, Any]:
    """One box as the JSON object of the output (rounded to 0.1 mm / 0.1 mrad)."""
    (sxx, sxy), (syx, syy) = box.covariance_xy_m2
    x, y, z = box.center_xyz_m
    length, width, height = box.size_lwh_m
    return {
        "x": _number(x),
        "y": _number(y),
        "z": _number(z),
        "length": _number(length),
        "width": _number(width),
        "height": _number(height),
        "heading": _number(box.heading_rad),
        "class": box.object_class.value,
        "points": box.num_points,
        "score": _number(box.score, 3),
        "covariance": [[_number(sxx, 6), _number(sxy, 6)], [_number(syx, 6), _number(syy, 6)]],
    }


def frame_json(
    path: Path,
    frame: PointFrame,
    result: DetectionResult,
    *,
    detection_path: str,
    mount: SensorMount | None,
) -> dict[str, Any]:
    """The output line of one processed file (``mount`` moves boxes to the site frame)."""
    boxes = result.detections
    if mount is not None:
        boxes = [box_to_site(box, mount.pose) for box in boxes]
    return {
        "file": str(path),
        "stamp": frame.stamp_s,
        "path": detection_path,
        "frame": "sensor" if mount is None else "site",
        "rows": frame.rows,
        "columns": frame.columns,
        "points": int(np.isfinite(frame.points[:, :3]).all(axis=1).sum()),
        "foreground_points": int(np.count_nonzero(result.foreground)),
        "detections": [box_json(box) for box in boxes],
        "timings_ms": {name: round(1e3 * s, 3) for name, s in result.timings_s.items()},
    }


def _load_background(path: Path, settings: LidarDetectorSettings) -> FastPipeline:
    """A saved model (an .npz with a ``kind``) or a cloud of background points."""
    saved = False
    if path.suffix.lower() == ".npz" and path.is_file():
        try:
            with np.load(path, allow_pickle=False) as archive:
                saved = "kind" in archive.files
        except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
            raise PointCloudFileError(path, f"not a readable NPZ archive: {exc}") from exc
    if saved:
        try:
            return FastPipeline(settings.fast, load_background(path))
        except (KeyError, EOFError, zipfile.BadZipFile) as exc:  # an archive cut short
            raise BackgroundFileError(f"{path}: not a complete background model ({exc})") from exc
    cloud = read_point_cloud(path)
    xyz = cloud.points[:, :3]
    xyz = xyz[np.isfinite(xyz).all(axis=1)]
    if len(xyz) == 0:
        raise PointCloudFileError(path, "the background has no valid point")
    background = VoxelBackground.from_points(xyz, settings.voxel_m)
    log.info(
        "voxel background of %d voxels (%g m) from %d points of %s",
        background.num_voxels,
        settings.voxel_m,
        len(xyz),
        path,
    )
    return FastPipeline(settings.fast, background)


def _write(line: dict[str, Any]) -> None:
    sys.stdout.write(json.dumps(line) + "\n")
    sys.stdout.flush()


def run(argv: Sequence[str] | None = None) -> int:
    """Parse ``argv``, process every file, return the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    detection_path = args.path or ("fast" if args.background else "reference")
    if detection_path == "fast" and args.background is None:
        parser.error("the fast path needs --background (a background cloud or a saved .npz)")
    if detection_path == "reference" and args.background is not None:
        parser.error("--background is for the fast path; leave out --path reference")
    settings = LidarDetectorSettings(path=detection_path)
    # The site gives the pose for --frame site, and organizes NPZ exports by the LiDAR's layout.
    site_file = args.site or settings.site_file
    try:
        mount = lidar_mount(load_site(site_file), args.sensor)
    except (SiteFileError, ValueError) as exc:
        if args.frame == "site" or args.site or args.sensor:
            parser.error(str(exc))
        mount = None
    intrinsics = mount.intrinsics if mount is not None else None
    shape_hint = (
        (intrinsics.beams, intrinsics.azimuth_steps)
        if isinstance(intrinsics, LidarIntrinsics)
        else None
    )

    detector: ReferencePipeline | FastPipeline
    if detection_path == "fast":
        try:
            detector = _load_background(args.background, settings)
        except (PointCloudFileError, BackgroundFileError) as exc:
            _write({"file": str(args.background), "error": f"background: {exc}"})
            return 1
    else:
        detector = ReferencePipeline(settings.reference)

    failed = 0
    for path in args.files:
        try:
            frame = read_point_cloud(path, shape_hint=shape_hint)
            result = detector.detect(frame)
        except PointCloudFileError as exc:
            failed += 1
            _write({"file": str(path), "error": str(exc)})
            continue
        except Exception as exc:  # one file the core cannot handle must not stop the others
            failed += 1
            log.debug("detection failed on %s", path, exc_info=True)
            _write({"file": str(path), "error": f"{path}: detection failed: {exc}"})
            continue
        _write(
            frame_json(
                path,
                frame,
                result,
                detection_path=detection_path,
                mount=mount if args.frame == "site" else None,
            )
        )
    return 1 if failed else 0


def main() -> None:
    configure_logging(service="wz-detect-lidar", site="-")
    try:
        code = run()
    except BrokenPipeError:  # `wz detect-lidar ... | head`
        code = 0
    sys.exit(code)


if __name__ == "__main__":
    main()
