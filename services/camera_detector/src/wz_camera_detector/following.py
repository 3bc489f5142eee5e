"""Detect where it pays, follow in between: the image-plane steps of each frame.

A roadside camera streams 15-30 frames a second, and consecutive frames differ by a few
pixels; the detector's model costs tens of milliseconds a region on one core. So the model runs
on a frame only when ``detection_period_s`` (less half a frame's interval) has passed since it
last ran (its far-field tiles at every ``tiles_every``-th run when it skips frames, at each
while it runs on every frame), and on the frames between each
track's box is followed by optical flow (:class:`~wz_camera_detector.flow.BoxFlow`):

=========== =================================== ===================
camera      detector runs on (period 0.13 s)    detections a second
=========== =================================== ===================
10 fps      every frame                         10
15 fps      every 2nd frame                     7.5
20 fps      every 3rd frame                     6.7
25 fps      every 3rd frame                     8.3
30 fps      every 4th frame                     7.5
=========== =================================== ===================

The image tracker (:class:`~wz_camera_detector.tracker.ImageTracker`) takes the detections
where the model ran and flow's boxes for the tracks they did not update. On a frame the model
ran on, flow follows only the boxes the view's edge cuts (vehicles leaving, which the model
loses); a whole box the model missed is mostly hidden by another vehicle, whose pixels flow
would follow, so it coasts on its motion. A track is published
(:meth:`DetectAndFollow.publishes`) once confirmed and while the model's latest run over it
found it, or while it is cut by the edge of the view: a vehicle leaving the frame, which the
model loses while flow still follows what is left of it (a vehicle half out of the frame is
not ranged: :func:`cut_by_view`).

The node (:class:`~wz_camera_detector.node.CameraDetector`), ``wz detect-camera`` and
``wz eval-camera --video`` run these steps through this one class. Nothing here does I/O.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import cv2
import numpy as np

from wz_camera_detector.flow import BoxFlow
from wz_camera_detector.settings import CameraDetectorSettings
from wz_camera_detector.tracker import ImageTrack, ImageTracker
from wz_camera_detector.yolo import ImageDetection, YoloOnnxDetector
from wz_shared.arrays import U8

#: A box this close to the edge of the detector's view is cut by it: not ranged [px].
TRUNCATION_MARGIN_PX = 3.0


class ImageBackend(Protocol):
    def detect(self, image_bgr: U8) -> list[ImageDetection]: ...


def cut_by_view(
    box_xyxy_px: tuple[float, float, float, float],
    backend: object,
    width_px: int,
    height_px: int,
) -> bool:
    """Whether a box touches the left, right or bottom edge of every region the detector
    looks at (its ROI, else the frame, and its far-field tiles), within
    :data:`TRUNCATION_MARGIN_PX`: a vehicle cut by the view. A far car at the ROI's edge that
    a tile holds whole was seen whole."""
    roi = getattr(backend, "roi_xyxy_px", None) or (0, 0, width_px, height_px)
    regions = [roi, *getattr(backend, "tiles_xyxy_px", ())]
    x1, _, x2, y2 = box_xyxy_px
    margin = TRUNCATION_MARGIN_PX
    return not any(
        x1 > left + margin
        and x2 < min(right, width_px) - margin
        and y2 < min(bottom, height_px) - margin
        for left, _, right, bottom in regions
    )


@dataclass(frozen=True)
class FollowStep:
    """What one frame gave.

    Attributes
    ----------
    detections
        The model's vehicle boxes (classes it knows a shape for), None on a frame it skipped.
    updated
        The tracks this frame updated (by a detection or by flow), tentative ones included.
    published
        Those of them to publish (:meth:`DetectAndFollow.publishes`).
    tiles
        Whether the YOLO backend's far-field tiles ran (False on a frame it skipped).
    """

    detections: list[ImageDetection] | None
    updated: list[ImageTrack]
    published: list[ImageTrack]
    tiles: bool = False


class DetectAndFollow:
    """The detector where it is due, optical flow between, the image tracker over both.

    Parameters
    ----------
    backend
        The image detector (YOLO, or the background model, which runs on every frame: it
        learns the road from each).
    settings
        ``detection_period_s``, ``tiles_every``, ``tracker`` and ``flow`` (module docstring).
    vehicle_classes
        The class names kept from the detector (the others are dropped).
    """

    def __init__(
        self,
        backend: ImageBackend,
        settings: CameraDetectorSettings,
        vehicle_classes: frozenset[str],
    ) -> None:
        self.backend = backend
        self.settings = settings
        self.vehicle_classes = vehicle_classes
        self.tracker = ImageTracker(settings.tracker)
        self.flow = BoxFlow(settings.flow)
        #: Stamp of the latest frame the detector ran on [s]; None: none yet in this run.
        self._detected_s: float | None = None
        self._detections_run = 0
        #: Stamp of the previous frame [s] (for its interval).
        self._previous_s: float | None = None
        #: Whether a frame was skipped since the detector last ran (flow followed it).
        self._skipped_since_run = False

    @property
    def detections_run(self) -> int:
        """How many frames the detector has run on (the others were followed by flow)."""
        return self._detections_run

    def restart(self) -> None:
        """A new run (the stamps started again) or another backend: tracks, flow and the
        schedule start again (track ids go on)."""
        self.tracker.restart()
        self.flow.restart()
        self._detected_s = None
        self._previous_s = None
        self._skipped_since_run = False

    def due(self, stamp_s: float) -> bool:
        """Whether the detector runs on the frame of ``stamp_s``: always for a backend other
        than YOLO (the background model learns from every frame) or a period of 0; else when
        ``detection_period_s`` less half the frames' interval has passed since it last ran
        (or it has not run in this run)."""
        period = self.settings.detection_period_s
        last, previous = self._detected_s, self._previous_s
        if period <= 0.0 or not isinstance(self.backend, YoloOnnxDetector):
            return True
        if last is None or previous is None or stamp_s <= last:
            return True
        interval = max(0.0, stamp_s - previous)
        return stamp_s - last >= period - 0.5 * interval

    def detect(self, image: U8) -> list[ImageDetection]:
        """The model's boxes alone, nothing tracked (the background model's warm-up)."""
        return self.backend.detect(image)

    def step(self, image: U8, stamp_s: float, detect: bool) -> FollowStep:
        """One frame: the model if ``detect`` (``image`` BGR) else none (``image`` BGR or
        grey), flow from the previous frame, the tracker.

        Raises what the backend raises (the caller reports it; the frame is then not
        tracked), and ValueError for a stamp not after the previous frame's.
        """
        detections: list[ImageDetection] | None = None
        skipped_tiles: tuple[tuple[int, int, int, int], ...] = ()
        tiles = False
        if detect:
            backend = self.backend
            runs = self._detections_run
            if isinstance(backend, YoloOnnxDetector):
                # The tiles at every run while the detector runs on every frame (nothing
                # between for flow to carry a far track over); at every tiles_every-th when
                # flow follows the frames between.
                tiles = not self._skipped_since_run or runs % self.settings.tiles_every == 0
                if not tiles:
                    skipped_tiles = backend.tiles_xyxy_px
                found = backend.detect(image, tiles=tiles)
            else:
                found = backend.detect(image)
            self._detections_run += 1
            self._detected_s = stamp_s
            self._skipped_since_run = False
            detections = [box for box in found if box.class_name in self.vehicle_classes]
        else:
            self._skipped_since_run = True
        height, width = image.shape[:2]
        roi = getattr(self.backend, "roi_xyxy_px", None) or (0, 0, width, height)
        view = (max(0, roi[0]), max(0, roi[1]), min(width, roi[2]), min(height, roi[3]))
        followed = self._follow(image, stamp_s, view, only_cut=detect)
        updated = self.tracker.update(detections, stamp_s, followed, skipped_tiles, view)
        self._previous_s = stamp_s
        published = [track for track in updated if self.publishes(track, width, height)]
        return FollowStep(detections, updated, published, tiles)

    def publishes(self, track: ImageTrack, width_px: int, height_px: int) -> bool:
        """Whether a track updated this frame is published: confirmed, and found by the
        detector's latest run over it, or cut by the edge of the view (a vehicle leaving
        it, which the detector loses while flow still follows what is left of it)."""
        return track.confirmed and (
            track.misses == 0 or cut_by_view(track.box_xyxy_px, self.backend, width_px, height_px)
        )

    def _follow(
        self, image: U8, stamp_s: float, view: tuple[int, int, int, int], only_cut: bool
    ) -> dict[int, tuple[float, float, float, float]]:
        """Where optical flow followed each live track's box of the previous frame to in this
        one, by ``local_id`` (tracks it lost are left out). Flow looks at ``view``, the
        detector's region of interest in the frame (the whole frame without one): the tracks
        are there.

        ``only_cut`` (a frame the detector runs on): only the tracks the view's edge cuts.
        The tracker takes flow's box for a track the detector missed; a miss of a box the
        edge cuts is a vehicle leaving, whose rest flow still follows, but a miss of a whole
        box is mostly a vehicle hidden by another, and flow would follow the pixels that hide
        it: that track coasts on its motion. (On the default site at 10 fps, flow carrying
        every missed track cost seed 11 a false speeding alert and 28 false track-frames.)
        """
        if not self.settings.flow.enabled:
            return {}
        previous = self.tracker.tracks()
        if only_cut:
            height, width = image.shape[:2]
            previous = [
                track
                for track in previous
                if cut_by_view(track.box_xyxy_px, self.backend, width, height)
            ]
        gray: U8 = (
            image
            if image.ndim == 2
            else np.asarray(cv2.cvtColor(image, cv2.COLOR_BGR2GRAY), dtype=np.uint8)
        )
        x0, y0, x1, y1 = (int(edge) for edge in view)
        crop = gray[y0:y1, x0:x1]  # a view: OpenCV takes its row stride
        last_s = self.tracker.last_stamp_s
        dt = stamp_s - last_s if last_s is not None and stamp_s > last_s else 0.0
        followed = self.flow.follow(
            crop,
            [track.box_xyxy_px for track in previous],
            [
                (track.velocity_px_per_s[0] * dt, track.velocity_px_per_s[1] * dt)
                for track in previous
            ],
            origin_px=(x0, y0),
        )
        return {
            track.local_id: (float(box[0]), float(box[1]), float(box[2]), float(box[3]))
            for track, box in zip(previous, followed, strict=True)
            if np.isfinite(box).all()
        }
