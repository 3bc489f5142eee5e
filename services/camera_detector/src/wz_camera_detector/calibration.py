"""The camera and the radar learn their rotation and their clock from the LiDAR's vehicles.

The LiDAR learns its own pose from the road (:mod:`wz_lidar_detector.calibration`) and
publishes its vehicles in the site frame. Every vehicle the camera also sees is then a
calibration target of known position: a target-free camera-LiDAR calibration from traffic, as
roadside systems do it (the camera's boxes against the LiDAR's objects projected into the
image). A camera frame stamped ``dt`` late shows the vehicles where they were ``dt`` before its
stamp, so the clock is learned with the rotation.

Camera (:class:`CameraSelfCalibration`)
---------------------------------------
For each camera frame kept (a few a second), the image tracks' boxes are paired with the LiDAR's
objects at the frame's true time ``stamp - dt`` (the object's position moved along its velocity
from the nearest LiDAR sweep: :class:`ReferenceObjects`). Each object's outline (its class's
:class:`~wz_camera_detector.world.VehicleShape` on the road at its heading) is projected with
the candidate pose; the residuals are the box's left, right and bottom edges [px], as the
camera's own ranging fits them (:func:`~wz_camera_detector.world.fit_box_to_ground`). The
parameters are the yaw, pitch and roll corrections, the position's three and the clock offset,
with the site file's pose as the prior (angles 3 deg, position 0.25 m horizontally and 0.15 m
up, clock 0.2 s: a weak pull that only decides what the data leave open). They are found by

1. a vote, when nothing is known yet (or after a bump): for clock offsets on a 25 ms grid, the
   image shifts between every predicted and detected box bottom are histogrammed over all
   frames; the sharpest peak gives the clock offset and a shift, which the rotation's
   Jacobian at the image centre turns into yaw and pitch. Near vehicles move more pixels per
   second than far ones, so only the right clock offset makes all ranges agree;
2. Gauss-Newton with Huber weights on the edge residuals, the pairs matched again (Hungarian
   on box centres) between steps.

What separates the parameters: a yaw moves every box sideways alike, a sideways shift moves
near boxes more; a pitch moves every box up or down alike, a height moves near boxes more; a
late clock moves boxes along the road by their speed times ``dt``, so traffic of mixed speeds
(and queues) separates it from the pitch. The LiDAR's own position along the road is
unobservable (the road is straight), and the camera inherits it.

Radar (:class:`~wz_camera_detector.radar_calibration.RadarSelfCalibration`)
--------------------------------------------------------------------------
A radar target is a range, an azimuth and a radial speed. Paired with the LiDAR's objects at
``stamp - dt`` (each object's echo: the centre of its face nearest the radar,
:func:`~wz_camera_detector.association.face_offsets`), the bearing residual is the yaw
correction and the horizontal range residual is ``c + (u . v) dt`` for the object's velocity
``v`` along the line of sight ``u``: a linear fit of the yaw, the clock offset and a range
offset ``c`` (the echo model's and the radar's position's), the pairs matched again between
fits. A vote over the bearing residuals starts it.

Bumps: the residuals of the last seconds' pairs are checked against the learned pose at every
fit; twice past the threshold (``bump_deg``) the sensor is ``bumped``: the window restarts from
the recent frames. A knock turns a sensor on its bracket, so the camera is turned back at once
by the shift the check measured (known to the pairs' spread), and its fits after the knock
keep the position and clock learned before it and free the rotation (applied from
``knock_min_pairs``); the radar votes again. Meanwhile the detections carry the angles'
uncertainty in their covariance.
"""

from __future__ import annotations

import logging
import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, ConfigDict, Field
from scipy.optimize import linear_sum_assignment

from wz_camera_detector.world import PIXEL_EDGE_INSET_PX, VehicleShape
from wz_shared.arrays import F64, Bool
from wz_shared.camera_geometry import PinholeCamera, camera_at_size
from wz_shared.messages import (
    CalibrationState,
    DetectionBatch,
    PoseCorrection,
    SensorCalibration,
)
from wz_shared.self_calibration import (
    CalibrationLog,
    bounded_correction,
    corrected_pose,
    offset_pose,
)
from wz_shared.site import SensorMount

log = logging.getLogger("wz_camera_detector.calibration")


