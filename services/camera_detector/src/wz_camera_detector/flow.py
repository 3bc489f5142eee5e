"""Boxes followed from one frame to the next by optical flow: the image tracker's measurement
on the frames the detector skips.

Median Flow (Kalal, Mikolajczyk and Matas, "Forward-Backward Error: Automatic Detection of
Tracking Failures", ICPR 2010): a grid of points inside each box is followed by pyramidal
Lucas-Kanade (OpenCV's ``calcOpticalFlowPyrLK``) into the new frame and back again; a point
that does not come back to where it started (forward-backward error above
``max_fb_error_px``) is unreliable; a box with fewer than ``min_points_kept`` of its points
inside the frame reliable is lost (occluded, blurred, or left the frame: the tracker coasts
it). Of the reliable points, the better half (forward-backward error at most their median)
moves the box: by their median displacement, scaled by the median ratio of their pairwise
distances. Each box is followed at the level of the frames' pyramid where it is about
``box_height_px`` tall (a near truck's flat side has no texture at full resolution).

Cost: about 20 us per point on one core of the edge box (both directions, 1200 x 1200
grey frames); a 3 x 3 grid on ten vehicles is about 2 ms. The frames are grey (the node
decodes the JPEG's luma only on frames it does not detect on: a third of a colour decode).

Pixel coordinates are :mod:`wz_camera_detector.yolo`'s: ``u`` right, ``v`` down, boxes
``(x1, y1, x2, y2)`` by their pixel edges [px].
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, ConfigDict, Field

from wz_shared.arrays import F32, F64, U8

#: The box's edges are left out of its point grid by this share of its width and height on
#: each side: a point on the box's edge lies on the background as often as on the vehicle.
GRID_INSET = 0.2
#: LK stops after this many iterations or when a step moves less than this [px].
LK_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 0.03)
#: A corner weaker than this share of the box's strongest is not followed.
CORNER_QUALITY = 0.05
#: The coarsest level a box is followed at (a 16th of the frame's size).
MAX_BOX_LEVEL = 4


def _window(
    boxes: F64, guess: F64, reach_px: float, shape: tuple[int, ...]
) -> tuple[int, int, int, int]:
    """The part ``(x0, y0, x1, y1)`` [px] of an image of ``shape`` that holds the boxes
    (shape (N, 4)) where they are and where ``guess`` (shape (N, 2)) moves them, with
    ``reach_px`` round them."""
    moved = boxes + np.hstack([guess, guess])
    x0 = int(max(0.0, math.floor(min(boxes[:, 0].min(), moved[:, 0].min()) - reach_px)))
    y0 = int(max(0.0, math.floor(min(boxes[:, 1].min(), moved[:, 1].min()) - reach_px)))
    x1 = int(min(shape[1], math.ceil(max(boxes[:, 2].max(), moved[:, 2].max()) + reach_px)))
    y1 = int(min(shape[0], math.ceil(max(boxes[:, 3].max(), moved[:, 3].max()) + reach_px)))
    return x0, y0, max(x1, x0 + 1), max(y1, y0 + 1)


def _level(pyramid: list[U8], level: int) -> U8:
    """Level ``level`` of a frame's pyramid (``pyramid[0]`` the frame), made as needed
    (``cv2.pyrDown``: Gaussian, half the size) and kept in ``pyramid``."""
    while len(pyramid) <= level:
        pyramid.append(np.asarray(cv2.pyrDown(pyramid[-1]), dtype=np.uint8))
    return pyramid[level]


class FlowSettings(BaseModel):
    """Parameters of :class:`BoxFlow`."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    #: Follow boxes between detections; False: tracks coast on their filter between them (and
    #: the detector had better run on every frame: ``detection_period_s`` 0).
    enabled: bool = True
    #: Points per side of the grid laid in each box (``n x n`` points).
    grid_points: int = Field(default=3, ge=2, le=10)
    #: Side of LK's search window [px] at each pyramid level.
    window_px: int = Field(default=15, ge=5, le=51)
    #: LK's pyramid levels above the level a box is followed at (each halves it):
    #: ``window * 2**levels / 2`` is about the largest motion followed there (15 px, 2 levels:
    #: 30 px, that is, a box's own height or more between two frames).
    pyramid_levels: int = Field(default=2, ge=0, le=6)
    #: A point whose forward-backward error exceeds this is dropped [px].
    max_fb_error_px: float = Field(default=1.0, gt=0.0)
    #: Share of a box's points inside the frame that must be reliable, else it is lost [0-1].
    min_points_kept: float = Field(default=0.5, gt=0.0, le=1.0)
    #: A box is followed at the pyramid level where it is about this tall [px] (or smaller).
    box_height_px: float = Field(default=24.0, gt=8.0)
    #: A box smaller than this at its level [px] keeps its size (flow moves it only): the
    #: distances between a few points a few pixels apart do not measure its scale (a far
    #: car's box 15 px tall would be ranged metres off by a 5 % error in its size).
    min_scaled_height_px: float = Field(default=24.0, ge=0.0)
    #: A box scaling by more than this factor (or less than its inverse) in one frame is
    #: lost: a vehicle at 30 fps does not, a point cloud split between two vehicles does.
    max_scale_step: float = Field(default=1.25, gt=1.0)


