"""``wz calibrate --pictures DIR``: before and after, for people (matplotlib, PNG).

- ``<lidar>-lanes.png``: the LiDAR's detections of the last minute and a half in the road
  frame (station from the sensor along the road, offset across it), placed with the site
  file's pose (above) and with the learned pose (below), the lanes' centres dashed and their
  edges solid. A sensor turned by a degree puts far vehicles off their lanes; learned, they
  sit on the centres. The titles give the median distance of a detection on the road (under
  either pose) to its nearest lane centre.
- ``<camera>-projection.png``: one camera frame with the LiDAR's vehicles (placed with the
  LiDAR's learned pose) drawn as 3D boxes, projected with the site file's camera pose at the
  frame's stamp (left) and with the learned pose at the learned clock's time (right); white:
  the camera detector's own boxes in that frame.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wz_cli.calibrate_views import CameraShot, LidarView, SensorResult
from wz_shared.arrays import F64, U8
from wz_shared.site import Pose, SensorMount, Site

#: Detections within this horizontal range of the LiDAR are drawn [m] (the lane fit's).
LANE_RANGE_M = (8.0, 150.0)
#: Detections this far beyond the outer lanes' edges count as on the road [m].
ROAD_MARGIN_M = 1.0
#: A LiDAR batch this far in time from a camera frame is not drawn on it [s].
MAX_GAP_S = 0.2
#: Box edges: pairs of corner indices (bottom 0-3, top 4-7).
EDGES = (
    (0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7),
)  # fmt: skip


@dataclass(frozen=True)
class LaneFigures:
    """How far the detections sit from their lanes' centres, before and after [m]."""

    #: Detections scored (on the road under either pose), and those off it (not scored).
    boxes: int
    off_road: int
    median_before_m: float
    median_after_m: float


def _agg() -> None:
    import matplotlib

    matplotlib.use("Agg")


def _to_lane(site: Site, offsets: F64) -> F64:
    lanes = np.array([lane.center_offset_m for lane in site.lanes], dtype=np.float64)
    gaps = np.abs(offsets[:, None] - lanes[None, :])
    return np.asarray(gaps.min(axis=1), dtype=np.float64)


def lanes_picture(
    site: Site, result: SensorResult, views: Sequence[LidarView], out: Path
) -> LaneFigures | None:
    """Draw ``<lidar>-lanes.png`` (module docstring); None when there is nothing to draw."""
    if not views:
        return None
    road = site.road_frame
    sensor_station, _ = road.to_road(result.nominal.x_m, result.nominal.y_m)
    lanes = site.lanes
    road_low = min(lane.center_offset_m - lane.width_m / 2 for lane in lanes) - ROAD_MARGIN_M
    road_high = max(lane.center_offset_m + lane.width_m / 2 for lane in lanes) + ROAD_MARGIN_M
    # The same detections in both panels: those within range of the sensor.
    near = np.concatenate([v.centres_site(result.nominal)[:, :2] for v in views])
    rel = np.hypot(near[:, 0] - result.nominal.x_m, near[:, 1] - result.nominal.y_m)
    chosen = (rel >= LANE_RANGE_M[0]) & (rel <= LANE_RANGE_M[1])
    if not chosen.any():
        return None
    panels = []
    for pose in (result.nominal, result.learned):
        xy = np.concatenate([v.centres_site(pose)[:, :2] for v in views])[chosen]
        stations, offsets = road.to_road(xy[:, 0], xy[:, 1])
        panels.append(
            (
                np.asarray(stations, dtype=np.float64).reshape(-1) - float(sensor_station),
                np.asarray(offsets, dtype=np.float64).reshape(-1),
            )
        )
    # Scored: the detections on the road under either pose (a drum, a sign or a false box
    # off the road is on no lane under any pose, and would only swamp the figure).
    on_road = np.zeros(len(panels[0][1]), dtype=bool)
    for _, offsets in panels:
        on_road |= (offsets >= road_low) & (offsets <= road_high)
    if not on_road.any():
        return None
    before = float(np.median(_to_lane(site, panels[0][1][on_road])))
    after = float(np.median(_to_lane(site, panels[1][1][on_road])))
    _agg()
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(2, 1, figsize=(12, 6.5), sharex=True)
    low = min(lane.center_offset_m - lane.width_m / 2 for lane in lanes) - 2.5
    high = max(lane.center_offset_m + lane.width_m / 2 for lane in lanes) + 2.5
    c = result.message.correction if result.message is not None else None
    titles = (
        f"site file's pose: median {before:.2f} m from a lane centre",
        f"learned pose ({result.state}"
        + (
            f": yaw {c.yaw_deg:+.2f} deg, pitch {c.pitch_deg:+.2f} deg, roll {c.roll_deg:+.2f} deg"
            if c is not None
            else ""
        )
        + f"): median {after:.2f} m",
    )
    for axis, (stations, offsets), title in zip(axes, panels, titles, strict=True):
        for lane in lanes:
            axis.axhline(lane.center_offset_m, color="tab:blue", linestyle="--", linewidth=1)
            for edge in (-0.5, 0.5):
                axis.axhline(
                    lane.center_offset_m + edge * lane.width_m, color="0.55", linewidth=0.8
                )
        axis.scatter(stations, offsets, s=4, color="tab:orange", alpha=0.6, linewidths=0)
        axis.set_ylim(low, high)
        axis.set_ylabel("offset across the road [m]")
        axis.set_title(title, fontsize=10)
        axis.grid(True, axis="x", color="0.9")
    axes[-1].set_xlabel(f"station along the road from the LiDAR {result.sensor_id} [m]")
    figure.suptitle(
        f"{result.sensor_id}: detections {LANE_RANGE_M[0]:g}-{LANE_RANGE_M[1]:g} m from it over "
        f"the last {views[-1].stamp_s - views[0].stamp_s:.0f} s: {int(on_road.sum())} on the "
        f"road, scored, {int((~on_road).sum())} off it (dashed: lane centres)",
        fontsize=11,
    )
    figure.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(out, dpi=110)
    plt.close(figure)
    return LaneFigures(int(on_road.sum()), int((~on_road).sum()), before, after)


