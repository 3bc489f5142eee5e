"""Image-plane multi-object tracking: stable local ids for camera detections.

ByteTrack-style association (Zhang et al., 2022) on top of a constant-velocity Kalman filter
per track. Each :meth:`ImageTracker.update` is one cycle, in this order:

1. **prune**: tracks not updated for more than ``max_age_s`` are deleted;
2. **predict**: every live track is predicted to the frame's stamp (``dt`` from stamps, never
   from a frame count, since stamps come from messages and frames may be dropped);
3. **associate, stage 1**: detections with ``score >= high_score_threshold`` against the
   predicted boxes of all live tracks, by IoU (Hungarian assignment on ``1 - IoU``, pairs with
   ``IoU < match_iou_threshold`` forbidden);
4. **associate, stage 2**: detections with ``low_score_threshold <= score <
   high_score_threshold`` against the confirmed tracks left over; such a detection continues a
   track but never starts one (a partly occluded vehicle scores low; so does clutter);
5. **update** the matched tracks; **spawn** a tentative track for each unmatched high-score
   detection; a tentative track that goes a frame without a match is deleted (ByteTrack's rule:
   a one-frame false positive leaves no coasting ghost);
6. **follow**: a track no detection updated takes the box optical flow followed it to in this
   frame (:mod:`wz_camera_detector.flow`), as a measurement of its own noise
   (``flow_noise_px``). That is all a frame the detector skips gives (``detections`` None):
   the node detects at a few hertz and follows the boxes in between. A track is deleted
   ``max_age_s`` after its last *detection* however long flow follows it (flow would follow a
   false box on the background as faithfully as a vehicle), and a tentative track needs a
   detection at each frame the detector ran. A tentative track is confirmed at
   ``min_hits`` detections, or at ``min_hits_followed`` when flow followed it through every
   frame between them: flow checks that the box moves as one thing.

Pixel coordinates are those of :mod:`wz_camera_detector.yolo`: ``u`` right, ``v`` down, boxes
``(x1, y1, x2, y2)`` by their pixel edges [px of the original frame].

Kalman filter (textbook symbols kept), state ``x = (cx, cy, w, h, vcx, vcy, vw, vh)`` [px, px/s],
measurement ``z = (cx, cy, w, h)`` [px]::

    F = [[I, dt I], [0, I]]                 (constant velocity)
    Q = sigma_a^2 [[dt^4/4 I, dt^3/2 I],    (white acceleration, piecewise constant over dt)
                   [dt^3/2 I, dt^2 I]]
    H = [I, 0],  R = sigma_z^2 I

Nothing here does I/O: the node decodes frames, calls :meth:`ImageTracker.update`, publishes.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, ConfigDict, Field, model_validator
from scipy.optimize import linear_sum_assignment

from wz_camera_detector.yolo import ImageDetection, box_iou
from wz_shared.arrays import F64

_STATE_DIM = 8  # cx, cy, w, h and their rates
_MEAS_DIM = 4  # cx, cy, w, h

#: Smallest box side a prediction may shrink to [px]: keeps the IoU of a predicted box defined.
_MIN_BOX_SIDE_PX = 1.0


class ImageTrackerSettings(BaseModel):
    """Parameters of :class:`ImageTracker`; pixels of the original frame, seconds of stamps."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    # --- detection scores ---
    #: Detections scoring at least this are matched first and may start tracks [0-1].
    high_score_threshold: float = Field(default=0.5, ge=0.0, le=1.0)
    #: Detections scoring below this are ignored; between the two they only continue tracks [0-1].
    low_score_threshold: float = Field(default=0.1, ge=0.0, le=1.0)

    # --- association ---
    #: A detection and a predicted track box with IoU below this are never paired [0-1].
    match_iou_threshold: float = Field(default=0.2, gt=0.0, le=1.0)

    # --- lifecycle ---
    #: A confirmed track not updated for longer than this is deleted [s].
    max_age_s: float = Field(default=1.0, gt=0.0)
    #: Updates (the first detection included) before a track is confirmed.
    min_hits: int = Field(default=3, ge=1)
    #: ... when optical flow followed it through every frame between its detections (at least
    #: one): a box that flow follows from one detection to the next is one moving thing.
    min_hits_followed: int = Field(default=2, ge=1)
    #: A track born cut by the edge of the view that has grown out of it by this much (its
    #: extent across that edge) [px] is a vehicle entering: confirmed at two detections, or
    #: at one that flow then followed through ``min_frames_entering`` frames. The detector
    #: finds a vehicle cut by the edge less often than a whole one; its growth from the edge
    #: is what a false box does not do.
    entering_growth_px: float = Field(default=4.0, gt=0.0)
    min_frames_entering: int = Field(default=2, ge=1)
    #: A box this close to the view's edge is cut by it [px].
    edge_margin_px: float = Field(default=3.0, ge=0.0)

    # --- Kalman filter ---
    #: Standard deviation of the white acceleration of box centre and size [px/s^2].
    process_noise_accel_px_per_s2: float = Field(default=100.0, gt=0.0)
    #: Standard deviation of a detected box's centre and size [px].
    measurement_noise_px: float = Field(default=2.0, gt=0.0)
    #: Standard deviation of the unknown velocity of a new track [px/s].
    initial_velocity_std_px_per_s: float = Field(default=300.0, gt=0.0)
    #: Standard deviation of a box followed by optical flow, centre and size [px]: a little
    #: above a detection's (the grid's points are not all on the vehicle).
    flow_noise_px: float = Field(default=3.0, gt=0.0)

    @model_validator(mode="after")
    def _check_thresholds(self) -> ImageTrackerSettings:
        if self.low_score_threshold > self.high_score_threshold:
            raise ValueError(
                f"low_score_threshold ({self.low_score_threshold}) must not exceed "
                f"high_score_threshold ({self.high_score_threshold})"
            )
        return self


