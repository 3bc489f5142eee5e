"""Background-subtraction vehicle detector: the second camera backend, for a fixed camera.

A mast camera does not move, so whatever differs from a learned model of the empty road is a
candidate vehicle. Each frame goes through four steps:

1. **Subtract**: OpenCV's MOG2 (``cv2.createBackgroundSubtractorMOG2``, Zivkovic 2004/2006), a
   per-pixel mixture of Gaussians updated with a learning rate ``alpha``; a pixel is foreground
   when its squared Mahalanobis distance to every background component exceeds
   ``foreground_threshold_sigma ** 2``. With shadow detection on, a pixel darker than the
   background by a ratio in ``[shadow_threshold_ratio, 1]`` at the same chromaticity is marked
   127 (shadow) and, by default, counted as background: a car's cast shadow would otherwise
   widen its box across the lane.
2. **Clean**: morphological opening (drops speckle from sensor noise and rain streaks), then
   closing (fills windows and dark tyres that happen to match the road), then the optional
   region-of-interest polygon (the road) masks everything else.
3. **Group**: 8-connected components (``cv2.connectedComponentsWithStats``); blobs smaller than
   ``min_blob_area_px`` or longer than ``max_aspect_ratio`` (lane-marking flicker, poles
   swaying) are dropped.
4. **Box and score**: each blob's bounding box in pixel edges, score
   ``solidity * (1 - exp(-area / score_area_scale_px))``: compact, large blobs score near 1,
   ragged or tiny ones near 0.

Why MOG2 and not a running median: the median needs the last ``N`` frames in memory
(``N x H x W x 3`` bytes, 216 MB for 50 frames at 1200 x 1200) and a per-pixel sort every frame,
and it has no notion of noise level, so its threshold must be tuned per weather; MOG2 keeps a
few Gaussians per pixel, learns each pixel's variance (rain, dusk noise), adapts to slow light
changes through its learning rate, and labels shadows, all in optimised C++.

The detector cannot classify: every detection is ``class_name = "vehicle"``, and the node
labels its output with :data:`BACKEND` so a consumer knows which backend produced it. Boxes use
the same continuous pixel coordinates as :mod:`wz_camera_detector.yolo`: the image spans
``[0, W] x [0, H]``, and pixel (row ``i``, column ``j``) covers ``[j, j + 1) x [i, i + 1)``.

The core is pure: it takes frames as numpy arrays and returns values; no bus, no files.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import cv2
import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

from wz_camera_detector.yolo import ImageDetection
from wz_shared.arrays import U8

#: Name of this backend, carried in the node's output next to its detections.
BACKEND = "background-subtraction"

#: The only class this backend reports: it sees moving blobs, not what they are.
VEHICLE_CLASS_NAME = "vehicle"

#: MOG2's mask values: 255 foreground, 127 shadow, 0 background.
_MOG2_FOREGROUND = 255
_MOG2_SHADOW = 127


class BackgroundSubtractionSettings(BaseModel):
    """Parameters of :class:`BackgroundSubtractionDetector` (pixels of the camera's frame).

    The pixel defaults suit the mast camera's native 1200 x 1200 frame; scale areas by the
    square of the resolution ratio for smaller frames.
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    #: Frames the background model remembers (MOG2's ``history``): a vehicle parked for longer
    #: than about this fades into the background [frames].
    history_frames: int = Field(default=500, ge=1)
    #: Weight of each new frame in the background model once warmed up [1/frame]; None:
    #: ``1 / history_frames``. A stopped vehicle becomes background after roughly
    #: ``0.1 / learning_rate_per_frame`` frames (MOG2's background ratio is 0.9). During the
    #: warm-up MOG2's own rate ``1 / min(2 n, history_frames)`` after ``n`` frames applies, so
    #: an empty model learns the road in a few frames.
    learning_rate_per_frame: float | None = Field(default=None, ge=0.0, le=1.0)
    #: A pixel is foreground beyond this many standard deviations from every background
    #: component (MOG2's ``varThreshold`` is its square) [sigma].
    foreground_threshold_sigma: float = Field(default=4.0, gt=0.0)
    #: Detect cast shadows (darker, same chromaticity) and keep them out of the boxes.
    detect_shadows: bool = True
    #: Count shadow pixels as foreground (only with ``detect_shadows``; default: background).
    shadows_as_foreground: bool = False
    #: A pixel is a shadow when its brightness over the background's lies in
    #: ``[shadow_threshold_ratio, 1]`` (MOG2's ``tau``) [-].
    shadow_threshold_ratio: float = Field(default=0.5, gt=0.0, lt=1.0)
    #: Side of the square opening kernel (removes specks smaller than it); 0: no opening [px].
    open_kernel_px: int = Field(default=3, ge=0)
    #: Side of the square closing kernel (fills gaps narrower than it); 0: no closing [px].
    close_kernel_px: int = Field(default=7, ge=0)
    #: Blobs with fewer pixels are dropped [px].
    min_blob_area_px: int = Field(default=150, ge=1)
    #: Blobs whose box is longer than this times its width, either way, are dropped [-].
    max_aspect_ratio: float = Field(default=6.0, ge=1.0)
    #: Area at which a solid blob scores ``1 - 1/e`` (0.63) [px].
    score_area_scale_px: float = Field(default=1500.0, gt=0.0)
    #: Only pixels inside this polygon ``((u, v), ...)`` are searched (e.g. the road); None:
    #: the whole frame [px, continuous coordinates].
    roi_polygon_px: tuple[tuple[float, float], ...] | None = None
    #: Frames learned before the first detection (the model is empty at start) [frames].
    warm_up_frames: int = Field(default=15, ge=0)

    @field_validator("roi_polygon_px")
    @classmethod
    def _polygon_has_an_area(
        cls, polygon: tuple[tuple[float, float], ...] | None
    ) -> tuple[tuple[float, float], ...] | None:
        if polygon is not None and len(polygon) < 3:
            raise ValueError(
                f"roi_polygon_px needs at least 3 vertices (u, v) to enclose an area, got "
                f"{len(polygon)}; leave it unset to search the whole frame"
            )
        return polygon


@dataclass(frozen=True, slots=True)
class BackgroundTimings:
    """Wall-clock time of each step of one :meth:`BackgroundSubtractionDetector.detect` [s]."""

    subtract_s: float
    morphology_s: float
    components_s: float

    @property
    def total_s(self) -> float:
        """Sum of the three steps [s]."""
        return self.subtract_s + self.morphology_s + self.components_s


def _square_kernel(side_px: int) -> U8 | None:
    return None if side_px <= 1 else np.ones((side_px, side_px), dtype=np.uint8)


class BackgroundSubtractionDetector:
    """Finds moving vehicles in a fixed camera's frames against a learned background.

    The detector is stateful: feed it every frame of one camera, in order. The first frame
    fixes the expected size; :meth:`reset` forgets the background (e.g. after the camera was
    moved).

    Parameters
    ----------
    settings
        Thresholds, morphology and warm-up.
    """

    def __init__(self, settings: BackgroundSubtractionSettings) -> None:
        self.settings = settings
        self._open_kernel = _square_kernel(settings.open_kernel_px)
        self._close_kernel = _square_kernel(settings.close_kernel_px)
        self._learning_rate = (
            1.0 / settings.history_frames
            if settings.learning_rate_per_frame is None
            else settings.learning_rate_per_frame
        )
        self.reset()

    def reset(self) -> None:
        """Forget the background, the frame size and the warm-up count."""
        settings = self.settings
        self._subtractor = cv2.createBackgroundSubtractorMOG2(
            history=settings.history_frames,
            varThreshold=settings.foreground_threshold_sigma**2,
            detectShadows=settings.detect_shadows,
        )
        self._subtractor.setShadowValue(_MOG2_SHADOW)
        self._subtractor.setShadowThreshold(settings.shadow_threshold_ratio)
        self._frame_shape: tuple[int, int] | None = None
        self._roi_mask: U8 | None = None
        self._frames_seen = 0

    @property
    def frames_seen(self) -> int:
        """Frames learned since construction or the last :meth:`reset`."""
        return self._frames_seen

    @property
    def warmed_up(self) -> bool:
        """Whether the next frame can produce detections."""
        return self._frames_seen >= self.settings.warm_up_frames

    def _check_frame(self, image_bgr: U8) -> None:
        if image_bgr.ndim != 3 or image_bgr.shape[2] != 3 or image_bgr.dtype != np.uint8:
            raise ValueError(
                f"expected a BGR uint8 frame of shape (H, W, 3), got {image_bgr.dtype} of shape "
                f"{image_bgr.shape}; convert grayscale or other formats before detection"
            )
        height, width = int(image_bgr.shape[0]), int(image_bgr.shape[1])
        if self._frame_shape is None:
            self._frame_shape = (height, width)
            self._roi_mask = self._build_roi_mask(height, width)
        elif self._frame_shape != (height, width):
            raise ValueError(
                f"frame is {width} x {height} px but the background was learned on "
                f"{self._frame_shape[1]} x {self._frame_shape[0]} px: a background-subtraction "
                "detector serves one fixed camera; reset() it if the camera changed"
            )

    def _build_roi_mask(self, height: int, width: int) -> U8 | None:
        polygon = self.settings.roi_polygon_px
        if polygon is None:
            return None
        mask = np.zeros((height, width), dtype=np.uint8)
        # Continuous (u, v) to pixel indices: the pixel whose centre is (j + 0.5, i + 0.5).
        vertices = np.round(np.asarray(polygon, dtype=np.float64) - 0.5).astype(np.int32)
        cv2.fillPoly(mask, [vertices.reshape(-1, 1, 2)], 255)
        return mask

    def detect(self, image_bgr: U8) -> list[ImageDetection]:
        """Learn from one frame and return the vehicles moving in it.

        Parameters
        ----------
        image_bgr
            Frame, shape (H, W, 3), uint8, BGR; the same size as every earlier frame.

        Returns
        -------
        list of ImageDetection
            By decreasing score, class ``"vehicle"``, boxes in the frame's pixels; empty during
            the warm-up.

        Raises
        ------
        ValueError
            The frame is not BGR uint8 (H, W, 3), or its size differs from the first frame's.
        """
        return self.detect_with_timings(image_bgr)[0]

    def detect_with_timings(self, image_bgr: U8) -> tuple[list[ImageDetection], BackgroundTimings]:
        """:meth:`detect`, plus how long each step took.

        Parameters
        ----------
        image_bgr
            Frame, shape (H, W, 3), uint8, BGR.

        Returns
        -------
        detections
            By decreasing score; empty during the warm-up.
        timings
            Background update and subtraction, morphology, components and boxes [s].
        """
        self._check_frame(image_bgr)
        start = time.perf_counter()
        # MOG2's automatic rate (-1) while warming up: a fixed small rate would take
        # hundreds of frames to learn the road from an empty model.
        learning_rate = -1.0 if not self.warmed_up else self._learning_rate
        raw_mask = self._subtractor.apply(image_bgr, learningRate=learning_rate)
        self._frames_seen += 1
        subtracted = time.perf_counter()
        if self._frames_seen <= self.settings.warm_up_frames:
            return [], BackgroundTimings(subtracted - start, 0.0, 0.0)

        threshold = _MOG2_SHADOW - 1 if self.settings.shadows_as_foreground else _MOG2_SHADOW
        foreground: U8 = np.where(raw_mask > threshold, np.uint8(255), np.uint8(0))
        foreground = self._clean(foreground)
        cleaned = time.perf_counter()
        detections = self._blobs_to_detections(foreground)
        done = time.perf_counter()
        return detections, BackgroundTimings(
            subtract_s=subtracted - start,
            morphology_s=cleaned - subtracted,
            components_s=done - cleaned,
        )

    def _clean(self, foreground: U8) -> U8:
        """Opening, closing, then the region of interest."""
        if self._open_kernel is not None:
            foreground = np.asarray(
                cv2.morphologyEx(foreground, cv2.MORPH_OPEN, self._open_kernel), dtype=np.uint8
            )
        if self._close_kernel is not None:
            foreground = np.asarray(
                cv2.morphologyEx(foreground, cv2.MORPH_CLOSE, self._close_kernel), dtype=np.uint8
            )
        if self._roi_mask is not None:
            foreground = np.asarray(cv2.bitwise_and(foreground, self._roi_mask), dtype=np.uint8)
        return foreground

    def _blobs_to_detections(self, foreground: U8) -> list[ImageDetection]:
        """Connected components to scored boxes (pixel edges)."""
        settings = self.settings
        count, labels, stats, _ = cv2.connectedComponentsWithStats(
            foreground, connectivity=8, ltype=cv2.CV_32S
        )
        detections: list[ImageDetection] = []
        for label in range(1, count):  # 0 is the background
            left, top, width, height, area = (int(value) for value in stats[label])
            if area < settings.min_blob_area_px:
                continue
            if max(width / height, height / width) > settings.max_aspect_ratio:
                continue
            blob = labels[top : top + height, left : left + width] == label
            solidity = _solidity(blob.astype(np.uint8), area)
            score = solidity * (1.0 - math.exp(-area / settings.score_area_scale_px))
            detections.append(
                ImageDetection(
                    box_xyxy_px=(float(left), float(top), float(left + width), float(top + height)),
                    score=float(score),
                    class_name=VEHICLE_CLASS_NAME,
                )
            )
        detections.sort(key=lambda detection: detection.score, reverse=True)
        return detections


def _solidity(blob: U8, area_px: int) -> float:
    """Blob pixels over its convex hull's pixels, in (0, 1] (1: convex)."""
    contours, _ = cv2.findContours(blob, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    points = np.vstack([contour.reshape(-1, 2) for contour in contours])
    hull = cv2.convexHull(points)
    hull_mask = np.zeros_like(blob)
    cv2.fillPoly(hull_mask, [hull], 1)
    hull_area = int(np.count_nonzero(hull_mask))
    return min(1.0, area_px / hull_area) if hull_area > 0 else 1.0