def _nearest(views: Sequence[LidarView], stamp_s: float) -> LidarView | None:
    best = min(views, key=lambda v: abs(v.stamp_s - stamp_s), default=None)
    if best is None or abs(best.stamp_s - stamp_s) > MAX_GAP_S:
        return None
    return best


def box_corners(site: Site, view: LidarView, pose: Pose) -> F64:
    """The 8 corners (bottom, then top) of each box of ``view`` placed with ``pose``,
    shape (K, 8, 3); a box without a heading takes the road's."""
    centres = view.centres_site(pose)
    headings = view.headings + math.radians(pose.yaw_deg)
    missing = ~np.isfinite(headings)
    if missing.any():
        road = site.road_frame
        stations, _ = road.to_road(centres[missing, 0], centres[missing, 1])
        normal = np.asarray(road.normal_at(stations), dtype=np.float64).reshape(-1, 2)
        headings[missing] = np.arctan2(-normal[:, 0], normal[:, 1])
    length, width, height = view.sizes[:, 0], view.sizes[:, 1], view.sizes[:, 2]
    unit = np.array([[1, 1], [1, -1], [-1, -1], [-1, 1]], dtype=np.float64) * 0.5
    cos, sin = np.cos(headings), np.sin(headings)
    along = unit[None, :, 0] * length[:, None]
    across = unit[None, :, 1] * width[:, None]
    x = centres[:, None, 0] + along * cos[:, None] - across * sin[:, None]
    y = centres[:, None, 1] + along * sin[:, None] + across * cos[:, None]
    bottom_z = centres[:, 2] - 0.5 * height
    corners = np.zeros((len(centres), 8, 3))
    corners[:, :4, 0], corners[:, :4, 1], corners[:, :4, 2] = x, y, bottom_z[:, None]
    corners[:, 4:, 0], corners[:, 4:, 1] = x, y
    corners[:, 4:, 2] = (bottom_z + height)[:, None]
    return corners