@dataclass(frozen=True, slots=True)
class ImageTrack:
    """One tracked object, as reported after a cycle.

    Attributes
    ----------
    local_id
        Id of the track, unique for the tracker's lifetime (never reused), from 1.
    box_xyxy_px
        Filtered box ``(x1, y1, x2, y2)`` [px].
    velocity_px_per_s
        Filtered velocity ``(du/dt, dv/dt)`` of the box centre [px/s].
    class_name
        Most frequent class over the track's detections (ties: the most recent of them).
    score
        Score of the track's latest detection, in [0, 1].
    hits
        Number of detections the track has been updated with, the first included.
    age_s
        Time since the track's first detection [s].
    time_since_update_s
        Time since the track's latest detection [s]; 0 for a track updated this cycle.
    confirmed
        Whether the track is confirmed (``min_hits`` detections, or ``min_hits_followed``
        with flow between them).
    followed
        Whether this cycle's update was optical flow's (no detection this frame).
    misses
        Detector runs over the track's region since its latest detection: 0 when the latest
        run found it. Flow follows a track the detector missed (a vehicle cut by the frame's
        edge, or one the detector lost for a frame), and a false box as faithfully.
    """

    local_id: int
    box_xyxy_px: tuple[float, float, float, float]
    velocity_px_per_s: tuple[float, float]
    class_name: str
    score: float
    hits: int
    age_s: float
    time_since_update_s: float
    confirmed: bool
    followed: bool = False
    misses: int = 0


def _xyxy_to_z(box_xyxy_px: Sequence[float]) -> F64:
    """Box edges ``(x1, y1, x2, y2)`` -> measurement ``(cx, cy, w, h)`` [px], shape (4,)."""
    x1, y1, x2, y2 = (float(edge) for edge in box_xyxy_px)
    return np.array([(x1 + x2) / 2.0, (y1 + y2) / 2.0, x2 - x1, y2 - y1], dtype=np.float64)


def _z_to_xyxy(z: F64) -> F64:
    """``(cx, cy, w, h)`` -> ``(x1, y1, x2, y2)`` [px], sides floored at 1 px; shape (4,)."""
    half_w = max(float(z[2]), _MIN_BOX_SIDE_PX) / 2.0
    half_h = max(float(z[3]), _MIN_BOX_SIDE_PX) / 2.0
    return np.array([z[0] - half_w, z[1] - half_h, z[0] + half_w, z[1] + half_h], dtype=np.float64)