class BoxFlow:
    """Follows boxes from the previous grey frame to the new one (Median Flow).

    Call :meth:`follow` with each frame in turn (grey, the same size, the same region of the
    picture); the first call and the first after :meth:`restart` or a change of size only keep
    the frame.
    """

    def __init__(self, settings: FlowSettings) -> None:
        self.settings = settings
        #: The previous frame and the pyramid levels made of it so far (each half the last).
        self._previous: list[U8] | None = None
        self._origin: tuple[int, int] = (0, 0)
        grid = np.linspace(GRID_INSET, 1.0 - GRID_INSET, settings.grid_points)
        #: Grid points as shares of a box's width and height, shape (n*n, 2).
        self._grid = np.array([(gx, gy) for gy in grid for gx in grid], dtype=np.float64)
        #: Index pairs of the grid's points for the scale's distance ratios.
        first, second = np.triu_indices(len(self._grid), k=1)
        self._pairs = (first, second)

    def restart(self) -> None:
        """Forget the previous frame (a new run, another picture)."""
        self._previous = None

    def follow(
        self,
        gray: U8,
        boxes_xyxy_px: npt.ArrayLike,
        guess_shift_px: npt.ArrayLike | None = None,
        origin_px: tuple[int, int] = (0, 0),
    ) -> F64:
        """Where each box of the previous frame is in ``gray``.

        Parameters
        ----------
        gray
            The new frame, grey, shape (H, W), uint8; with ``origin_px`` a crop of the frame
            whose top left corner is there [px].
        boxes_xyxy_px
            The boxes in the previous frame, shape (N, 4) [px of the whole frame].
        guess_shift_px
            Each box's expected shift ``(du, dv)`` [px], shape (N, 2) (the tracker's velocity
            times the frames' interval): LK starts from it, so a fast near vehicle is not
            searched for at its old place. None: no guess.
        origin_px
            The crop's top left corner in the whole frame [px].

        Returns
        -------
        boxes
            Shape (N, 4) [px of the whole frame]; a row of NaN for a box that was lost, or
            for every box on the first frame (nothing to follow from).
        """
        boxes = np.asarray(boxes_xyxy_px, dtype=np.float64).reshape(-1, 4)
        followed = np.full_like(boxes, np.nan)
        previous, self._previous = self._previous, [gray]
        same_picture = (
            previous is not None and previous[0].shape == gray.shape and self._origin == origin_px
        )
        self._origin = origin_px
        if not same_picture or len(boxes) == 0:
            return followed
        assert previous is not None
        local = boxes - np.array([*origin_px, *origin_px], dtype=np.float64)
        guess = (
            np.zeros((len(boxes), 2))
            if guess_shift_px is None
            else np.asarray(guess_shift_px, dtype=np.float64).reshape(-1, 2)
        )
        # Each box is followed at the level of the frames' pyramid where it is about
        # box_height_px tall: LK's window then spans a good part of it, its edges and windows
        # included (a grid point in the middle of a near truck's flat side has no texture to
        # lock on at full resolution).
        heights = np.maximum(local[:, 3] - local[:, 1], 1.0)
        levels = np.clip(
            np.floor(np.log2(heights / self.settings.box_height_px)), 0, MAX_BOX_LEVEL
        ).astype(int)
        for level in np.unique(levels):
            chosen = np.flatnonzero(levels == level)
            scale = 2.0**level
            boxes_at, guess_at = local[chosen] / scale, guess[chosen] / scale
            before, after = _level(previous, int(level)), _level(self._previous, int(level))
            # Only the part of the images round these boxes (LK builds its pyramids of what it
            # is given, every call): the boxes, where the guesses move them, and the search's
            # reach at LK's coarsest level.
            reach = self.settings.window_px * 2.0**self.settings.pyramid_levels
            x0, y0, x1, y1 = _window(boxes_at, guess_at, reach, after.shape)
            moved = self._follow_at(
                before[y0:y1, x0:x1],
                after[y0:y1, x0:x1],
                boxes_at - np.array([x0, y0, x0, y0], dtype=np.float64),
                guess_at,
            )
            shift = np.array([x0, y0, x0, y0], dtype=np.float64)
            followed[chosen] = (moved + shift) * scale + np.array(
                [*origin_px, *origin_px], dtype=np.float64
            )
        return followed

    def _follow_at(self, previous: U8, gray: U8, boxes: F64, guess: F64) -> F64:
        """:meth:`follow` for boxes in one pair of images (one pyramid level) [its px]."""
        followed = np.full_like(boxes, np.nan)
        # (N, n*n, 2): each box's points in the image's pixels (pixel centres at +0.5), NaN
        # where it has fewer.
        points = np.stack([self._points(previous, box) for box in boxes])
        height_px, width_px = gray.shape[:2]
        inside = (
            np.isfinite(points[..., 0])
            & (points[..., 0] >= 0.0)
            & (points[..., 0] < width_px)
            & (points[..., 1] >= 0.0)
            & (points[..., 1] < height_px)
        )
        if not inside.any():
            return followed
        start: F32 = (points[inside] - 0.5).astype(np.float32).reshape(-1, 1, 2)
        shifts = np.broadcast_to(guess[:, None, :], points.shape)[inside]
        initial: F32 = (start + shifts.astype(np.float32).reshape(-1, 1, 2)).astype(np.float32)
        settings = self.settings
        window = (settings.window_px, settings.window_px)
        forward, status_f, _ = cv2.calcOpticalFlowPyrLK(
            previous,
            gray,
            start,
            initial,
            winSize=window,
            maxLevel=settings.pyramid_levels,
            criteria=LK_CRITERIA,
            flags=cv2.OPTFLOW_USE_INITIAL_FLOW,
        )
        backward, status_b, _ = cv2.calcOpticalFlowPyrLK(
            gray,
            previous,
            forward,
            start.copy(),
            winSize=window,
            maxLevel=settings.pyramid_levels,
            criteria=LK_CRITERIA,
            flags=cv2.OPTFLOW_USE_INITIAL_FLOW,
        )
        fb_error = np.linalg.norm((backward - start).reshape(-1, 2), axis=1)
        ok = (status_f.ravel() == 1) & (status_b.ravel() == 1) & np.isfinite(fb_error)
        moved = np.full(points.shape, np.nan)
        moved[inside] = forward.reshape(-1, 2).astype(np.float64) + 0.5
        error = np.full(inside.shape, np.inf)
        error[inside] = np.where(ok, fb_error, np.inf)
        for index, box in enumerate(boxes):
            new_box = self._box(
                box, points[index], moved[index], error[index], int(inside[index].sum())
            )
            if new_box is not None:
                followed[index] = new_box
        return followed

    def _points(self, image: U8, box: F64) -> F64:
        """A box's points to follow, shape (n*n, 2) [px], NaN rows where fewer: the
        strongest corners inside it (Shi-Tomasi, ``cv2.goodFeaturesToTrack``: a rendered or
        a plain-painted vehicle has texture at its edges and windows only), or its grid
        when it has fewer than three."""
        count = len(self._grid)
        points = np.full((count, 2), np.nan)
        width, height = box[2] - box[0], box[3] - box[1]
        x0 = max(0, math.floor(box[0] + GRID_INSET / 2.0 * width))
        y0 = max(0, math.floor(box[1] + GRID_INSET / 2.0 * height))
        x1 = min(image.shape[1], math.ceil(box[2] - GRID_INSET / 2.0 * width))
        y1 = min(image.shape[0], math.ceil(box[3] - GRID_INSET / 2.0 * height))
        corners = None
        if x1 - x0 >= 5 and y1 - y0 >= 5:
            corners = cv2.goodFeaturesToTrack(
                image[y0:y1, x0:x1],
                maxCorners=count,
                qualityLevel=CORNER_QUALITY,
                minDistance=max(2.0, min(x1 - x0, y1 - y0) / (self.settings.grid_points + 1)),
                blockSize=3,
            )
        if corners is not None and len(corners) >= 3:
            found = corners.reshape(-1, 2).astype(np.float64) + np.array([x0 + 0.5, y0 + 0.5])
            points[: len(found)] = found
            return points
        points[:] = np.column_stack(
            [box[0] + self._grid[:, 0] * width, box[1] + self._grid[:, 1] * height]
        )
        return points

    def _box(self, box: F64, before: F64, after: F64, fb_error: F64, n_inside: int) -> F64 | None:
        """The box's new place from its points (Median Flow's rule), None when lost.

        ``n_inside``: the box's points inside the frame (a vehicle leaving the frame has only
        its visible part followed).
        """
        settings = self.settings
        reliable = np.isfinite(fb_error) & (fb_error <= settings.max_fb_error_px)
        if reliable.sum() < max(3, math.ceil(settings.min_points_kept * n_inside)):
            return None
        # Of those, the better half estimates the motion (Median Flow's rule).
        kept = reliable & (fb_error <= float(np.median(fb_error[reliable])))
        first, second = self._pairs
        both = kept[first] & kept[second]
        distance_before = np.linalg.norm(before[first[both]] - before[second[both]], axis=1)
        distance_after = np.linalg.norm(after[first[both]] - after[second[both]], axis=1)
        usable = distance_before > 1.0
        scale = (
            float(np.median(distance_after[usable] / distance_before[usable]))
            if usable.any() and box[3] - box[1] >= settings.min_scaled_height_px
            else 1.0
        )
        if not (1.0 / settings.max_scale_step <= scale <= settings.max_scale_step):
            return None
        # Scale the box's sides about its centre and move the centre by what the points moved
        # beyond the scaling (points off the centre move apart as a near vehicle grows).
        centre = np.array([box[0] + box[2], box[1] + box[3]]) / 2.0
        centre = centre + np.median(
            after[kept] - (centre + scale * (before[kept] - centre)), axis=0
        )
        half_w, half_h = scale * (box[2] - box[0]) / 2.0, scale * (box[3] - box[1]) / 2.0
        return np.array(
            [centre[0] - half_w, centre[1] - half_h, centre[0] + half_w, centre[1] + half_h]
        )