class SensorCalibrationSettings(BaseModel):
    """How the camera and the radar learn their pose and clock
    (``WZ_CAMERA_CALIBRATION__*``)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    #: Learn and apply; False: the site file's poses and the stamps as they come.
    enabled: bool = True
    #: Vehicle classes whose pairs the camera's fit uses (both the image box's and the
    #: LiDAR object's class): those of one typical shape.
    target_classes: tuple[str, ...] = ("car",)
    #: Camera frames kept for the fit, per second of camera time.
    frames_per_s: float = Field(default=10.0, gt=0.0)
    #: Seconds of pairs the fit uses [s].
    window_s: float = Field(default=120.0, gt=0.0)
    #: Seconds between fits while learning, and once calibrated (the bump check runs with
    #: each) [s].
    fit_every_s: float = Field(default=5.0, gt=0.0)
    calibrated_fit_every_s: float = Field(default=15.0, gt=0.0)
    #: Once calibrated, each fit moves the applied pose this share of the way (1: all).
    calibrated_gain: float = Field(default=0.3, gt=0.0, le=1.0)
    #: Camera frames a fit uses at most (evenly over the window).
    max_fit_frames: int = Field(default=400, ge=20)
    #: Seconds between bump checks once calibrated [s].
    bump_every_s: float = Field(default=2.0, gt=0.0)
    #: Matched pairs before a correction is applied.
    min_pairs: int = Field(default=150, ge=10)
    #: Pairs before the state is ``calibrated`` (with the yaw std below
    #: ``calibrated_std_deg``).
    calibrated_pairs: int = Field(default=250, ge=10)
    calibrated_std_deg: float = Field(default=0.2, gt=0.0)
    #: Camera frames paired with the LiDAR's objects before the first vote.
    vote_min_frames: int = Field(default=50, ge=5)
    #: The clock offsets the vote tries [s]: from, to.
    clock_search_s: tuple[float, float] = (-0.05, 0.3)
    #: Bump check: the recent seconds [s] and the angle their residuals may stand off [deg].
    bump_window_s: float = Field(default=5.0, gt=0.0)
    bump_deg: float = Field(default=0.6, gt=0.0)
    #: After a knock the fit keeps the position and clock learned before it, to these [m],
    #: [s]: a knock turns a sensor on its bracket (the bolts hold its place; the clock is the
    #: electronics').
    knock_position_m: float = Field(default=0.05, gt=0.0)
    knock_clock_s: float = Field(default=0.005, gt=0.0)
    #: Matched pairs before a fit after a knock is applied: only the rotation is free then.
    knock_min_pairs: int = Field(default=30, ge=10)
    #: Prior std of the yaw and of the pitch and roll [deg] (a compass and a level), of the
    #: horizontal and vertical position [m] (a tape), of the clock offset [s].
    prior_yaw_deg: float = Field(default=2.0, gt=0.0)
    prior_tilt_deg: float = Field(default=1.0, gt=0.0)
    prior_horizontal_m: float = Field(default=0.2, gt=0.0)
    prior_vertical_m: float = Field(default=0.1, gt=0.0)
    prior_clock_s: float = Field(default=0.2, gt=0.0)
    #: Radar: learn its shift across the boresight with its yaw. Off: on traffic from one
    #: approach the two trade off (a shift moves near targets' bearings more, but the ranges
    #: seen are too alike), and on the default site seed 5 the shift took the whole yaw.
    radar_shift: bool = False
    #: Radar: prior std of the range offset between its echoes and the LiDAR's objects [m].
    #: At one speed a late clock and a range offset look alike (``c + v dt``); only traffic of
    #: mixed speeds tells them apart. The fusion ranges with the same echo model
    #: (:func:`~wz_camera_detector.association.face_offsets`) and a radar's range is calibrated
    #: at the factory, so the offset is held near zero and the clock takes the rest.
    prior_range_m: float = Field(default=0.1, gt=0.0)
    #: Radar: pairs of one vehicle in successive scans are not independent (formal std
    #: inflation; the camera counts its vehicles instead).
    frames_per_vehicle: float = Field(default=10.0, ge=1.0)


# --- the LiDAR's objects as a reference ------------------------------------------------------


@dataclass(frozen=True)
class Snapshot:
    """The reference objects at one time: positions [m], velocities [m/s], headings [rad]."""

    stamp_s: float
    xy_m: F64
    velocity_mps: F64
    heading_rad: F64
    object_class: tuple[str, ...]
    #: Which vehicle each is (the reference tracker's number): pairs of one vehicle in
    #: successive frames share its box's error, so the fits count vehicles, not pairs.
    track_id: tuple[int, ...] = ()


@dataclass
class _RefTrack:
    points: deque[tuple[float, float, float]] = field(default_factory=lambda: deque(maxlen=10))
    misses: int = 0
    track_id: int = 0

    def velocity(self) -> tuple[float, float] | None:
        if len(self.points) < 4:
            return None
        arr = np.array(self.points)
        recent = arr[arr[:, 0] >= arr[-1, 0] - 0.5]
        if len(recent) < 3 or recent[-1, 0] - recent[0, 0] < 0.1:
            return None
        t = recent[:, 0] - recent[:, 0].mean()
        denom = float(t @ t)
        return float(t @ recent[:, 1] / denom), float(t @ recent[:, 2] / denom)

    def predict(self, stamp_s: float) -> tuple[float, float]:
        velocity = self.velocity() or (0.0, 0.0)
        t, x, y = self.points[-1]
        return x + velocity[0] * (stamp_s - t), y + velocity[1] * (stamp_s - t)


class ReferenceObjects:
    """The LiDAR's objects with velocities: a small nearest-neighbour tracker over its batches.

    Only objects seen in four sweeps or more, with a velocity from the last half second, are in
    a :class:`Snapshot`; :meth:`at` gives the snapshot nearest a time.
    """

    def __init__(self, history_s: float = 3.0, gate_m: float = 2.5) -> None:
        self.history_s = history_s
        self.gate_m = gate_m
        self._tracks: list[_RefTrack] = []
        self._snapshots: deque[Snapshot] = deque()
        self._next_id = 0

    @property
    def newest_s(self) -> float:
        return self._snapshots[-1].stamp_s if self._snapshots else -math.inf

    def add(self, batch: DetectionBatch) -> None:
        """Take one LiDAR batch (site frame; a batch older than the newest is ignored)."""
        stamp = batch.stamp
        if self._snapshots and stamp <= self._snapshots[-1].stamp_s:
            if stamp < self._snapshots[-1].stamp_s - 5.0:  # a new run: start again
                self._tracks.clear()
                self._snapshots.clear()
            else:
                return
        # A box the LiDAR completed from its far end (cut by its field of view under the mast)
        # is placed from a slice of the vehicle, a metre off deep in the cone: no reference.
        # With them, the camera learned a 2.0 deg roll on a surveyed mast (default site, seed
        # 10400), 0.4 deg without.
        kept = [d for d in batch.detections if not d.completed_from_far_end]
        dets = np.array(
            [(d.x_m, d.y_m, d.time_offset_s or 0.0) for d in kept], dtype=np.float64
        ).reshape(-1, 3)
        predicted = np.array(
            [track.predict(stamp) for track in self._tracks], dtype=np.float64
        ).reshape(-1, 2)
        taken = np.zeros(len(dets), dtype=bool)
        if len(dets) and len(predicted):
            cost = np.hypot(
                predicted[:, None, 0] - dets[None, :, 0], predicted[:, None, 1] - dets[None, :, 1]
            )
            rows, cols = linear_sum_assignment(np.minimum(cost, 1e3))
            for row, col in zip(rows, cols, strict=True):
                if cost[row, col] <= self.gate_m:
                    x, y, offset = dets[col]
                    self._tracks[row].points.append((stamp + offset, x, y))
                    self._tracks[row].misses = -1
                    taken[col] = True
        for track in self._tracks:
            track.misses += 1
        self._tracks = [track for track in self._tracks if track.misses <= 3]
        for index in np.flatnonzero(~taken):
            x, y, offset = dets[index]
            track = _RefTrack(track_id=self._next_id)
            self._next_id += 1
            track.points.append((stamp + offset, x, y))
            self._tracks.append(track)
        xy, velocity, heading, classes, ids = [], [], [], [], []
        by_index = {id(t): t for t in self._tracks}
        for track in by_index.values():
            if track.misses != 0:
                continue
            v = track.velocity()
            if v is None:
                continue
            t, x, y = track.points[-1]
            xy.append((x - v[0] * (t - stamp), y - v[1] * (t - stamp)))
            velocity.append(v)
            heading.append(math.atan2(v[1], v[0]))
            classes.append("car")
            ids.append(track.track_id)
        # Classes and sizes: the batch's detection nearest each kept position.
        if xy and len(dets):
            for i, (x, y) in enumerate(xy):
                j = int(np.argmin(np.hypot(dets[:, 0] - x, dets[:, 1] - y)))
                classes[i] = str(kept[j].object_class)
        self._snapshots.append(
            Snapshot(
                stamp_s=stamp,
                xy_m=np.array(xy, dtype=np.float64).reshape(-1, 2),
                velocity_mps=np.array(velocity, dtype=np.float64).reshape(-1, 2),
                heading_rad=np.array(heading, dtype=np.float64),
                object_class=tuple(classes),
                track_id=tuple(ids),
            )
        )
        while self._snapshots and self._snapshots[0].stamp_s < stamp - self.history_s:
            self._snapshots.popleft()

    def at(self, stamp_s: float, within_s: float = 0.06) -> Snapshot | None:
        """The snapshot nearest ``stamp_s`` within ``within_s``, else None."""
        best: Snapshot | None = None
        for snapshot in self._snapshots:
            if abs(snapshot.stamp_s - stamp_s) <= within_s and (
                best is None or abs(snapshot.stamp_s - stamp_s) < abs(best.stamp_s - stamp_s)
            ):
                best = snapshot
        return best


# --- the camera -----------------------------------------------------------------------------


#: A target box this much covered by a nearer vehicle's box (a share of its area) is occluded.
OCCLUDED_SHARE = 0.02


def _occluded(boxes: F64, xy_m: F64, camera_xy: F64, rows: npt.NDArray[np.int64]) -> Bool:
    """Which of the vehicles ``rows`` (of the predicted image boxes ``boxes`` (N, 4), at site
    positions ``xy_m`` (N, 2)) a vehicle nearer the camera covers by more than
    :data:`OCCLUDED_SHARE` of its box, shape (len(rows),)."""
    out = np.zeros(len(rows), dtype=bool)
    finite = np.isfinite(boxes).all(axis=1)
    distance = np.hypot(*(xy_m - camera_xy).T)
    for k, i in enumerate(rows.tolist()):
        box = boxes[i]
        area = (box[2] - box[0]) * (box[3] - box[1])
        nearer = finite & (distance < distance[i])
        if area <= 0.0 or not nearer.any():
            continue
        other = boxes[nearer]
        width = np.minimum(other[:, 2], box[2]) - np.maximum(other[:, 0], box[0])
        height = np.minimum(other[:, 3], box[3]) - np.maximum(other[:, 1], box[1])
        covered = np.clip(width, 0.0, None) * np.clip(height, 0.0, None)
        out[k] = bool((covered > OCCLUDED_SHARE * area).any())
    return out


def _track_ids(snapshot: Snapshot, count: int) -> F64:
    """The snapshot's vehicle numbers (one per object; -1 each when not given)."""
    if len(snapshot.track_id) == count:
        return np.asarray(snapshot.track_id, dtype=np.float64)
    return np.full(count, -1.0)