def _centre_in(box_xyxy_px: F64, regions: Sequence[Sequence[float]]) -> bool:
    """Whether the box's centre lies in one of the regions ``(x1, y1, x2, y2)`` [px]."""
    u, v = (box_xyxy_px[0] + box_xyxy_px[2]) / 2.0, (box_xyxy_px[1] + box_xyxy_px[3]) / 2.0
    return any(x1 <= u <= x2 and y1 <= v <= y2 for x1, y1, x2, y2 in regions)


def iou_matrix(boxes_a_xyxy_px: npt.ArrayLike, boxes_b_xyxy_px: npt.ArrayLike) -> F64:
    """Pairwise intersection over union of two sets of boxes.

    Parameters
    ----------
    boxes_a_xyxy_px
        Boxes ``(x1, y1, x2, y2)`` [px], shape (M, 4).
    boxes_b_xyxy_px
        Boxes [px], shape (N, 4).

    Returns
    -------
    iou
        Shape (M, N), in [0, 1].
    """
    boxes_a = np.asarray(boxes_a_xyxy_px, dtype=np.float64).reshape(-1, 4)
    boxes_b = np.asarray(boxes_b_xyxy_px, dtype=np.float64).reshape(-1, 4)
    iou = np.zeros((len(boxes_a), len(boxes_b)), dtype=np.float64)
    for row, box in enumerate(boxes_a):
        iou[row] = box_iou(box, boxes_b)
    return iou


def match_by_iou(iou: F64, match_iou_threshold: float) -> list[tuple[int, int]]:
    """Optimal one-to-one pairing maximising total IoU, with pairs below a threshold forbidden.

    Solves the assignment on the cost ``1 - IoU`` (Hungarian, ``scipy``) and then drops the
    pairs whose IoU is below ``match_iou_threshold``; forbidden pairs get a cost above any
    allowed one so they never displace an allowed pairing.

    Parameters
    ----------
    iou
        IoU of each row item (tracks) with each column item (detections), shape (M, N).
    match_iou_threshold
        Smallest IoU of an accepted pair, in (0, 1].

    Returns
    -------
    pairs
        ``(row, column)`` index pairs, each row and column at most once, by increasing row.
    """
    if iou.size == 0:
        return []
    allowed = iou >= match_iou_threshold
    cost = np.where(allowed, 1.0 - iou, 2.0)
    rows, columns = linear_sum_assignment(cost)
    return [
        (int(row), int(column))
        for row, column in zip(rows, columns, strict=True)
        if allowed[row, column]
    ]


@dataclass(slots=True)
class _Track:
    """Mutable state of one live track; the filter's ``x`` and ``P`` are kept by name."""

    local_id: int
    x: F64  # state (cx, cy, w, h, vcx, vcy, vw, vh) [px, px/s], shape (8,)
    P: F64  # state covariance, shape (8, 8)
    born_s: float
    updated_s: float
    score: float
    hits: int = 1
    #: Frames optical flow followed it through since its first detection.
    followed_frames: int = 0
    #: Whether flow followed it through every frame no detection updated it in (while tentative).
    followed_throughout: bool = True
    #: Confirmed once; stays so.
    confirmed: bool = False
    #: Detector runs over its region since its latest detection.
    misses: int = 0
    #: Which edges of the view (left, top, right, bottom) its first box touched, and that
    #: box's width and height [px]: a vehicle entering the view.
    born_at_edges: tuple[bool, bool, bool, bool] = (False, False, False, False)
    born_size_px: tuple[float, float] = (0.0, 0.0)
    class_counts: dict[str, int] = field(default_factory=dict)
    class_last_hit: dict[str, int] = field(default_factory=dict)

    def vote(self, class_name: str) -> None:
        self.class_counts[class_name] = self.class_counts.get(class_name, 0) + 1
        self.class_last_hit[class_name] = self.hits

    def class_name(self) -> str:
        return max(
            self.class_counts,
            key=lambda name: (self.class_counts[name], self.class_last_hit[name]),
        )

    def box_xyxy_px(self) -> F64:
        return _z_to_xyxy(self.x[:_MEAS_DIM])


