"""Where the detector looks: the region of interest and far-field tiles from the road's geometry.

A mast camera sees sky, verge and the road beyond the mast; the vehicles that matter are on the
approach. :func:`detector_regions` projects the road the site file describes into the camera's
image and returns, for any resolution, field of view and aim:

- the **region of interest** (ROI): the bounding box of the carriageway (every lane, a margin
  for vehicles straddling its edges) from the ground up to a truck's roof, within
  ``max_range_m`` of the camera and in front of it. The detector crops it and letterboxes it to
  the model's input, so nothing outside the road costs time or gives false boxes;
- **far-field tiles**: where the letterbox shrinks a distant car below ``min_car_px`` pixels of
  the model's input, the part of the road beyond that range is cut out once more as a tile and
  letterboxed on its own, magnified, so that those cars reach sizes the model finds reliably.
  The range follows from the camera: a car ``h`` metres high at range ``r`` spans
  ``f h / r`` pixels of the frame (``f`` the focal length), times the letterbox's scale.

Everything comes from the mount (pose, resolution, field of view) and the road frame; nothing
is a pixel of one camera. No camera stands exactly at its site file's pose: with
``margin_deg`` the regions hold the road for every aim within that many degrees of yaw and
pitch of the pose given (the union of its projections), so a vehicle at the far end is not cut
by a region drawn for a pose the camera does not have. The detector gives the set-up
tolerance until the camera's pose is learned, then what is left of it (the node).
``--roi`` / ``--tiles`` (or the settings) override it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wz_shared.arrays import F64
from wz_shared.camera_geometry import PinholeCamera, camera_at_size, camera_intrinsics
from wz_shared.site import SensorMount, Site

Box = tuple[int, int, int, int]

#: Height of the tallest vehicle the ROI must hold whole: a tractor-trailer's 4.1 m (13.5 ft,
#: the usual US legal height), rounded up.
VEHICLE_TOP_M = 4.2
#: Height of a car [m], for the apparent-size rule of the tiles.
CAR_HEIGHT_M = 1.5
#: Carriageway margin each side [m]: half a vehicle straddling an edge line, mirrors included.
EDGE_MARGIN_M = 1.5
#: Station step of the sampled road outline [m].
STEP_M = 2.0
#: A ROI side this close to the frame's edge (share of the frame) goes to the edge: the road
#: leaves the frame there, between two of its samples.
SNAP_SHARE = 0.05


@dataclass(frozen=True)
class DetectorRegions:
    """The ROI and far-field tiles of one camera, in pixels of its frame."""

    roi_xyxy_px: Box | None
    tiles_xyxy_px: tuple[Box, ...]
    #: Range [m] beyond which a car is smaller than ``min_car_px`` in the letterboxed ROI (the
    #: tile's near end), None without a tile.
    tile_from_m: float | None = None


def _road_points(site: Site, camera: PinholeCamera, max_range_m: float) -> tuple[F64, F64]:
    """Road outline points in front of the camera, shape (N, 3), with their ground range [m]."""
    lanes = sorted(site.lanes, key=lambda lane: lane.index)
    right = lanes[0].center_offset_m - lanes[0].width_m / 2.0 - EDGE_MARGIN_M
    left = lanes[-1].center_offset_m + lanes[-1].width_m / 2.0 + EDGE_MARGIN_M
    stations = np.arange(0.0, site.road_length_m, STEP_M)
    offsets = np.linspace(right, left, 5)
    s_grid, d_grid = np.meshgrid(stations, offsets, indexing="ij")
    x, y = site.road_frame.to_site(s_grid.ravel(), d_grid.ravel())
    ground_range = np.hypot(x - camera.position_m[0], y - camera.position_m[1])
    near = ground_range <= max_range_m
    x, y, ground_range = x[near], y[near], ground_range[near]
    points = np.concatenate(
        [
            np.column_stack([x, y, np.zeros_like(x)]),
            np.column_stack([x, y, np.full_like(x, VEHICLE_TOP_M)]),
        ]
    )
    return points, np.concatenate([ground_range, ground_range])


def _bounds(uv: F64, width_px: int, height_px: int, *, snap: bool = False) -> Box | None:
    """Bounding box of pixel points clipped to the frame, None if none falls inside.

    With ``snap``, a side within :data:`SNAP_SHARE` of the frame's edge, where the sampled road
    leaves the frame between two samples, is moved onto the edge.
    """
    inside = (uv[:, 0] >= 0) & (uv[:, 0] <= width_px) & (uv[:, 1] >= 0) & (uv[:, 1] <= height_px)
    if not inside.any():
        return None
    u, v = uv[inside, 0], uv[inside, 1]
    x0, y0 = math.floor(u.min()), math.floor(v.min())
    x1, y1 = math.ceil(u.max()), math.ceil(v.max())
    if snap:
        x0 = 0 if x0 < SNAP_SHARE * width_px else x0
        y0 = 0 if y0 < SNAP_SHARE * height_px else y0
        x1 = width_px if x1 > (1.0 - SNAP_SHARE) * width_px else x1
        y1 = height_px if y1 > (1.0 - SNAP_SHARE) * height_px else y1
    return max(0, x0), max(0, y0), min(width_px, x1), min(height_px, y1)


def _projected(camera: PinholeCamera, points: F64) -> tuple[F64, np.ndarray]:
    uv, depth = camera.project(points)
    visible = (depth > 0.5) & np.isfinite(uv).all(axis=1)
    return uv, visible


def _turned(mount: SensorMount, margin_deg: tuple[float, float]) -> list[SensorMount]:
    """``mount`` turned by the margin's yaw and pitch, each way, alone and together."""
    yaw, pitch = margin_deg
    if not (math.isfinite(yaw) and math.isfinite(pitch)) or yaw < 0.0 or pitch < 0.0:
        raise ValueError(f"margin_deg must be finite and non-negative, got {margin_deg}")
    pose = mount.pose
    turns = {
        (dy, dp) for dy in (-yaw, 0.0, yaw) for dp in (-pitch, 0.0, pitch) if (dy, dp) != (0.0, 0.0)
    }
    return [
        mount.model_copy(
            update={
                "pose": pose.model_copy(
                    update={"yaw_deg": pose.yaw_deg + dy, "pitch_deg": pose.pitch_deg + dp}
                )
            }
        )
        for dy, dp in sorted(turns)
    ]