def _projected(
    site: Site,
    mount: SensorMount,
    pose: Pose,
    size: tuple[int, int],
    view: LidarView | None,
    lidar_pose: Pose,
) -> list[F64]:
    """Each box's corners in pixels (8, 2), for the boxes wholly in front of the camera."""
    from wz_shared.camera_geometry import camera_at_size

    if view is None or not len(view.centres):
        return []
    camera = camera_at_size(mount.model_copy(update={"pose": pose}), size[0], size[1])
    corners = box_corners(site, view, lidar_pose)
    uv, depth = camera.project(corners.reshape(-1, 3))
    uv, depth = uv.reshape(-1, 8, 2), depth.reshape(-1, 8)
    return [uv[i] for i in range(len(uv)) if (depth[i] > 0.5).all()]


def _inside(boxes: list[F64], size: tuple[int, int]) -> int:
    return sum(
        1
        for uv in boxes
        if 0 <= float(uv[:, 0].mean()) < size[0] and 0 <= float(uv[:, 1].mean()) < size[1]
    )


def camera_picture(
    site: Site,
    camera: SensorResult,
    lidar: SensorResult,
    views: Sequence[LidarView],
    shots: Sequence[CameraShot],
    out: Path,
    detect: Callable[[U8], Sequence[Any]] | None = None,
) -> CameraShot | None:
    """Draw ``<camera>-projection.png`` (module docstring) on the kept frame that shows the
    most LiDAR vehicles; ``detect`` (an image backend's ``detect``) adds the camera's own
    boxes. None when no frame has a LiDAR batch near it."""
    import cv2

    mount = site.sensor(camera.sensor_id)
    message = camera.message
    clock_s = message.clock_offset_s if message is not None else 0.0
    lidar_pose = lidar.learned
    best: tuple[int, CameraShot, U8] | None = None
    for shot in shots:
        image = cv2.imdecode(np.frombuffer(shot.jpeg, np.uint8), cv2.IMREAD_COLOR)
        if image is None:
            continue
        size = (int(image.shape[1]), int(image.shape[0]))
        learned = _projected(
            site,
            mount,
            camera.learned,
            size,
            _nearest(views, shot.stamp_s - clock_s),
            lidar_pose,
        )
        count = _inside(learned, size)
        if count and (best is None or count >= best[0]):
            best = (count, shot, np.asarray(image, np.uint8))
    if best is None:
        return None
    _, shot, image = best
    size = (int(image.shape[1]), int(image.shape[0]))
    rgb = image[:, :, ::-1]
    own = []
    if detect is not None:
        try:
            own = [box.box_xyxy_px for box in detect(np.asarray(image, np.uint8))]
        except Exception:  # the picture goes on without the camera's boxes
            own = []
    _agg()
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(1, 2, figsize=(15, 7.8))
    c = message.correction if message is not None else None
    panels = (
        (
            mount.pose,
            shot.stamp_s,
            "tab:red",
            "site file's camera pose, at the frame's stamp",
        ),
        (
            camera.learned,
            shot.stamp_s - clock_s,
            "lime",
            f"learned ({camera.state}"
            + (
                f": yaw {c.yaw_deg:+.2f}, pitch {c.pitch_deg:+.2f}, roll {c.roll_deg:+.2f} deg, "
                f"clock {1000 * clock_s:+.0f} ms"
                if c is not None
                else ""
            )
            + ")",
        ),
    )
    for axis, (pose, at_s, colour, title) in zip(axes, panels, strict=True):
        axis.imshow(rgb)
        for x0, y0, x1, y1 in own:
            axis.plot([x0, x1, x1, x0, x0], [y0, y0, y1, y1, y0], color="white", linewidth=0.8)
        for uv in _projected(site, mount, pose, size, _nearest(views, at_s), lidar_pose):
            for a, b in EDGES:
                axis.plot([uv[a, 0], uv[b, 0]], [uv[a, 1], uv[b, 1]], color=colour, linewidth=1.0)
        axis.set_xlim(0, size[0])
        axis.set_ylim(size[1], 0)
        axis.set_title(title, fontsize=10)
        axis.axis("off")
    figure.suptitle(
        f"{camera.sensor_id}, frame stamped {shot.stamp_s:.2f} s: the LiDAR {lidar.sensor_id}'s "
        "vehicles (its learned pose) projected; white: the camera's own boxes",
        fontsize=11,
    )
    figure.tight_layout(rect=(0.0, 0.0, 1.0, 0.95))
    out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(out, dpi=100)
    plt.close(figure)
    return shot