class ImageTracker:
    """ByteTrack-style multi-object tracker in the image plane (see the module docstring).

    Parameters
    ----------
    settings
        Thresholds, lifecycle and filter noise.
    """

    def __init__(self, settings: ImageTrackerSettings) -> None:
        self.settings = settings
        self._tracks: list[_Track] = []
        self._next_id = 1
        self._last_stamp_s: float | None = None
        self._H = np.hstack([np.eye(_MEAS_DIM), np.zeros((_MEAS_DIM, _MEAS_DIM))])
        self._R = np.eye(_MEAS_DIM) * settings.measurement_noise_px**2
        self._R_flow = np.eye(_MEAS_DIM) * settings.flow_noise_px**2
        self._FQ: tuple[float, F64, F64] | None = None

    # --- the filter ---

    def _transition(self, dt: float) -> tuple[F64, F64]:
        """``F`` and ``Q`` for a step of ``dt`` [s] (one pair per frame, for every track)."""
        if self._FQ is not None and self._FQ[0] == dt:
            return self._FQ[1], self._FQ[2]
        eye = np.eye(_MEAS_DIM)
        F = np.block([[eye, dt * eye], [np.zeros_like(eye), eye]])
        sigma_a2 = self.settings.process_noise_accel_px_per_s2**2
        Q = sigma_a2 * np.block(
            [[dt**4 / 4.0 * eye, dt**3 / 2.0 * eye], [dt**3 / 2.0 * eye, dt**2 * eye]]
        )
        self._FQ = (dt, F, Q)
        return F, Q

    def _predict(self, track: _Track, dt: float) -> None:
        F, Q = self._transition(dt)
        # x = F x
        track.x = F @ track.x
        # P = F P F' + Q
        track.P = F @ track.P @ F.T + Q

    def _update(self, track: _Track, z: F64, R: F64 | None = None) -> None:
        H = self._H
        R = self._R if R is None else R
        # y = z - H x
        y = z - H @ track.x
        # S = H P H' + R
        S = H @ track.P @ H.T + R
        # K = P H' S^-1  (solved, not inverted: S is symmetric positive definite)
        K = np.linalg.solve(S, H @ track.P).T
        # x = x + K y
        track.x = track.x + K @ y
        # P = (I - K H) P (I - K H)' + K R K'  (Joseph form: stays symmetric positive
        # definite under rounding, which the short form (I - K H) P does not guarantee)
        I_KH = np.eye(_STATE_DIM) - K @ H
        P = I_KH @ track.P @ I_KH.T + K @ R @ K.T
        track.P = (P + P.T) / 2.0

    def _spawn(
        self,
        detection: ImageDetection,
        stamp_s: float,
        view_xyxy_px: Sequence[float] | None = None,
    ) -> _Track:
        x = np.zeros(_STATE_DIM, dtype=np.float64)
        x[:_MEAS_DIM] = _xyxy_to_z(detection.box_xyxy_px)
        variances = [self.settings.measurement_noise_px**2] * _MEAS_DIM + [
            self.settings.initial_velocity_std_px_per_s**2
        ] * _MEAS_DIM
        track = _Track(
            local_id=self._next_id,
            x=x,
            P=np.diag(variances),
            born_s=stamp_s,
            updated_s=stamp_s,
            score=detection.score,
        )
        track.vote(detection.class_name)
        if view_xyxy_px is not None:
            x1, y1, x2, y2 = detection.box_xyxy_px
            vx1, vy1, vx2, vy2 = (float(edge) for edge in view_xyxy_px)
            margin = self.settings.edge_margin_px
            track.born_at_edges = (
                x1 <= vx1 + margin,
                y1 <= vy1 + margin,
                x2 >= vx2 - margin,
                y2 >= vy2 - margin,
            )
            track.born_size_px = (x2 - x1, y2 - y1)
        self._next_id += 1
        return track

    def restart(self) -> None:
        """A new run (the frames' stamps started again): drop every track and the previous
        stamp; ids go on (never reused)."""
        self._tracks = []
        self._last_stamp_s = None

    # --- one cycle ---

    def update(
        self,
        detections: Sequence[ImageDetection] | None,
        stamp_s: float,
        followed: Mapping[int, Sequence[float]] | None = None,
        unsearched: Sequence[Sequence[float]] = (),
        view_xyxy_px: Sequence[float] | None = None,
    ) -> list[ImageTrack]:
        """Run one cycle on a frame: prune, predict, associate, update, spawn, follow.

        Parameters
        ----------
        detections
            The frame's detections (any order), boxes [px]; None for a frame the detector
            did not run on (only ``followed`` updates tracks then).
        stamp_s
            Capture time of the frame [s]; must increase from call to call.
        followed
            Boxes ``(x1, y1, x2, y2)`` [px] optical flow followed live tracks to in this frame,
            by ``local_id`` (from their boxes of the previous frame, :meth:`tracks`); taken
            for the tracks no detection updates.
        unsearched
            Regions ``(x1, y1, x2, y2)`` [px] the detector did not search this frame at their
            own resolution (far-field tiles it skipped): a tentative track whose box centre is
            in one is not deleted for missing a detection.
        view_xyxy_px
            The region ``(x1, y1, x2, y2)`` [px] the detector sees (its ROI, or the frame): a
            track born cut by its edge and growing out of it is a vehicle entering
            (``entering_growth_px``); None: no such rule.

        Returns
        -------
        tracks
            The tracks updated by this frame (by a detection, tentative ones included with
            ``confirmed=False``, or by flow, ``followed=True``), by increasing ``local_id``.
            Tracks coasting without either are in :meth:`tracks`.

        Raises
        ------
        ValueError
            ``stamp_s`` is not finite or not later than the previous frame's (an out-of-order
            or repeated frame: the filters cannot predict backwards).
        """
        if not math.isfinite(stamp_s):
            raise ValueError(f"frame stamp must be finite, got {stamp_s}")
        if self._last_stamp_s is not None and stamp_s <= self._last_stamp_s:
            raise ValueError(
                f"frame stamp {stamp_s:.6f} s is not after the previous one "
                f"({self._last_stamp_s:.6f} s): out-of-order or repeated frame refused"
            )
        dt = 0.0 if self._last_stamp_s is None else stamp_s - self._last_stamp_s
        self._last_stamp_s = stamp_s
        settings = self.settings

        # prune
        self._tracks = [
            track for track in self._tracks if stamp_s - track.updated_s <= settings.max_age_s
        ]
        # predict
        if dt > 0.0:
            for track in self._tracks:
                self._predict(track, dt)

        updated: list[_Track] = []
        unmatched_high: list[ImageDetection] = []
        if detections is not None:
            updated, unmatched_high = self._associate_detections(detections, stamp_s)
        updated_ids = {track.local_id for track in updated}

        # follow: flow's boxes for the tracks no detection updated
        flowed: list[_Track] = []
        for track in self._tracks:
            if track.local_id in updated_ids:
                continue
            box = followed.get(track.local_id) if followed is not None else None
            if box is not None and all(math.isfinite(float(edge)) for edge in box):
                self._update(track, _xyxy_to_z(box), self._R_flow)
                # Flow measures motion from the previous box: its error stays in every box
                # after it (drift), so what it added is kept as uncertainty: a detection
                # then takes over with the weight the drift calls for.
                track.P[:_MEAS_DIM, :_MEAS_DIM] += self._R_flow
                track.followed_frames += 1
                flowed.append(track)
            elif not track.confirmed:
                track.followed_throughout = False
        if detections is not None:
            for track in self._tracks:
                if track.local_id in updated_ids:
                    track.misses = 0
                elif not _centre_in(track.box_xyxy_px(), unsearched):
                    track.misses += 1
            # a tentative track missing a frame the detector ran on was probably a false positive
            self._tracks = [
                track
                for track in self._tracks
                if track.local_id in updated_ids
                or track.confirmed
                or _centre_in(track.box_xyxy_px(), unsearched)
            ]
            for detection in unmatched_high:
                track = self._spawn(detection, stamp_s, view_xyxy_px)
                self._tracks.append(track)
                updated.append(track)
        for track in [*updated, *flowed]:
            track.confirmed = track.confirmed or self._confirms(track)
        reported = [self._report(track, stamp_s) for track in updated]
        reported += [self._report(track, stamp_s, followed=True) for track in flowed]
        return sorted(reported, key=lambda t: t.local_id)

    def _confirms(self, track: _Track) -> bool:
        settings = self.settings
        if track.hits >= settings.min_hits:
            return True
        followed = track.followed_throughout and track.followed_frames > 0
        if followed and track.hits >= settings.min_hits_followed:
            return True
        return self._entering(track) and (
            track.hits >= 2
            or (track.followed_throughout and track.followed_frames >= settings.min_frames_entering)
        )

    def _entering(self, track: _Track) -> bool:
        """Whether the track was born cut by the view's edge and has grown out of it since."""
        left, top, right, bottom = track.born_at_edges
        if not (left or top or right or bottom):
            return False
        x1, y1, x2, y2 = track.box_xyxy_px()
        born_w, born_h = track.born_size_px
        growth = self.settings.entering_growth_px
        return ((left or right) and x2 - x1 >= born_w + growth) or (
            (top or bottom) and y2 - y1 >= born_h + growth
        )

    def _associate_detections(
        self, detections: Sequence[ImageDetection], stamp_s: float
    ) -> tuple[list[_Track], list[ImageDetection]]:
        """Stages 1 and 2: the tracks updated, and the high-score detections left over."""
        settings = self.settings
        high = [d for d in detections if d.score >= settings.high_score_threshold]
        low = [
            d
            for d in detections
            if settings.low_score_threshold <= d.score < settings.high_score_threshold
        ]
        updated: list[_Track] = []

        # stage 1: high-score detections against every live track
        unmatched_tracks = list(self._tracks)
        unmatched_high = list(high)
        if unmatched_tracks and unmatched_high:
            pairs = self._associate(unmatched_tracks, unmatched_high)
            for track_index, detection_index in pairs:
                self._correct(
                    unmatched_tracks[track_index], unmatched_high[detection_index], stamp_s
                )
                updated.append(unmatched_tracks[track_index])
            matched_tracks = {track_index for track_index, _ in pairs}
            matched_detections = {detection_index for _, detection_index in pairs}
            unmatched_tracks = [
                t for i, t in enumerate(unmatched_tracks) if i not in matched_tracks
            ]
            unmatched_high = [
                d for i, d in enumerate(unmatched_high) if i not in matched_detections
            ]

        # stage 2: low-score detections only continue confirmed tracks
        candidates = [t for t in unmatched_tracks if t.confirmed]
        if candidates and low:
            for track_index, detection_index in self._associate(candidates, low):
                self._correct(candidates[track_index], low[detection_index], stamp_s)
                updated.append(candidates[track_index])
        return updated, unmatched_high

    @property
    def last_stamp_s(self) -> float | None:
        """The latest frame's stamp [s]; None before the first (or after :meth:`restart`)."""
        return self._last_stamp_s

    def tracks(self) -> list[ImageTrack]:
        """All live tracks as of the latest frame, coasting ones included, by ``local_id``.

        Returns
        -------
        tracks
            Boxes and velocities are the filter's estimate at the latest frame's stamp (a
            prediction for a track not updated by that frame).
        """
        if self._last_stamp_s is None:
            return []
        stamp_s = self._last_stamp_s
        return sorted(
            (self._report(track, stamp_s) for track in self._tracks), key=lambda t: t.local_id
        )

    def _associate(
        self, tracks: Sequence[_Track], detections: Sequence[ImageDetection]
    ) -> list[tuple[int, int]]:
        predicted = np.array([track.box_xyxy_px() for track in tracks])
        detected = np.array([d.box_xyxy_px for d in detections], dtype=np.float64)
        return match_by_iou(iou_matrix(predicted, detected), self.settings.match_iou_threshold)

    def _correct(self, track: _Track, detection: ImageDetection, stamp_s: float) -> None:
        self._update(track, _xyxy_to_z(detection.box_xyxy_px))
        track.updated_s = stamp_s
        track.score = detection.score
        track.hits += 1
        track.vote(detection.class_name)

    def _report(self, track: _Track, stamp_s: float, followed: bool = False) -> ImageTrack:
        box = track.box_xyxy_px()
        return ImageTrack(
            local_id=track.local_id,
            box_xyxy_px=(float(box[0]), float(box[1]), float(box[2]), float(box[3])),
            velocity_px_per_s=(float(track.x[4]), float(track.x[5])),
            class_name=track.class_name(),
            score=track.score,
            hits=track.hits,
            age_s=stamp_s - track.born_s,
            time_since_update_s=stamp_s - track.updated_s,
            confirmed=track.confirmed,
            followed=followed,
            misses=track.misses,
        )
