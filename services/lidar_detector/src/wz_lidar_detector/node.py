"""The LiDAR detector node: LiDAR frames in, site-frame detections out.

Run it as ``python -m wz_lidar_detector.node`` (``wz up`` does). Settings come from the
environment (``WZ_LIDAR_*`` for the detector, ``WZ_BUS_*`` for the bus; see
:mod:`wz_lidar_detector.settings`). It

- takes frames from ``wz/<site>/raw/lidar/<sensor>`` through a ring of one: the newest frame
  wins, and the frames a slow detector had no time for are counted as dropped by the bus;
- with the fast path, first learns the background from ``learn_frames`` frames (or loads it
  from ``background_file``), then detects; the reference path detects from the first frame;
- publishes one :class:`DetectionBatch` per processed frame on ``wz/<site>/detections/<sensor>``
  (site frame, ``stamp`` = the frame's stamp, ``latency_s`` = time from taking the frame to
  publishing), an empty one when the frame holds no vehicle;
- reports health on ``wz/<site>/status/lidar-detector``; ``state`` is ``starting`` while the
  background is being learned and ``degraded`` while it is relearned after a layout change.

Bad input never stops it. Each problem is counted in the status message's ``invalid_counts``
under ``<raw key>|<reason>`` and logged once per reason:

- envelopes that do not decode (garbage, truncated, payload size not what the metadata says):
  the bus's own reasons (``bad_magic``, ``truncated``, ``size_mismatch``, ``bad_json`` ...);
- ``wrong_sensor``: the metadata names another sensor or site;
- ``wrong_shape``: ``rows x columns`` is not the number of points (processed as unorganized);
- ``absurd_coordinates``: points with a coordinate beyond ``max_abs_coordinate_m`` or infinite
  (set to no return; the rest of the frame is processed);
- ``no_returns``: not one valid point (nothing published: a blind sensor is not an empty road);
- ``shape_change``: the layout differs from the previous frame's (the fast path learns a
  background for the new layout, keeping the old one should that layout come back);
- ``detector_error``: the detection core raised (the traceback is logged once);
- ``bad_detection``: a detection with non-finite values (dropped from the batch).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
import zipfile
from collections import OrderedDict
from collections.abc import Callable
from pathlib import Path

import numpy as np
import numpy.typing as npt
from pydantic import ValidationError

from wz_lidar_detector.background import (
    BackgroundFileError,
    BackgroundModel,
    RangeBackgroundLearner,
    RangeImageBackground,
    VoxelBackground,
    learn_background_from_frames,
    load_background,
)
from wz_lidar_detector.calibration import LidarSelfCalibration
from wz_lidar_detector.detection import BoxDetection, DetectionResult, PointFrame
from wz_lidar_detector.fast import FastPipeline
from wz_lidar_detector.reference import ReferencePipeline
from wz_lidar_detector.settings import LidarDetectorSettings, lidar_mount
from wz_lidar_detector.transform import box_to_site, to_detection
from wz_shared.arrays import F32, F64
from wz_shared.codec import Frame
from wz_shared.messages import (
    CalibrationState,
    Detection,
    DetectionBatch,
    LidarFrameMeta,
    SensorCalibration,
    ServiceState,
)
from wz_shared.self_calibration import angular_covariance
from wz_shared.service import NodeApp, ServiceRuntime
from wz_shared.site import LidarIntrinsics, SensorMount, Site
from wz_shared.timebase import SimClock

SERVICE = "lidar-detector"
log = logging.getLogger("wz_lidar_detector.node")

#: Layout of a frame: (rows, columns) when organized, (1, 0) for any unorganized cloud.
Layout = tuple[int, int]
UNORGANIZED: Layout = (1, 0)
#: Backgrounds kept for layouts seen before (a sensor switching between two modes).
MAX_LAYOUTS = 2
#: How a problem is reported: (reason, detail).
Report = Callable[[str, str], None]


def layout_of(frame: PointFrame) -> Layout:
    return (frame.rows, frame.columns) if frame.organized else UNORGANIZED


def describe(layout: Layout) -> str:
    return "unorganized" if layout == UNORGANIZED else f"{layout[0]}x{layout[1]}"


class BackgroundLearner:
    """Backgrounds of the fast path, one per frame layout, learned from the first K frames.

    Parameters
    ----------
    settings
        ``learn_frames``, the background and fast-path parameters, ``background_file``.
    """

    def __init__(self, settings: LidarDetectorSettings) -> None:
        self.settings = settings
        self._pipelines: OrderedDict[Layout, FastPipeline] = OrderedDict()
        #: A voxel model given from a file fits every layout.
        self._any_layout: FastPipeline | None = None
        self._learning: Layout | None = None
        self._frames: list[PointFrame] = []
        self._started_s = 0.0
        #: Per layout: the long learning that replaces the quick one (see :meth:`refine`).
        self._refining: dict[Layout, _Refinement] = {}

    def use(self, background: BackgroundModel) -> None:
        """Take a model (loaded from a file, or given by the caller) instead of learning one."""
        pipeline = FastPipeline(self.settings.fast, background)
        if isinstance(background, RangeImageBackground):
            self._pipelines[(background.rows, background.columns)] = pipeline
        else:
            self._any_layout = pipeline

    def load(self, path: Path) -> bool:
        """Load a saved model from ``path`` if it exists; False (logged) when it cannot."""
        if not path.is_file():
            log.info("no saved background at %s: it will be learned", path)
            return False
        try:
            background = load_background(path)
        except (BackgroundFileError, OSError, KeyError, EOFError, zipfile.BadZipFile) as exc:
            log.warning("cannot use the saved background (%s): it will be learned again", exc)
            return False
        self.use(background)
        log.info("loaded the %s background from %s", background.kind, path)
        return True

    def pipeline(self, layout: Layout) -> FastPipeline | None:
        """The pipeline whose background fits ``layout``, or None while it is being learned."""
        pipeline = self._pipelines.get(layout)
        if pipeline is not None:
            self._pipelines.move_to_end(layout)
            return pipeline
        return self._any_layout

    @property
    def learning(self) -> bool:
        return self._learning is not None

    @property
    def has_background(self) -> bool:
        return bool(self._pipelines) or self._any_layout is not None

    def learn(self, frame: PointFrame) -> FastPipeline | None:
        """Add a frame to the learning set of its layout; the new pipeline once K are in."""
        layout = layout_of(frame)
        if self._learning != layout:
            if self._learning is not None:
                log.warning(
                    "the layout changed from %s to %s while learning: starting over",
                    describe(self._learning),
                    describe(layout),
                )
            self._learning, self._frames = layout, []
            self._started_s = time.monotonic()
            log.info(
                "learning the background of %s frames from %d frames",
                describe(layout),
                self.settings.learn_frames,
            )
        self._frames.append(frame)
        wanted = self.settings.learn_frames
        if len(self._frames) < wanted:
            if len(self._frames) % max(1, wanted // 5) == 0:
                log.info("learning the background: %d/%d frames", len(self._frames), wanted)
            return None
        background = learn_background_from_frames(
            self._frames,
            range_settings=self.settings.range_background,
            voxel_m=self.settings.voxel_m,
            min_occupancy_fraction=self.settings.voxel_min_occupancy_fraction,
        )
        pipeline = FastPipeline(self.settings.fast, background)
        self._pipelines[layout] = pipeline
        while len(self._pipelines) > MAX_LAYOUTS:
            self._pipelines.popitem(last=False)
        log.info(
            "learned the %s background of %s frames from %d frames in %.2f s",
            background.kind,
            describe(layout),
            wanted,
            time.monotonic() - self._started_s,
        )
        self._learning, self._frames = None, []
        if self.settings.background_file is not None:
            self._save(background, self.settings.background_file)
        if isinstance(background, RangeImageBackground) and self.settings.refine_span_s > 0:
            self._refining[layout] = _Refinement(
                RangeBackgroundLearner(layout[0], layout[1], self.settings.range_background),
                self.settings.refine_span_s / self.settings.refine_frames,
            )
            log.info(
                "refining the background over the next %.0f s (%d frames)",
                self.settings.refine_span_s,
                self.settings.refine_frames,
            )
        return pipeline

    def refine(self, frame: PointFrame, layout: Layout, pipeline: FastPipeline) -> None:
        """Go on learning a quickly learned range background over ``refine_span_s``.

        The quick background comes from ``learn_frames`` frames in a row, a second or two: less
        than one period of a mast's sway (1-4 s), so a slot at the edge of a kerb, a drum or a
        barrier, which the sway swings between two surfaces, may have seen only one of them.
        The refinement samples ``refine_frames`` frames spread over ``refine_span_s`` and then
        replaces the pipeline's background (and writes ``background_file``).
        """
        refinement = self._refining.get(layout)
        if refinement is None:
            return
        # Not yet due; a stamp that went back further than that (a replay started over) is.
        due_s = refinement.next_take_s
        if 0 < frame.stamp_s < due_s and frame.stamp_s >= due_s - 2.0 * refinement.every_s:
            return
        refinement.learner.add(frame)
        refinement.next_take_s = frame.stamp_s + refinement.every_s
        if refinement.learner.frames < min(
            self.settings.refine_frames, RangeBackgroundLearner.MAX_FRAMES
        ):
            return
        del self._refining[layout]
        background = refinement.learner.finish()
        pipeline.background = background
        log.info(
            "refined the background of %s frames from %d frames",
            describe(layout),
            refinement.learner.frames,
        )
        if self.settings.background_file is not None:
            self._save(background, self.settings.background_file)

    @staticmethod
    def _save(background: RangeImageBackground | VoxelBackground, path: Path) -> None:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            background.save(path)
        except OSError as exc:
            log.warning("could not save the background to %s: %s", path, exc)
        else:
            log.info("saved the background to %s", path)


@dataclasses.dataclass
class _Refinement:
    learner: RangeBackgroundLearner
    every_s: float
    next_take_s: float = 0.0


class ColumnClock:
    """When each column of an organized frame fired, to stamp each detection with its own time.

    A spinning LiDAR's columns fire one after the other across the sweep: column ``j`` at
    ``stamp + sweep_duration_s * j / columns`` (:class:`LidarFrameMeta`). Which azimuth each
    column looks at is read from the data, not assumed: the circular mean of the horizontal
    directions of the column's returns (every column has some: the lower beams hit the road).
    A detection's capture time is then the time of the column nearest its centre's azimuth.
    """

    def __init__(self, frame: PointFrame, sweep_duration_s: float) -> None:
        image = frame.points.reshape(frame.rows, frame.columns, 4)
        xy = image[:, :, :2].astype(np.float64)
        norm = np.hypot(xy[..., 0], xy[..., 1])
        with np.errstate(invalid="ignore", divide="ignore"):
            unit = xy / norm[..., None]
        unit = np.where(np.isfinite(unit), unit, 0.0)
        summed = unit.sum(axis=0)  # (columns, 2)
        #: Azimuth of each column in the sensor frame [rad]; NaN for a column with no return.
        self.azimuth_rad = np.where(
            np.hypot(summed[:, 0], summed[:, 1]) > 0, np.arctan2(summed[:, 1], summed[:, 0]), np.nan
        )
        self.columns = frame.columns
        self.sweep_duration_s = sweep_duration_s
        self._known = np.flatnonzero(np.isfinite(self.azimuth_rad))

    def offsets_s(self, x_m: npt.ArrayLike, y_m: npt.ArrayLike) -> F64:
        """Capture time after the stamp [s] of points at sensor-frame ``(x, y)``."""
        azimuth = np.arctan2(np.asarray(y_m, np.float64), np.asarray(x_m, np.float64))
        if len(self._known) == 0:
            return np.zeros_like(azimuth)
        known = self.azimuth_rad[self._known]
        gap = np.abs(np.angle(np.exp(1j * (azimuth[..., None] - known[None, :]))))
        column = self._known[np.argmin(gap, axis=-1)]
        offsets: F64 = column * (self.sweep_duration_s / self.columns)
        return offsets


class LidarDetector:
    """What the node does with one frame, without the bus: check, learn, detect, move to site.

    Parameters
    ----------
    site_id
        The site the node serves (frames of another site are refused).
    mount
        The sensor: its id (frames of another sensor are refused) and pose (sensor to site).
    settings
        The service's settings (path, learning, limits).
    report
        Called with ``(reason, detail)`` for every problem (the node counts them in the bus
        stats).
    site
        The site's road, which the sensor learns its pose from
        (:mod:`wz_lidar_detector.calibration`); None: the mount's pose as it is.
    """

    def __init__(
        self,
        site_id: str,
        mount: SensorMount,
        settings: LidarDetectorSettings,
        report: Report,
        site: Site | None = None,
    ) -> None:
        self.site_id = site_id
        self.mount = mount
        settings = fitted_to_mount(settings, site, mount)
        self.settings = settings
        self.report = report
        self.reference = (
            ReferencePipeline(settings.reference) if settings.path == "reference" else None
        )
        self.backgrounds = BackgroundLearner(settings)
        #: The pose learned from the road and the traffic (:mod:`wz_lidar_detector.calibration`).
        self.calibration = LidarSelfCalibration(site_id, mount, settings.calibration, site)
        #: Whether the pose is learned (a site given and the calibration enabled).
        self.calibrating = self.calibration.settings.enabled
        self._layout: Layout | None = None
        self._clock: ColumnClock | None = None
        self._logged: set[str] = set()
        #: Stamp of the newest frame taken [s] (the node's clock on simulation time).
        self.last_stamp_s = 0.0

    @property
    def state(self) -> ServiceState:
        """``starting`` until a background exists; ``degraded`` while the layout of the newest
        frame has none (learning it) or while the sensor is flagged as knocked (its pose being
        learned again); else ``running``."""
        has_background = self.backgrounds.has_background
        if self.calibration.log.state == CalibrationState.BUMPED:
            return ServiceState.DEGRADED
        if self.reference is not None:
            return ServiceState.RUNNING
        if self._layout is None:
            return ServiceState.RUNNING if has_background else ServiceState.STARTING
        if self.backgrounds.pipeline(self._layout) is not None:
            return ServiceState.RUNNING
        return ServiceState.DEGRADED if has_background else ServiceState.STARTING

    def handle(self, meta: LidarFrameMeta, points: F32, taken_s: float) -> DetectionBatch | None:
        """Process one decoded frame.

        Parameters
        ----------
        meta
            The frame's metadata (validated by the codec).
        points
            ``(num_points, 4)`` float32 x, y, z [m] (sensor frame), intensity; not modified.
        taken_s
            ``time.monotonic()`` when the frame was taken from the queue (for ``latency_s``).

        Returns
        -------
        DetectionBatch or None
            None while learning the background, or for a frame that cannot be used (reported).
        """
        if meta.source_id != self.mount.sensor_id or meta.site != self.site_id:
            self.report(
                "wrong_sensor",
                f"frame of {meta.site}/{meta.source_id} on the key of "
                f"{self.site_id}/{self.mount.sensor_id}",
            )
            return None
        frame = self._point_frame(meta, points)
        if frame is None:
            return None
        self.last_stamp_s = max(self.last_stamp_s, meta.stamp)
        state_before = self.calibration.log.state
        if self.calibrating:
            self.calibration.observe_frame(frame.points[:, :3], meta.stamp)
        layout = layout_of(frame)
        if self._layout is not None and layout != self._layout:
            self.report(
                "shape_change",
                f"frame {meta.frame_index} is {describe(layout)}, the previous one was "
                f"{describe(self._layout)}",
            )
            log.warning(
                "the frame layout changed from %s to %s",
                describe(self._layout),
                describe(layout),
                extra={"sensor": self.mount.sensor_id},
            )
        if self._layout != layout:
            self._clock = None
        self._layout = layout
        if self._clock is None and meta.organized and meta.sweep_duration_s > 0:
            self._clock = ColumnClock(frame, meta.sweep_duration_s)
        try:
            result = self._detect(frame, layout)
        except Exception as exc:  # a core that fails on one frame must not stop the node
            self.report("detector_error", repr(exc))
            if "detector_error" not in self._logged:
                self._logged.add("detector_error")
                log.exception("the detector failed on frame %d; going on", meta.frame_index)
            return None
        if result is None:
            return None
        if self.calibrating and result.detections:
            self.calibration.observe_boxes(
                np.array([box.center_xyz_m for box in result.detections]), meta.stamp
            )
        bumped = self.calibration.log.state == CalibrationState.BUMPED
        if bumped and state_before != CalibrationState.BUMPED:
            self._relearn_background(self.calibration.log.detail)
        detections = self._site_detections(result)
        return DetectionBatch(
            site=self.site_id,
            source_id=self.mount.sensor_id,
            stamp=meta.stamp,
            frame_index=meta.frame_index,
            detections=detections,
            latency_s=max(0.0, time.monotonic() - taken_s),
        )

    def _relearn_background(self, why: str) -> None:
        """A knocked sensor sees its background turned: the drums, the signs and the barrier
        would come out as vehicles. Learn it again from the next frames (fast path)."""
        if self.reference is not None:
            return
        log.warning(
            "the sensor was moved (%s): learning its background again",
            why,
            extra={"sensor": self.mount.sensor_id},
        )
        self.backgrounds = BackgroundLearner(
            self.settings.model_copy(update={"background_file": None})
        )

    def _point_frame(self, meta: LidarFrameMeta, points: F32) -> PointFrame | None:
        """A clean copy of the frame: corrupt points set to no return; None if none is left."""
        cloud = np.array(points, dtype=np.float32, copy=True).reshape(-1, 4)
        # The codec has checked an organized frame's rows x columns; an unorganized one may
        # still claim beams it does not have.
        if not meta.organized and meta.rows > 1 and meta.rows * meta.columns != len(cloud):
            self.report(
                "wrong_shape",
                f"frame {meta.frame_index}: {meta.rows}x{meta.columns} slots but {len(cloud)} "
                "points; processed as unorganized",
            )
        rows, columns = (meta.rows, meta.columns) if meta.organized else (1, len(cloud))
        # Column by column: numpy's reductions along a row of three are several times slower
        # than three passes over the columns (7 ms against 1 ms for a 131,072-slot frame).
        x, y, z = cloud[:, 0], cloud[:, 1], cloud[:, 2]
        limit = self.settings.max_abs_coordinate_m
        with np.errstate(invalid="ignore"):
            finite = np.isfinite(x) & np.isfinite(y) & np.isfinite(z)
            far = (np.abs(x) > limit) | (np.abs(y) > limit) | (np.abs(z) > limit)
            all_nan = np.isnan(x) & np.isnan(y) & np.isnan(z)
            absurd = (finite & far) | (~finite & ~all_nan)
        if absurd.any():
            self.report(
                "absurd_coordinates",
                f"frame {meta.frame_index}: {int(absurd.sum())} points beyond "
                f"{self.settings.max_abs_coordinate_m:g} m or not finite, set to no return",
            )
            cloud[absurd, :3] = np.nan
            finite &= ~absurd
        if not finite.any():
            self.report("no_returns", f"frame {meta.frame_index} has no valid point")
            return None
        return PointFrame(points=cloud, rows=rows, columns=columns, stamp_s=meta.stamp)

    def _detect(self, frame: PointFrame, layout: Layout) -> DetectionResult | None:
        if self.reference is not None:
            return self.reference.detect(frame)
        pipeline = self.backgrounds.pipeline(layout)
        if pipeline is None:
            self.backgrounds.learn(frame)
            return None
        self.backgrounds.refine(frame, layout, pipeline)
        return pipeline.detect(frame)

    def _near_field(self, box: BoxDetection) -> BoxDetection:
        """Widen the covariance when the vehicle is too near for the beams to see it whole.

        Under a mast the lowest beam meets a vehicle's top only beyond ``h / tan(-e_min)`` (6 m
        and -30 deg: 10.4 m); nearer, the returns are a slice of its roof and side and the box
        completed from them slides along the vehicle: a metre and more, measured. Within that
        reach plus the box's half length, the std along the length grows to
        ``settings.near_field_std_m``, and across it to ``settings.near_field_across_std_m``
        (which side is seen changes as the vehicle passes under: measured, 0.5 m lateral RMSE
        with errors to 2.5 m). A box completed from its far end (cut by the field of view) is
        widened too: its centre no longer stands on the cut edge, but deep in the cone what is
        seen of the far end is a slice as well (errors of a metre measured at 3-4 m from the
        mast), and without the widening the fused speed just past the mast was worse (default
        site, seed 10400: RMSE 5-10 m past the mast 2.1 m/s against 0.42 m/s with it).
        """
        intrinsics = self.mount.intrinsics
        if not isinstance(intrinsics, LidarIntrinsics) or intrinsics.vertical_min_deg >= 0:
            return box
        height_m = self.mount.pose.z_m
        reach_m = height_m / math.tan(math.radians(-intrinsics.vertical_min_deg))
        distance_m = math.hypot(box.center_xyz_m[0], box.center_xyz_m[1])
        if distance_m > reach_m + 0.5 * box.size_lwh_m[0]:
            return box
        along = np.array([math.cos(box.heading_rad), math.sin(box.heading_rad)])
        across = np.array([-along[1], along[0]])
        covariance = (
            np.asarray(box.covariance_xy_m2, dtype=np.float64)
            + self.settings.near_field_std_m**2 * np.outer(along, along)
            + self.settings.near_field_across_std_m**2 * np.outer(across, across)
        )
        return dataclasses.replace(
            box,
            covariance_xy_m2=(
                (float(covariance[0, 0]), float(covariance[0, 1])),
                (float(covariance[1, 0]), float(covariance[1, 1])),
            ),
        )

    def _site_detections(self, result: DetectionResult) -> list[Detection]:
        offsets: list[float | None] = [None] * len(result.detections)
        if self._clock is not None and result.detections:
            centres = np.array([box.center_xyz_m[:2] for box in result.detections])
            offsets = [float(v) for v in self._clock.offsets_s(centres[:, 0], centres[:, 1])]
        detections = []
        pose = self.calibration.pose
        yaw_std = self.calibration.yaw_std_rad if self.calibrating else 0.0
        for box, offset in zip(result.detections, offsets, strict=True):
            try:
                box = self._near_field(box)
                if yaw_std > 0.0:
                    box = _with_angle_uncertainty(box, yaw_std)
                detection = to_detection(box_to_site(box, pose))
                if offset is not None:
                    detection = detection.model_copy(update={"time_offset_s": round(offset, 6)})
                detections.append(detection)
            except (ValidationError, ValueError) as exc:
                self.report("bad_detection", f"{box}: {exc}")
        return detections


def run(
    runtime: ServiceRuntime,
    site_id: str,
    mount: SensorMount,
    settings: LidarDetectorSettings,
    clock: SimClock,
    site: Site | None = None,
) -> int:
    """Build the detector on the runtime's bus and take frames until ``runtime.stop``.

    ``clock`` follows the newest frame's stamp (the status messages' time: simulation time in
    simulation). With ``site``, the sensor learns its pose from the site's road and publishes
    it on ``calibration/<sensor>`` on each change of state and every
    :data:`CALIBRATION_PERIOD_S` of sensor time. Returns the number of frames processed.
    """
    bus = runtime.bus
    raw_key = bus.keys.raw_lidar(mount.sensor_id)
    detector = LidarDetector(
        site_id,
        mount,
        settings,
        report=lambda reason, detail: bus.stats.count_invalid(raw_key, reason, detail),
        site=site,
    )
    if settings.path == "fast" and settings.background_file is not None:
        detector.backgrounds.load(settings.background_file)
    frames = bus.subscribe_frames(raw_key, LidarFrameMeta)  # a ring of one: latest wins
    publisher = bus.publisher(bus.keys.detections(mount.sensor_id), DetectionBatch)
    calibration = bus.publisher(bus.keys.calibration(mount.sensor_id), SensorCalibration)
    log.info("detecting on %s with the %s path", raw_key, settings.path)
    processed = 0
    calibration_sent_s = -math.inf
    runtime.state = detector.state
    while not runtime.stop.is_set():
        frame: Frame[LidarFrameMeta] | None = frames.recv(0.25)
        runtime.beat(processed=frame is not None)
        if frame is None:
            continue
        taken_s = time.monotonic()
        batch = detector.handle(frame.meta, frame.points(), taken_s)
        runtime.state = detector.state
        clock.advance_to(detector.last_stamp_s)
        if batch is not None:
            publisher.put(batch)
            processed += 1
        own = detector.calibration
        if detector.calibrating and (
            own.log.changed or detector.last_stamp_s >= calibration_sent_s + CALIBRATION_PERIOD_S
        ):
            if own.log.changed:
                log.info(
                    "calibration of %s: %s (%s)", mount.sensor_id, own.log.state, own.log.detail
                )
            calibration.put(own.message())
            calibration_sent_s = detector.last_stamp_s
    return processed


#: Seconds of sensor time between two calibration messages of an unchanged state [s].
CALIBRATION_PERIOD_S = 5.0


def _with_angle_uncertainty(box: BoxDetection, angle_std_rad: float) -> BoxDetection:
    """``box`` with the covariance a yaw known to ``angle_std_rad`` adds (sensor frame: the
    sensor at the origin), :func:`wz_shared.self_calibration.angular_covariance`."""
    extra = angular_covariance((0.0, 0.0), np.array([box.center_xyz_m[:2]]), angle_std_rad)[0]
    covariance = np.asarray(box.covariance_xy_m2, dtype=np.float64) + extra
    return dataclasses.replace(
        box,
        covariance_xy_m2=(
            (float(covariance[0, 0]), float(covariance[0, 1])),
            (float(covariance[1, 0]), float(covariance[1, 1])),
        ),
    )


def road_heading_in_sensor_frame(site: Site, mount: SensorMount) -> float:
    """Direction of travel at the sensor's station, as a heading in the sensor frame [rad].

    Traffic on a roadside sensor's road moves along the road: the fast path's box fit searches
    headings near this one.
    """
    pose = mount.pose
    station, _ = site.road_frame.to_road(pose.x_m, pose.y_m)
    road = float(site.road_frame.heading_at(station))
    direction_sensor = pose.rotation().T @ np.array([math.cos(road), math.sin(road), 0.0])
    return float(math.atan2(direction_sensor[1], direction_sensor[0]))


def fitted_to_mount(
    settings: LidarDetectorSettings, site: Site | None, mount: SensorMount
) -> LidarDetectorSettings:
    """The fast path's settings for this sensor on this site, where not set by hand: the
    box fit's heading prior from the road (:func:`road_heading_in_sensor_frame`), and its beam
    spacing and angular resolution from the site file's LiDAR (``vertical_max - vertical_min``
    over ``beams - 1``, and 360 deg over ``azimuth_steps``).

    The beam spacing sets how much of a far vehicle's height may hide above its highest
    return: a 32-beam LiDAR's 1.3 deg, taken as a 64-beam one's 0.65, let a semitrailer 80 m
    off, 1.7 m of its front seen, be completed as a car with a tight covariance: its box 6 m
    ahead of it, a second track on the approach (generated site 9401).
    """
    fast, box = settings.fast, settings.fast.box
    box_updates: dict[str, float] = {}
    intrinsics = mount.intrinsics
    if isinstance(intrinsics, LidarIntrinsics):
        if "beam_spacing_deg" not in box.model_fields_set and intrinsics.beams > 1:
            box_updates["beam_spacing_deg"] = (
                intrinsics.vertical_max_deg - intrinsics.vertical_min_deg
            ) / (intrinsics.beams - 1)
        if "angular_resolution_deg" not in box.model_fields_set:
            box_updates["angular_resolution_deg"] = 360.0 / intrinsics.azimuth_steps
    fast_updates: dict[str, object] = {}
    if box_updates:
        fast_updates["box"] = box.model_copy(update=box_updates)
    if fast.heading_prior_rad is None and site is not None:
        fast_updates["heading_prior_rad"] = road_heading_in_sensor_frame(site, mount)
    if not fast_updates:
        return settings
    return settings.model_copy(update={"fast": fast.model_copy(update=fast_updates)})


def main() -> None:
    node = NodeApp(SERVICE, LidarDetectorSettings)
    site = node.read_site()
    with node.fatal(ValueError):
        mount = lidar_mount(site, node.settings.sensor_id)
    node.start_logging(site.site_id, sensor=mount.sensor_id)
    settings = fitted_to_mount(node.settings, site, mount)
    box = settings.fast.box
    log.info(
        "from the site file: heading prior %.1f deg in the sensor frame, beams %.2f deg apart, "
        "columns %.2f deg apart",
        math.degrees(settings.fast.heading_prior_rad or 0.0),
        box.beam_spacing_deg,
        box.angular_resolution_deg,
    )
    processed = node.serve(
        lambda runtime: run(runtime, site.site_id, mount, settings, node.clock, site)
    )
    log.info("stopped after %d frames", processed)


if __name__ == "__main__":
    main()