@dataclass(frozen=True)
class _Frame:
    stamp_s: float
    boxes_px: F64  # (M, 4)
    box_shapes: tuple[int, ...]  # index into the shape table, per box
    reference: Snapshot
    reference_shapes: tuple[int, ...]


#: Parameters of the camera fit, in this order, with their numeric-derivative steps.
_NAMES = ("yaw_deg", "pitch_deg", "roll_deg", "x_m", "y_m", "z_m", "clock_s")
_STEPS = np.array([0.01, 0.01, 0.01, 0.01, 0.01, 0.01, 0.002])
#: ... and the bounds of the search (the message's bounds).
_BOUNDS = np.array([6.0, 3.0, 3.0, 1.0, 1.0, 1.0, 0.5])


class CameraSelfCalibration:
    """One camera's rotation, position and clock learned against the LiDAR's objects.

    Parameters
    ----------
    site_id, mount
        The camera's site and its mount (the site file's pose: the prior).
    shapes
        Vehicle class name (bus class, e.g. ``car``, ``truck``) -> outline.
    settings
        :class:`SensorCalibrationSettings`.
    """

    def __init__(
        self,
        site_id: str,
        mount: SensorMount,
        shapes: dict[str, VehicleShape],
        settings: SensorCalibrationSettings,
    ) -> None:
        self.mount = mount
        self.nominal = mount.pose
        self.settings = settings
        self.log = CalibrationLog(site_id, mount.sensor_id, "camera")
        self._shape_names = list(shapes)
        self._shapes = [shapes[name] for name in self._shape_names]
        self._outlines = np.stack([shape.outline_points() for shape in self._shapes])
        self._target_shapes = np.array(
            [i for i, name in enumerate(self._shape_names) if name in settings.target_classes],
            dtype=int,
        )
        self.reference = ReferenceObjects()
        self._pending: deque[tuple[float, F64, tuple[int, ...]]] = deque()
        self._frames: deque[_Frame] = deque()
        self._size: tuple[int, int] | None = None
        self._next_keep_s = -math.inf
        self._next_fit_s = -math.inf
        self._next_check_s = -math.inf
        self._bump_votes = 0
        self._initialised = False
        #: What was applied when the camera was last found knocked: a knock turns the camera
        #: on its bracket; it neither moves it nor changes its clock.
        self._before_knock: F64 | None = None
        self.params = np.zeros(len(_NAMES))
        #: What is applied: the fits themselves while learning, smoothed once calibrated.
        self._applied: F64 | None = None
        self.std = np.full(len(_NAMES), np.nan)
        self.pairs = 0
        self.vehicles = 0
        self.correction = PoseCorrection()
        self.clock_offset_s = 0.0
        self.pose = mount.pose
        self._last_stamp_s = 0.0

    def shape_index(self, class_name: str) -> int:
        try:
            return self._shape_names.index(class_name)
        except ValueError:
            return 0

    # -- evidence ----------------------------------------------------------------------------

    def add_reference(self, batch: DetectionBatch) -> None:
        """A LiDAR batch (site frame, on the LiDAR's clock)."""
        if not self.settings.enabled:
            return
        self.reference.add(batch)
        self._pair_pending()

    def observe(
        self,
        stamp_s: float,
        width_px: int,
        height_px: int,
        boxes_px: F64,
        class_names: list[str],
    ) -> None:
        """A camera frame's whole vehicle boxes (not cut by the view), on the camera's clock."""
        if not self.settings.enabled:
            return
        self._last_stamp_s = max(self._last_stamp_s, stamp_s)
        if self._size is not None and self._size != (width_px, height_px):
            self._frames.clear()
            self._pending.clear()
        self._size = (width_px, height_px)
        if stamp_s >= self._next_keep_s and len(boxes_px):
            self._next_keep_s = stamp_s + 1.0 / self.settings.frames_per_s
            shapes = tuple(self.shape_index(name) for name in class_names)
            self._pending.append((stamp_s, np.asarray(boxes_px, dtype=np.float64), shapes))
            self._pair_pending()
        while self._frames and self._frames[0].stamp_s < stamp_s - self.settings.window_s:
            self._frames.popleft()
        if len(self._frames) < 10:
            return
        if self.log.state == CalibrationState.CALIBRATED and stamp_s >= self._next_check_s:
            self._next_check_s = stamp_s + self.settings.bump_every_s
            if self._check_bump(stamp_s, list(self._frames)):
                self._next_fit_s = stamp_s
        if stamp_s >= self._next_fit_s:
            every = self.settings.fit_every_s
            if self.log.state == CalibrationState.CALIBRATED:
                every = self.settings.calibrated_fit_every_s
            self._next_fit_s = stamp_s + every
            self._fit(stamp_s)

    def _pair_pending(self) -> None:
        newest = self.reference.newest_s
        while self._pending:
            stamp, boxes, shapes = self._pending[0]
            wanted = stamp - self.clock_offset_s
            if wanted > newest:
                return  # the LiDAR's sweep of that time has not come yet
            self._pending.popleft()
            snapshot = self.reference.at(wanted)
            if snapshot is None or not len(snapshot.xy_m):
                continue
            self._frames.append(
                _Frame(
                    stamp,
                    boxes,
                    shapes,
                    snapshot,
                    tuple(self.shape_index(name) for name in snapshot.object_class),
                )
            )

    # -- the model ---------------------------------------------------------------------------

    def camera_for(self, params: F64) -> PinholeCamera:
        pose = offset_pose(
            self.nominal,
            yaw_deg=params[0],
            pitch_deg=params[1],
            roll_deg=params[2],
            x_m=params[3],
            y_m=params[4],
            z_m=params[5],
        )
        assert self._size is not None
        return camera_at_size(self.mount.model_copy(update={"pose": pose}), *self._size)

    def _boxes(
        self,
        camera: PinholeCamera,
        centres_xy: F64,
        heading: F64,
        shapes: F64,
    ) -> F64:
        """Image boxes (N, 4) of vehicles (centre, heading, shape index) on the road."""
        local = self._outlines[shapes.astype(int)]  # (N, 12, 3)
        cos_h, sin_h = np.cos(heading)[:, None], np.sin(heading)[:, None]
        world = np.empty_like(local)
        world[:, :, 0] = centres_xy[:, 0:1] + local[:, :, 0] * cos_h - local[:, :, 1] * sin_h
        world[:, :, 1] = centres_xy[:, 1:2] + local[:, :, 0] * sin_h + local[:, :, 1] * cos_h
        world[:, :, 2] = local[:, :, 2]
        uv, _ = camera.project(world.reshape(-1, 3))
        uv = uv.reshape(len(local), -1, 2)
        return np.stack(
            [uv[:, :, 0].min(1), uv[:, :, 1].min(1), uv[:, :, 0].max(1), uv[:, :, 1].max(1)], 1
        )

    def _predict(self, params: F64, frames: list[_Frame]) -> list[F64]:
        camera = self.camera_for(params)
        centres, heading, shapes, counts = [], [], [], []
        for frame in frames:
            ref = frame.reference
            dt = frame.stamp_s - params[6] - ref.stamp_s
            centres.append(ref.xy_m + ref.velocity_mps * dt)
            heading.append(ref.heading_rad)
            shapes.append(np.array(frame.reference_shapes, dtype=np.float64))
            counts.append(len(ref.xy_m))
        boxes = self._boxes(
            camera, np.concatenate(centres), np.concatenate(heading), np.concatenate(shapes)
        )
        return np.split(boxes, np.cumsum(counts)[:-1])

    def _match(
        self, params: F64, frames: list[_Frame], gate_px: float
    ) -> tuple[F64, F64, F64, F64, F64, F64]:
        """Pairs under ``params``: reference centre at the stamp, velocity, heading, stamp
        offset, the detected box with its shape, and the reference vehicle's number, as
        arrays."""
        predicted = self._predict(params, frames)
        camera_xy = np.array([self.nominal.x_m + params[3], self.nominal.y_m + params[4]])
        rows: list[F64] = []
        for frame, boxes in zip(frames, predicted, strict=True):
            ok = np.isfinite(boxes).all(axis=1)
            if not ok.any():
                continue
            det = frame.boxes_px
            pred_c = np.stack([0.5 * (boxes[:, 0] + boxes[:, 2]), boxes[:, 3]], 1)
            det_c = np.stack([0.5 * (det[:, 0] + det[:, 2]), det[:, 3]], 1)
            cost = np.hypot(
                pred_c[:, None, 0] - det_c[None, :, 0], pred_c[:, None, 1] - det_c[None, :, 1]
            )
            cost[~ok] = 1e6
            r, c = linear_sum_assignment(cost)
            best = cost[r, c]
            keep = best <= gate_px
            if not keep.any():
                continue
            r, c, best = r[keep], c[keep], best[keep]
            # Unambiguous: no other prediction nearly as close to the box, nor another box to
            # the prediction (the second smallest of its column and of its row).
            col = np.sort(cost, axis=0)
            row = np.sort(cost, axis=1)
            col_second = col[1, c] if len(cost) > 1 else np.full(len(c), np.inf)
            row_second = row[r, 1] if cost.shape[1] > 1 else np.full(len(r), np.inf)
            clear = np.minimum(col_second, row_second) >= np.maximum(2.0 * best, best + 8.0)
            r, c = r[clear], c[clear]
            # Targets of a known shape only: a car is a car, a truck anything from a box van
            # to a semitrailer (its outline would be a guess, its edges biased).
            ref_shapes = np.asarray(frame.reference_shapes)[r]
            box_shapes = np.asarray(frame.box_shapes)[c]
            known = np.isin(ref_shapes, self._target_shapes) & np.isin(
                box_shapes, self._target_shapes
            )
            r, c = r[known], c[known]
            # Whole in the camera's view: a vehicle partly behind a nearer one (a queue seen
            # from the mast) has its bottom or a side edge hidden, which reads as a pitch.
            visible = ~_occluded(boxes, frame.reference.xy_m, camera_xy, r)
            r, c = r[visible], c[visible]
            if not len(r):
                continue
            ref = frame.reference
            rows.append(
                np.column_stack(
                    [
                        ref.xy_m[r],
                        ref.velocity_mps[r],
                        ref.heading_rad[r],
                        np.full(len(r), frame.stamp_s - ref.stamp_s),
                        det[c],
                        np.asarray(frame.box_shapes, dtype=np.float64)[c],
                        _track_ids(ref, len(ref.xy_m))[r],
                    ]
                )
            )
        arr = np.concatenate(rows) if rows else np.zeros((0, 12))
        return arr[:, 0:2], arr[:, 2:4], arr[:, 4], arr[:, 5], arr[:, 6:11], arr[:, 11]

    def _residuals(
        self, params: F64, xy: F64, velocity: F64, heading: F64, lag: F64, det: F64
    ) -> F64:
        camera = self.camera_for(params)
        centres = xy + velocity * (lag - params[6])[:, None]
        boxes = self._boxes(camera, centres, heading, det[:, 4])
        inset = PIXEL_EDGE_INSET_PX
        return np.concatenate(
            [
                boxes[:, 0] - (det[:, 0] + inset),
                boxes[:, 2] - (det[:, 2] - inset),
                boxes[:, 3] - (det[:, 3] - inset),
            ]
        )

    def _prior(self) -> tuple[F64, F64]:
        """The fit's prior (mean, std): the set-up tolerance about the site file's pose; after a
        knock, the same rotation tolerance about the pose learned before it, and the position
        and clock learned before it to ``knock_position_m`` and ``knock_clock_s`` (a few
        seconds of pairs after a knock would move the weakly seen ones, the position along
        the line of sight above all, where the knock did not)."""
        s = self.settings
        sigma = np.array(
            [
                s.prior_yaw_deg,
                s.prior_tilt_deg,
                s.prior_tilt_deg,
                s.prior_horizontal_m,
                s.prior_horizontal_m,
                s.prior_vertical_m,
                s.prior_clock_s,
            ]
        )
        if self._before_knock is None:
            return np.zeros(len(_NAMES)), sigma
        sigma[3:6] = s.knock_position_m
        sigma[6] = s.knock_clock_s
        return self._before_knock.copy(), sigma

    def _vote(self, frames: list[_Frame]) -> F64:
        """Clock offset and the yaw and pitch of the sharpest image shift (module docstring)."""
        s = self.settings
        best = (-1.0, 0.0, 0.0, 0.0)
        bin_px = 6.0
        reach = 300.0
        edges = np.arange(-reach, reach + bin_px, bin_px)
        base = self.params.copy()
        base[:2] = 0.0
        clocks = np.arange(s.clock_search_s[0], s.clock_search_s[1] + 1e-9, 0.025)
        if self._before_knock is not None:
            # A knock turns the camera: the shift is searched from the pose learned before it,
            # at the clock learned before it.
            base = self._before_knock.copy()
            clocks = np.array([base[6]])
        # The shifts a set-up error can make: a yaw or a pitch within the bounds turns the
        # image by at most f tan(bound) (the clock's shift is the grid's, not searched here).
        focal = self.camera_for(base).focal_px
        centres = 0.5 * (edges[:-1] + edges[1:])
        reach_u = focal * math.tan(math.radians(_BOUNDS[0])) + 2 * bin_px
        reach_v = focal * math.tan(math.radians(_BOUNDS[1])) + 2 * bin_px
        allowed = (np.abs(centres)[:, None] <= reach_u) & (np.abs(centres)[None, :] <= reach_v)
        for clock in clocks:
            trial = base.copy()
            trial[6] = clock
            predicted = self._predict(trial, frames)
            du_all, dv_all = [], []
            for frame, boxes in zip(frames, predicted, strict=True):
                pred_c = np.stack([0.5 * (boxes[:, 0] + boxes[:, 2]), boxes[:, 3]], 1)
                det = frame.boxes_px
                det_c = np.stack([0.5 * (det[:, 0] + det[:, 2]), det[:, 3]], 1)
                du_pairs = (det_c[None, :, 0] - pred_c[:, None, 0]).ravel()
                dv_pairs = (det_c[None, :, 1] - pred_c[:, None, 1]).ravel()
                keep = (
                    np.isfinite(du_pairs) & (np.abs(du_pairs) < reach) & (np.abs(dv_pairs) < reach)
                )
                du_all.append(du_pairs[keep])
                dv_all.append(dv_pairs[keep])
            du_cat, dv_cat = np.concatenate(du_all), np.concatenate(dv_all)
            if not du_cat.size:
                continue
            hist, _, _ = np.histogram2d(du_cat, dv_cat, bins=[edges, edges])
            smooth = hist.copy()
            smooth[1:, :] += hist[:-1, :]
            smooth[:-1, :] += hist[1:, :]
            smooth2 = smooth.copy()
            smooth2[:, 1:] += smooth[:, :-1]
            smooth2[:, :-1] += smooth[:, 1:]
            smooth2[~allowed] = 0.0
            i, j = np.unravel_index(int(smooth2.argmax()), smooth2.shape)
            if smooth2[i, j] > best[0]:
                best = (
                    float(smooth2[i, j]),
                    float(clock),
                    float(edges[i]) + bin_px / 2,
                    float(edges[j]) + bin_px / 2,
                )
        _, clock, du, dv = best
        angles = self._turn_for_shift(base, du, dv)
        result = base.copy()
        result[0], result[1], result[6] = base[0] + angles[0], base[1] + angles[1], clock
        log.debug(
            "camera %s vote: clock %.3f s, shift (%.0f, %.0f) px: yaw %.2f deg, pitch %.2f deg",
            self.mount.sensor_id,
            clock,
            du,
            dv,
            result[0],
            result[1],
        )
        return np.clip(result, -_BOUNDS, _BOUNDS)

    def _turn_for_shift(self, params: F64, du_px: float, dv_px: float) -> F64:
        """The (yaw, pitch) [deg] that move the image by (``du_px``, ``dv_px``) at a point on
        the road 50 m ahead of the camera posed by ``params``."""
        camera = self.camera_for(params)
        ahead = camera.position_m + 50.0 * camera.mount.pose.rotation()[:, 0]
        ahead[2] = 0.0
        jac = np.zeros((2, 2))
        u0, _ = camera.project(ahead[None, :])
        for k in range(2):
            trial = params.copy()
            trial[k] += 0.1
            uk, _ = self.camera_for(trial).project(ahead[None, :])
            jac[:, k] = (uk[0] - u0[0]) / 0.1
        try:
            return np.asarray(np.linalg.solve(jac, [du_px, dv_px]), dtype=np.float64)
        except np.linalg.LinAlgError:
            return np.zeros(2)

    def _fit(self, stamp_s: float) -> None:
        frames = list(self._frames)
        if len(frames) > self.settings.max_fit_frames:  # evenly over the window
            pick = np.linspace(0, len(frames) - 1, self.settings.max_fit_frames).astype(int)
            frames = [frames[i] for i in pick]
        # Knocked with nothing applied before (no turn to start from): vote afresh.
        revote = self.log.state == CalibrationState.BUMPED and self._before_knock is None
        if not self._initialised or revote:
            if len(frames) < self.settings.vote_min_frames:
                return
            self.params = self._vote(frames)
            self._initialised = True
        prior_mean, prior_sigma = self._prior()
        params = self.params.copy()
        pairs = 0
        covariance = None
        for gate in (60.0, 15.0, 15.0):
            xy, velocity, heading, lag, det, vehicle = self._match(params, frames, gate)
            pairs = len(xy)
            known = vehicle >= 0
            # Pairs of an unnumbered reference count as ``frames_per_vehicle`` to a vehicle.
            vehicles = max(
                1,
                len(np.unique(vehicle[known]))
                + round(int((~known).sum()) / self.settings.frames_per_vehicle),
            )
            if pairs < 10:
                self._initialised = False  # nothing meets: vote again with more frames
                return
            for _ in range(3):
                base = self._residuals(params, xy, velocity, heading, lag, det)
                good = np.isfinite(base)
                scale = max(1.4826 * float(np.median(np.abs(base[good]))), 1.0)
                weight = np.where(
                    good, np.minimum(1.0, 2.5 * scale / np.maximum(np.abs(base), 1e-9)), 0.0
                )
                weight = np.where(np.abs(base) > 6.0 * scale, 0.0, weight)
                base = np.where(good, base, 0.0)
                jac = np.empty((len(base), len(_NAMES)))
                for k, step in enumerate(_STEPS):
                    trial = params.copy()
                    trial[k] += step
                    r = self._residuals(trial, xy, velocity, heading, lag, det)
                    jac[:, k] = np.where(good, (np.nan_to_num(r) - base) / step, 0.0)
                w = weight / scale**2
                normal = jac.T @ (w[:, None] * jac) + np.diag(1.0 / prior_sigma**2)
                gradient = jac.T @ (w * base) + (params - prior_mean) / prior_sigma**2
                try:
                    step_vec = -np.linalg.solve(normal, gradient)
                    covariance = np.linalg.inv(normal)
                except np.linalg.LinAlgError:
                    return
                params = np.clip(params + step_vec, -_BOUNDS, _BOUNDS)
                if np.all(np.abs(step_vec) < _STEPS):
                    break
        log.debug(
            "camera %s fit: %s from %d pairs",
            self.mount.sensor_id,
            dict(zip(_NAMES, np.round(params, 4), strict=True)),
            pairs,
        )
        self.params = params
        self.pairs = pairs
        self.vehicles = vehicles
        if covariance is not None:
            # Pairs of one vehicle share its LiDAR box's error: as if each vehicle were one
            # pair of its weight (the conservative end of a cluster-robust covariance).
            self.std = np.sqrt(np.maximum(np.diag(covariance), 0.0) * pairs / max(vehicles, 1))
        knocked = self.log.state == CalibrationState.BUMPED and self._before_knock is not None
        if pairs >= (self.settings.knock_min_pairs if knocked else self.settings.min_pairs):
            self.take(params)
        self._update_state(stamp_s)

    def _check_bump(self, stamp_s: float, frames: list[_Frame]) -> bool:
        """Whether the camera was just found bumped (then the window restarts)."""
        recent = [f for f in frames if f.stamp_s >= stamp_s - self.settings.bump_window_s]
        if len(recent) < 5:
            return False
        xy, velocity, heading, lag, det, vehicle = self._match(self.params, recent, 120.0)
        # Too few pairs tells nothing: a gap in the traffic both sensors see, or cars outside
        # the detector's region. A knock shows as the pairs' shift.
        matched = len(xy) >= 8
        shift_deg = du = dv = 0.0
        spread_px = (0.0, 0.0)
        if matched:
            res = self._residuals(self.params, xy, velocity, heading, lag, det).reshape(3, -1)
            across, down = 0.5 * (res[0] + res[1]), res[2]
            du, dv = float(np.nanmedian(across)), float(np.nanmedian(down))
            spread_px = (
                1.4826 * float(np.nanmedian(np.abs(across - du))),
                1.4826 * float(np.nanmedian(np.abs(down - dv))),
            )
            camera = self.camera_for(self.params)
            shift_deg = math.degrees(math.hypot(du, dv) / camera.focal_px)
        moved = matched and shift_deg > self.settings.bump_deg
        self._bump_votes = self._bump_votes + 1 if moved else 0
        if self._bump_votes >= 2:
            self._bump_votes = 0
            self._before_knock = None
            if self._applied is not None:
                self._before_knock = self._applied.copy()
                self._turn_by_shift(du, dv, spread_px, len(np.unique(vehicle)))
            self.log.enter(
                CalibrationState.BUMPED,
                stamp_s,
                f"its image stands {shift_deg:.2f} deg off the LiDAR's vehicles",
            )
            while self._frames and self._frames[0].stamp_s < stamp_s - self.settings.bump_window_s:
                self._frames.popleft()
            return True
        return False

    def _turn_by_shift(
        self, du_px: float, dv_px: float, spread_px: tuple[float, float], vehicles: int
    ) -> None:
        """Apply the knock the bump check measured (its pairs' median shift, predicted minus
        seen) at once: the rotation that undoes it, known to the pairs' spread over the
        vehicles they come from. The fits then refine it from the frames after the knock."""
        turn = self._turn_for_shift(self.params, -du_px, -dv_px)
        yaw_spread = abs(float(self._turn_for_shift(self.params, spread_px[0], 0.0)[0]))
        pitch_spread = abs(float(self._turn_for_shift(self.params, 0.0, spread_px[1])[1]))
        self.params = self.params.copy()
        self.params[:2] += turn
        self._applied = self.params.copy()
        self.std = self.std.copy()
        self.std[:2] = np.array([yaw_spread, pitch_spread]) / math.sqrt(max(vehicles, 1))
        self._apply()

    def take(self, params: F64) -> None:
        """Apply a fit's parameters (the order of ``_NAMES``): as they are while learning or
        just bumped; once calibrated, ``calibrated_gain`` of the way from the applied ones.
        Successive fits then share most of their window and differ by noise (the camera's
        position along its line of sight is weakly observed: fits 15 s apart moved it 0.6 m),
        and the applied pose follows them smoothly, still fast enough for a mast's settling
        (tenths of a degree an hour)."""
        if self.log.state == CalibrationState.CALIBRATED and self._applied is not None:
            gain = self.settings.calibrated_gain
            self._applied = self._applied + gain * (np.asarray(params) - self._applied)
        else:
            self._applied = np.array(params, dtype=np.float64)
        self._apply()

    def _apply(self) -> None:
        assert self._applied is not None
        p, std = self._applied, self.std
        self.correction = bounded_correction(
            yaw_deg=float(p[0]),
            pitch_deg=float(p[1]),
            roll_deg=float(p[2]),
            x_m=float(p[3]),
            y_m=float(p[4]),
            z_m=float(p[5]),
            yaw_std_deg=float(std[0]),
            pitch_std_deg=float(std[1]),
            roll_std_deg=float(std[2]),
            x_std_m=float(std[3]),
            y_std_m=float(std[4]),
            z_std_m=float(std[5]),
        )
        self.clock_offset_s = float(np.clip(p[6], -0.5, 0.5))
        self.pose = corrected_pose(self.nominal, self.correction)

    def _update_state(self, stamp_s: float) -> None:
        state = self.log.state
        if state == CalibrationState.PRIOR and self.pairs:
            self.log.enter(CalibrationState.LEARNING, stamp_s, "learning from the LiDAR's vehicles")
        done = (
            self.pairs >= self.settings.calibrated_pairs
            and float(self.std[0]) <= self.settings.calibrated_std_deg
            and float(self.std[1]) <= self.settings.calibrated_std_deg
        )
        if done and self.log.state in (CalibrationState.LEARNING, CalibrationState.BUMPED):
            self.log.enter(
                CalibrationState.CALIBRATED,
                stamp_s,
                f"yaw {self.params[0]:+.2f} deg, pitch {self.params[1]:+.2f} deg, clock "
                f"{1000 * self.params[6]:+.0f} ms from {self.pairs} boxes of {self.vehicles} "
                "vehicles",
            )

    @property
    def angle_std_rad(self) -> tuple[float, float]:
        """(yaw, pitch) uncertainty the detections carry now [rad]: 1 deg each until learned
        and after a knock with no turn to start from, the fit's (or the knock's measured turn's)
        while learning again, none once calibrated (the camera's own noise model then holds, as
        for a surveyed camera)."""
        state = self.log.state
        unturned = state == CalibrationState.BUMPED and self._before_knock is None
        if state == CalibrationState.PRIOR or unturned or not np.isfinite(self.std[0]):
            return math.radians(1.0), math.radians(1.0)
        if state == CalibrationState.CALIBRATED:
            return 0.0, 0.0
        return math.radians(float(self.std[0])), math.radians(float(self.std[1]))

    def message(self) -> SensorCalibration:
        std = float(self.std[6]) if np.isfinite(self.std[6]) else None
        return self.log.message(
            self._last_stamp_s, self.correction, self.clock_offset_s, std, self.pairs
        )
