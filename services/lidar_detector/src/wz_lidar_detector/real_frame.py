"""Both paths on the real roadside frame, compared with that dataset's own foreground.

``python -m wz_lidar_detector.real_frame [--data DIR] [--out PICTURE.png]`` reads the real
80-beam freeway frame (``rawdata.pcd``), its accumulated background (``background.pcd``) and
the foreground another method produced (``filtered.pcd``, Su et al. 2024) from ``--data``, runs
the fast path (voxel background from ``background.pcd``) and the reference path, prints one
JSON summary, and draws a top view:

- grey: all returns; orange: the fast path's foreground; cyan rings: the reference foreground
  of ``filtered.pcd``; green boxes: the fast path's detections (completed boxes, centre dot);
  red crosses: the reference path's detections (centroids).

Agreement near the road (``x`` in -10..130 m, ``|y|`` < 20 m) is measured both ways: the share
of ``filtered.pcd`` points within ``match_m`` of a fast-path foreground point, and the share of
fast-path foreground points within ``match_m`` of a ``filtered.pcd`` point.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from wz_lidar_detector.background import VoxelBackground
from wz_lidar_detector.detection import DetectionResult
from wz_lidar_detector.fast import FastPipeline, FastSettings
from wz_lidar_detector.reference import ReferencePipeline, ReferenceSettings
from wz_shared.pointcloud_files import read_point_cloud

DEFAULT_DATA = Path(__file__).resolve().parents[4] / "samples" / "real-freeway-lidar"
ROAD_X_M = (-10.0, 130.0)
ROAD_ABS_Y_M = 20.0


def _near_road(xyz: npt.NDArray[np.float32]) -> npt.NDArray[np.bool_]:
    return (
        (xyz[:, 0] >= ROAD_X_M[0]) & (xyz[:, 0] <= ROAD_X_M[1]) & (np.abs(xyz[:, 1]) < ROAD_ABS_Y_M)
    )


def agreement(
    ours: npt.NDArray[np.float32], theirs: npt.NDArray[np.float32], match_m: float
) -> tuple[float, float]:
    """(share of theirs near ours, share of ours near theirs), near the road."""
    ours, theirs = ours[_near_road(ours), :3], theirs[_near_road(theirs), :3]
    if not len(ours) or not len(theirs):
        return 0.0, 0.0
    theirs_covered = cKDTree(ours).query(theirs, distance_upper_bound=match_m)[0] <= match_m
    ours_covered = cKDTree(theirs).query(ours, distance_upper_bound=match_m)[0] <= match_m
    return float(theirs_covered.mean()), float(ours_covered.mean())


def top_view(
    points: npt.NDArray[np.float32],
    foreground: npt.NDArray[np.bool_],
    reference_points: npt.NDArray[np.float32],
    fast: DetectionResult,
    reference: DetectionResult,
    px_per_m: float = 8.0,
) -> npt.NDArray[np.uint8]:
    """The picture described in the module docstring (x to the right, y up)."""
    x0, x1 = ROAD_X_M[0] - 5.0, ROAD_X_M[1] + 5.0
    y0, y1 = -25.0, 25.0
    width, height = int((x1 - x0) * px_per_m), int((y1 - y0) * px_per_m)
    image = np.full((height, width, 3), 16, dtype=np.uint8)

    def px(xy: npt.NDArray[np.float64]) -> npt.NDArray[np.int32]:
        u = (xy[:, 0] - x0) * px_per_m
        v = (y1 - xy[:, 1]) * px_per_m
        return np.column_stack([u, v]).astype(np.int32)

    def dots(xyz: npt.NDArray[np.float32], colour: tuple[int, int, int]) -> None:
        uv = px(xyz[:, :2].astype(np.float64))
        keep = (uv[:, 0] >= 0) & (uv[:, 0] < width) & (uv[:, 1] >= 0) & (uv[:, 1] < height)
        image[uv[keep, 1], uv[keep, 0]] = colour

    valid = np.isfinite(points[:, 0])
    dots(points[valid & ~foreground], (90, 90, 90))
    for u, v in px(reference_points[:, :2].astype(np.float64)):
        if 0 <= u < width and 0 <= v < height:
            cv2.circle(image, (int(u), int(v)), 2, (200, 200, 0), 1)
    dots(points[foreground], (0, 140, 255))
    for box in fast.detections:
        cx, cy, _ = box.center_xyz_m
        length, width_m, _ = box.size_lwh_m
        c, s = np.cos(box.heading_rad), np.sin(box.heading_rad)
        corners = np.array([[1, 1], [1, -1], [-1, -1], [-1, 1]]) * [0.5 * length, 0.5 * width_m]
        polygon = corners @ np.array([[c, s], [-s, c]]) + [cx, cy]
        cv2.polylines(image, [px(polygon)], True, (60, 220, 60), 1, cv2.LINE_AA)
        centre = px(np.array([[cx, cy]]))[0]
        cv2.circle(image, (int(centre[0]), int(centre[1])), 2, (60, 220, 60), -1)
    for box in reference.detections:
        centre = px(np.array([box.center_xyz_m[:2]]))[0]
        cv2.drawMarker(
            image, (int(centre[0]), int(centre[1])), (60, 60, 230), cv2.MARKER_CROSS, 8, 1
        )
    for x in range(0, int(ROAD_X_M[1]) + 1, 20):
        u = int((x - x0) * px_per_m)
        cv2.line(image, (u, height - 12), (u, height - 4), (160, 160, 160), 1)
        cv2.putText(
            image,
            f"{x} m",
            (u + 2, height - 14),
            cv2.FONT_HERSHEY_SIMPLEX,
            0.35,
            (160, 160, 160),
            1,
            cv2.LINE_AA,
        )
    legend = (
        "grey: returns  orange: fast-path foreground  cyan: filtered.pcd (Su et al.)  "
        "green: fast boxes  red: reference centroids"
    )
    cv2.putText(
        image, legend, (8, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (220, 220, 220), 1, cv2.LINE_AA
    )
    return image


def run(data: Path, out: Path | None, match_m: float = 0.3) -> dict[str, Any]:
    raw = read_point_cloud(data / "rawdata.pcd")
    background_points = read_point_cloud(data / "background.pcd").points
    reference_foreground = read_point_cloud(data / "filtered.pcd").points
    background = VoxelBackground.from_points(background_points[:, :3])
    # The carriageway runs along the sensor's x axis (the dataset's README): the heading prior.
    fast_settings = FastSettings(update_background=False, heading_prior_rad=0.0)
    fast = FastPipeline(fast_settings, background).detect(raw)
    reference = ReferencePipeline(ReferenceSettings()).detect(raw)
    ours = raw.points[fast.foreground]
    theirs_covered, ours_covered = agreement(ours, reference_foreground, match_m)
    on_road = [
        d for d in fast.detections if _near_road(np.array([d.center_xyz_m], dtype=np.float32))[0]
    ]
    summary: dict[str, Any] = {
        "returns": int(np.isfinite(raw.points[:, 0]).sum()),
        "fast": {
            "detections": len(fast.detections),
            "on_road": len(on_road),
            "foreground_points": int(fast.foreground.sum()),
            "ms": round(1e3 * sum(fast.timings_s.values()), 1),
        },
        "reference": {
            "detections": len(reference.detections),
            "foreground_points": int(reference.foreground.sum()),
            "ms": round(1e3 * sum(reference.timings_s.values()), 1),
        },
        "filtered_pcd_points_near_road": int(_near_road(reference_foreground).sum()),
        f"filtered_within_{match_m}m_of_fast_foreground": round(theirs_covered, 3),
        f"fast_foreground_within_{match_m}m_of_filtered": round(ours_covered, 3),
        "fast_detections_on_road": [
            {
                "x": round(d.center_xyz_m[0], 2),
                "y": round(d.center_xyz_m[1], 2),
                "length": round(d.size_lwh_m[0], 2),
                "width": round(d.size_lwh_m[1], 2),
                "class": d.object_class.value,
                "points": d.num_points,
            }
            for d in on_road
        ],
    }
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        image = top_view(raw.points, fast.foreground, reference_foreground, fast, reference)
        cv2.imwrite(str(out), image)
    return summary


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m wz_lidar_detector.real_frame")
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--out", type=Path, default=None, help="write the top view here (PNG)")
    args = parser.parse_args(argv)
    sys.stdout.write(json.dumps(run(args.data, args.out), indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