def _clip_square(box: Box, width_px: int, height_px: int, min_side_px: int) -> Box:
    """Grow ``box`` about its centre to at least ``min_side_px`` each way, inside the frame."""
    x0, y0, x1, y1 = box
    grow_w = max(0, min_side_px - (x1 - x0))
    grow_h = max(0, min_side_px - (y1 - y0))
    x0, x1 = x0 - grow_w // 2, x1 + grow_w - grow_w // 2
    y0, y1 = y0 - grow_h // 2, y1 + grow_h - grow_h // 2
    # Shift back inside the frame, then clip.
    shift_x = max(0, -x0) - max(0, x1 - width_px)
    shift_y = max(0, -y0) - max(0, y1 - height_px)
    x0, x1, y0, y1 = x0 + shift_x, x1 + shift_x, y0 + shift_y, y1 + shift_y
    return max(0, x0), max(0, y0), min(width_px, x1), min(height_px, y1)


def detector_regions(
    site: Site,
    mount: SensorMount,
    input_size_px: int,
    *,
    width_px: int | None = None,
    height_px: int | None = None,
    max_range_m: float = 200.0,
    min_car_px: float = 16.0,
    max_magnification: float = 4.0,
    margin_deg: tuple[float, float] = (0.0, 0.0),
) -> DetectorRegions:
    """The ROI and far-field tiles of ``mount`` at ``site`` (module docstring).

    Parameters
    ----------
    site, mount
        The site and its camera (pose, resolution, field of view).
    input_size_px
        The model's (square) input side [px]: the ROI and each tile are letterboxed to it.
    width_px, height_px
        The frames' size when it differs from the site file's: the same picture, scaled
        (:func:`~wz_shared.camera_geometry.camera_at_size`; another aspect ratio is refused).
    max_range_m
        Road farther than this from the camera (on the ground) is not looked at [m].
    min_car_px
        A car smaller than this in the model's input [px] gets a far-field tile.
    max_magnification
        A tile is never magnified more than this (a tile of at least ``input / this`` pixels):
        beyond it, the frame's own pixels are the limit.
    margin_deg
        (yaw, pitch) [deg]: the regions hold the road for the mount's pose turned by up to
        this much either way (each alone and both together).

    Returns
    -------
    DetectorRegions
        ``roi_xyxy_px`` None when the road is not in view at all (the detector then looks at
        the whole frame and says so).
    """
    intrinsics = camera_intrinsics(mount)
    width = width_px or intrinsics.width_px
    height = height_px or intrinsics.height_px
    camera = camera_at_size(mount, width, height)
    points, ranges = _road_points(site, camera, max_range_m)
    uv, visible = _projected(camera, points)
    if margin_deg != (0.0, 0.0):
        views = [(uv, visible)] + [
            _projected(camera_at_size(turned, width, height), points)
            for turned in _turned(mount, margin_deg)
        ]
        uv = np.concatenate([view[0] for view in views])
        visible = np.concatenate([view[1] for view in views])
        ranges = np.tile(ranges, len(views))
    roi = _bounds(uv[visible], width, height, snap=True)
    if roi is None:
        return DetectorRegions(None, ())
    scale = input_size_px / max(roi[2] - roi[0], roi[3] - roi[1])
    # A car of CAR_HEIGHT_M at range r spans f * h / r px of the frame, scale times that in
    # the model's input: below min_car_px beyond r_tile.
    tile_from_m = camera.focal_px * CAR_HEIGHT_M * scale / min_car_px
    far = visible & (ranges >= tile_from_m)
    if tile_from_m >= max_range_m or not far.any():
        return DetectorRegions(roi, ())
    tile = _bounds(uv[far], width, height)
    if tile is None:
        return DetectorRegions(roi, ())
    tile = _clip_square(tile, width, height, math.ceil(input_size_px / max_magnification))
    return DetectorRegions(roi, (tile,), round(tile_from_m, 1))
