"""The camera-radar detector node: camera frames (and radar scans) in, site-frame detections out.

Run it as ``python -m wz_camera_detector.node``. Settings come from the environment
(``WZ_CAMERA_*`` for the detector, ``WZ_BUS_*`` for the bus; see
:mod:`wz_camera_detector.settings`). It

- takes frames from ``wz/<site>/raw/camera/<camera>`` through a ring of ``frame_queue`` frames
  (the newest kept; frames a slow detector had no time for are counted as dropped by the
  bus), and keeps the newest scan of ``wz/<site>/raw/radar/<radar>`` (a ring of one);
- per frame: decodes the JPEG (``cv2.imdecode``), detects boxes with the backend
  (background subtraction, or a local YOLOv8 ONNX model) on the frames it is due on
  (``detection_period_s``: each frame of a 10 fps camera, every fourth of a 30 fps one;
  the others are decoded grey only), follows the boxes of the previous frame by optical flow
  (:class:`~wz_camera_detector.flow.BoxFlow`), tracks them in the image
  (:class:`ImageTracker`: detections where the detector ran, flow's boxes for the tracks
  they did not update), puts each box on the road (:func:`fit_boxes_to_ground`: the class's
  typical shape, :data:`CLASS_SHAPES`, on the site road's heading at the box's ground point,
  placed so that its image box has the box's left, right and bottom edges),
  gives it the camera covariance (below), and fuses with the newest radar scan when its stamp
  is within ``radar_max_age_s`` of the frame's (:func:`fuse_camera_radar`, speeds along the
  road heading at the mast);
- publishes one :class:`DetectionBatch` per processed frame on
  ``wz/<site>/detections/<camera>`` (site frame, ``stamp`` and ``frame_index`` of the frame,
  ``source_id`` the camera, ``latency_s`` from taking the frame to publishing);
- reports health on ``wz/<site>/status/camera-detector``; ``state`` is ``starting`` while the
  background backend learns the empty road (its warm-up; nothing is published then).

Camera covariance. A box's column gives a precise bearing, its bottom row a poor range (flat
road, pitch, the assumed vehicle size), so the covariance is built in the camera's line of
sight ``u`` (horizontal, camera to object) and its normal ``n``, with ``r`` the horizontal
range [m]::

    sigma_lat = lateral_std_m + lateral_std_per_m * r      (0.15 m + 0.0025 r)
                + near_lateral_std_m * max(0, 1 - r / near_range_m)   (1.3 m, 25 m)
    sigma_los = range_std_m + range_std_per_m * r          (1.0 m + 0.03 r)
    P = sigma_los^2 u u^T + sigma_lat^2 n n^T              [m^2]

Bad input never stops it. Each problem is counted in the status message's ``invalid_counts``
under ``<raw camera key>|<reason>`` (the bus's own decode reasons such as ``bad_magic`` or
``bad_jpeg`` come first):

- ``bad_image``: the JPEG does not decode (the frame is skipped);
- ``wrong_size``: the image is not the size its metadata says, is not the camera's picture
  (another aspect ratio than its calibration: a frame of the same aspect, scaled, is ranged
  with the intrinsics scaled), or does not contain a region of interest set in the settings
  (skipped);
- ``wrong_sensor``: the metadata names another camera or site;
- ``out_of_order``: the stamp is not after the previous frame's (skipped). When the stamps
  go back for good (:class:`~wz_shared.timebase.RunWatch`: a restarted simulation counts from
  its start again), a new run starts instead: the image tracker (its ids go on) and the radar
  scan start again, and the frame is processed;
- ``detector_error``: the backend raised (traceback logged once);
- ``above_horizon``: a box whose bottom is at or above the horizon (dropped);

A box cut by the edge of the detector's view (its region of interest, else the frame) is tracked
in the image but not ranged: its bottom edge is not where the vehicle meets the road, nor its
middle column the vehicle's bearing (a vehicle passing under the mast; the LiDAR sees it).
- ``bad_detection``: a detection with non-finite values (dropped).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np
from pydantic import ValidationError

from wz_camera_detector.association import (
    CameraObject,
    FusedObject,
    camera_only,
    fuse_camera_radar,
    to_detection,
)
from wz_camera_detector.background import BACKEND, BackgroundSubtractionDetector
from wz_camera_detector.calibration import CameraSelfCalibration
from wz_camera_detector.following import (
    DetectAndFollow,
    ImageBackend,
    cut_by_view,
)
from wz_camera_detector.radar_calibration import RadarSelfCalibration
from wz_camera_detector.regions import detector_regions
from wz_camera_detector.settings import (
    CameraDetectorSettings,
    camera_mount,
    radar_mount,
    shipped_model,
)
from wz_camera_detector.tracker import ImageTrack
from wz_camera_detector.world import VehicleShape, box_to_ground, fit_boxes_to_ground
from wz_camera_detector.yolo import (
    Box,
    ImageDetection,
    ModelLoadError,
    RegionsForSize,
    YoloOnnxDetector,
)
from wz_shared.arrays import F64, U8
from wz_shared.camera_calibration import CalibrationError
from wz_shared.camera_geometry import PinholeCamera, camera_at_size, camera_intrinsics
from wz_shared.codec import Frame
from wz_shared.messages import (
    CalibrationState,
    CameraFrameMeta,
    Detection,
    DetectionBatch,
    RadarScan,
    SensorCalibration,
    ServiceState,
    VehicleClass,
)
from wz_shared.service import NodeApp, ServiceRuntime
from wz_shared.site import SensorMount, Site
from wz_shared.timebase import RunWatch, SimClock

SERVICE = "camera-detector"
log = logging.getLogger("wz_camera_detector.node")

#: How a problem is reported: (reason, detail).
Report = Callable[[str, str], None]

#: Seconds of sensor time between two calibration messages of an unchanged state [s].
CALIBRATION_PERIOD_S = 5.0

#: A detector box scoring below this is not a calibration target (a false box would be paired
#: with a LiDAR object now and then).
CALIBRATION_MIN_SCORE = 0.5

#: (yaw, pitch) [deg] the detector's regions allow for while the camera's pose is not known:
#: what a technician's compass and level leave at most (issue 39), or a knocked camera.
SETUP_MARGIN_DEG = (3.0, 1.5)
#: ... once it is calibrated: the mast's sway and what the calibration may still be off.
CALIBRATED_MARGIN_DEG = (0.2, 0.2)
#: ... while it is learned: this many of the fit's standard deviations (between the two above).
LEARNING_MARGIN_SIGMAS = 3.0
#: The regions are drawn again when the pose they were drawn for is this far off [deg].
REGIONS_REDRAW_DEG = 0.1

#: A passenger car: 4.6 x 1.8 x 1.5 m, its bumpers 0.28 m up, the front wheels' foot about
#: half a metre behind the bumper (a 0.85 m overhang less a 0.32 m tyre radius).
CAR_SHAPE = VehicleShape(4.6, 1.8, 1.5, clearance_m=0.28, wheel_inset_m=0.53)
#: Image class name -> (bus class, typical shape); other names are ignored. A tractor-
#: semitrailer's bumper is about 0.5 m up, its steer axle's tyres 0.3 m behind it.
CLASS_SHAPES: dict[str, tuple[VehicleClass, VehicleShape]] = {
    "car": (VehicleClass.CAR, CAR_SHAPE),
    # The background backend cannot classify: a car-sized guess, class unknown.
    "vehicle": (VehicleClass.UNKNOWN, CAR_SHAPE),
    "truck": (VehicleClass.TRUCK, VehicleShape(16.5, 2.6, 4.0, clearance_m=0.5, wheel_inset_m=0.3)),
    "bus": (VehicleClass.BUS, VehicleShape(12.0, 2.55, 3.2, clearance_m=0.35, wheel_inset_m=0.6)),
    "motorcycle": (VehicleClass.MOTORCYCLE, VehicleShape(2.2, 0.8, 1.4)),
}


@dataclass(frozen=True)
class FrameResult:
    """What one frame gave: the published image tracks, their ground positions (camera only,
    by ``local_id``), and the objects after radar fusion."""

    tracks: list[ImageTrack]
    camera_objects: list[CameraObject]
    fused: list[FusedObject]
    #: The frame's capture time on the LiDAR's clock: its stamp less the camera's learned
    #: clock offset [s].
    stamp_s: float = 0.0


def fog_contrast(settings: CameraDetectorSettings, rendered: bool) -> bool:
    """Whether flat frames (fog, haze) get local contrast before the model
    (``settings.fog_contrast``: ``auto`` for the shipped real-camera model only)."""
    if settings.fog_contrast == "auto":
        return settings.model_path is None and not rendered
    return settings.fog_contrast == "on"


def make_backend(
    settings: CameraDetectorSettings,
    site: Site | None = None,
    camera: SensorMount | None = None,
    rendered: bool = False,
    margin_deg: tuple[float, float] = SETUP_MARGIN_DEG,
) -> ImageBackend:
    """The image detector the settings name.

    With ``site`` and ``camera``, YOLO looks at the region of interest and far-field tiles the
    road's geometry gives (:func:`~wz_camera_detector.regions.detector_regions`, for any aim
    within ``margin_deg`` of yaw and pitch of the camera's pose), unless the settings give
    their own; without them, at the model's metadata regions, else the frame.
    Without a model in the settings: the shipped one for real frames, or for the simulator's
    ``rendered`` ones (:func:`~wz_camera_detector.settings.shipped_model`).

    Raises
    ------
    ModelLoadError
        ``yolo`` with a model that is missing, unreadable or not a YOLOv8 or NanoDet model
        (never a download).
    """
    if settings.backend == BACKEND:
        return BackgroundSubtractionDetector(settings.background)
    detector = YoloOnnxDetector(
        settings.model_path if settings.model_path is not None else shipped_model(rendered),
        settings.class_names,
        conf_threshold=settings.conf_threshold,
        roi_xyxy_px=settings.roi_xyxy_px,
        tiles_xyxy_px=settings.tiles_xyxy_px,
        threads=settings.onnx_threads,
        flat_below=settings.flat_below if fog_contrast(settings, rendered) else None,
    )
    if site is not None and camera is not None:
        intrinsics = camera_intrinsics(camera)
        detector.follow_frame_size(
            _geometry_regions(settings, site, camera, detector, margin_deg),
            (intrinsics.width_px, intrinsics.height_px),
        )
    return detector


def _geometry_regions(
    settings: CameraDetectorSettings,
    site: Site,
    camera: SensorMount,
    detector: YoloOnnxDetector,
    margin_deg: tuple[float, float],
) -> RegionsForSize:
    """Where YOLO looks in frames of each size: the settings' ROI and tiles where given, the
    road's geometry (:func:`~wz_camera_detector.regions.detector_regions`) otherwise."""

    def regions_for(width_px: int, height_px: int) -> tuple[Box | None, tuple[Box, ...]]:
        regions = detector_regions(
            site,
            camera,
            max(detector.input_size),
            width_px=width_px,
            height_px=height_px,
            margin_deg=margin_deg,
        )
        roi = settings.roi_xyxy_px if settings.roi_xyxy_px is not None else regions.roi_xyxy_px
        tiles = (
            settings.tiles_xyxy_px if settings.tiles_xyxy_px is not None else regions.tiles_xyxy_px
        )
        log.info(
            "camera %s, %dx%d frames: detector ROI %s, far-field tiles %s (from %s)",
            camera.sensor_id,
            width_px,
            height_px,
            roi,
            list(tiles),
            "the settings"
            if settings.roi_xyxy_px is not None
            else f"the road's geometry, +-{margin_deg[0]:.2f} deg yaw, +-{margin_deg[1]:.2f} deg pitch",
        )
        return roi, tiles

    return regions_for


def road_heading_at(site: Site, x_m: float, y_m: float) -> float:
    """The site road's heading at the point's station [rad], CCW from east."""
    return site.road_frame.heading_at_point(x_m, y_m)


def camera_covariance(
    camera_xy_m: tuple[float, float],
    object_xy_m: tuple[float, float],
    settings: CameraDetectorSettings,
) -> F64:
    """``sigma_los^2 u u^T + sigma_lat^2 n n^T`` [m^2], shape (2, 2) (module docstring)."""
    dx, dy = object_xy_m[0] - camera_xy_m[0], object_xy_m[1] - camera_xy_m[1]
    range_m = math.hypot(dx, dy)
    bearing = math.atan2(dy, dx)
    u = np.array([math.cos(bearing), math.sin(bearing)])
    n = np.array([-u[1], u[0]])
    lateral = (
        settings.lateral_std_m
        + settings.lateral_std_per_m * range_m
        + settings.near_lateral_std_m * max(0.0, 1.0 - range_m / settings.near_range_m)
    )
    along = settings.range_std_m + settings.range_std_per_m * range_m
    covariance: F64 = along**2 * np.outer(u, u) + lateral**2 * np.outer(n, n)
    return covariance


class CameraDetector:
    """What the node does with one frame, without the bus: decode, detect, track, range, fuse.

    Parameters
    ----------
    site
        The site (its id, and its road for headings).
    camera
        The camera's mount; frames of another size than its intrinsics (the same picture,
        scaled) are ranged with its intrinsics scaled to their size; frames of another aspect
        ratio are refused (``wrong_size``).
    radar
        The radar's mount, None for camera-only detections.
    settings
        The service's settings.
    report
        Called with ``(reason, detail)`` for every problem.
    backend
        The image detector; default :func:`make_backend` (which may raise
        :class:`ModelLoadError`): with no model in the settings, the shipped model for the
        frames, switched when the frames' ``rendered`` flag says they come from the simulator
        (or, for :meth:`process_image` callers, ``rendered``).
    rendered
        The frames are the simulator's renders (the default backend's first model).
    """

    def __init__(
        self,
        site: Site,
        camera: SensorMount,
        radar: SensorMount | None,
        settings: CameraDetectorSettings,
        report: Report,
        backend: ImageBackend | None = None,
        rendered: bool = False,
    ) -> None:
        self.site = site
        self.camera_mount = camera
        self.radar_mount = radar
        self.settings = settings
        self.report = report
        #: Whether the backend follows the frames' source (the shipped models, by default).
        self._follows_source = backend is None and settings.model_path is None
        self._rendered = rendered
        #: Detect where due, follow between, track (:mod:`wz_camera_detector.following`).
        self.images = DetectAndFollow(
            backend if backend is not None else make_backend(settings, site, camera, rendered),
            settings,
            frozenset(CLASS_SHAPES),
        )
        #: The shipped models loaded so far, by ``rendered`` (each is loaded once).
        self._shipped: dict[bool, ImageBackend] = {rendered: self.backend}
        #: Whether this node draws its backends' regions from the road's geometry (a backend
        #: given to it keeps its own), and the (yaw, pitch, margin) they were drawn for.
        self._draws_regions = backend is None
        self._regions_drawn: tuple[float, float, tuple[float, float]] | None = (
            camera.pose.yaw_deg,
            camera.pose.pitch_deg,
            SETUP_MARGIN_DEG,
        )
        self._cameras: dict[tuple[int, int], PinholeCamera] = {}
        self._radar_heading = (
            road_heading_at(site, radar.pose.x_m, radar.pose.y_m) if radar is not None else None
        )
        #: The camera's pose and clock learned against the LiDAR's vehicles, and the radar's
        #: (:mod:`wz_camera_detector.calibration`); fed by :meth:`lidar_batch`.
        shapes = {str(bus_class): shape for bus_class, shape in CLASS_SHAPES.values()}
        self.calibration = CameraSelfCalibration(site.site_id, camera, shapes, settings.calibration)
        self.radar_calibration = (
            RadarSelfCalibration(
                site.site_id,
                radar,
                settings.calibration,
                self.calibration.reference,
                settings.association.target_height_m,
            )
            if radar is not None
            else None
        )
        self._scan: RadarScan | None = None
        self._logged: set[str] = set()
        self._frames_taken = 0
        #: Stamp of the newest frame taken [s] (the node's clock on simulation time).
        self.last_stamp_s = 0.0
        self._run = RunWatch()
        #: Runs seen: 1, then one more each time the frames' stamps start again.
        self.runs = 1

    @property
    def backend(self) -> ImageBackend:
        """The image detector in use."""
        return self.images.backend

    @property
    def detections_run(self) -> int:
        """How many frames the detector has run on (the others were followed by flow)."""
        return self.images.detections_run

    @property
    def state(self) -> ServiceState:
        """``starting`` while the background backend warms up; ``degraded`` while the camera
        or the radar is flagged as knocked (its pose being learned again); else
        ``running``."""
        backend = self.backend
        if isinstance(backend, BackgroundSubtractionDetector) and not backend.warmed_up:
            return ServiceState.STARTING
        owners = [self.calibration, self.radar_calibration]
        if any(o is not None and o.log.state == CalibrationState.BUMPED for o in owners):
            return ServiceState.DEGRADED
        return ServiceState.RUNNING

    def radar_scan(self, scan: RadarScan) -> None:
        """Keep ``scan`` if it is the newest seen (by stamp), on the LiDAR's clock (the radar's
        learned clock offset taken off its stamp)."""
        if self.radar_mount is None or scan.source_id != self.radar_mount.sensor_id:
            return
        own = self.radar_calibration
        if own is not None and own.settings.enabled:
            own.observe(scan)
            if own.pose != self.radar_mount.pose:
                self.radar_mount = self.radar_mount.model_copy(update={"pose": own.pose})
            if own.clock_offset_s:
                scan = scan.model_copy(update={"stamp": max(0.0, scan.stamp - own.clock_offset_s)})
        if self._scan is None or scan.stamp >= self._scan.stamp:
            self._scan = scan

    def lidar_batch(self, batch: DetectionBatch) -> None:
        """The LiDAR's detections (site frame): what the camera and the radar calibrate
        against."""
        if not self.settings.calibration.enabled:
            return
        self.calibration.add_reference(batch)
        if self.radar_calibration is not None:
            self.radar_calibration.pair_pending()

    @property
    def clock_offset_s(self) -> float:
        """The camera's learned clock offset [s]: its stamps are this late."""
        return self.calibration.clock_offset_s if self.settings.calibration.enabled else 0.0

    def camera(self, width_px: int, height_px: int) -> PinholeCamera:
        """The pinhole model at a frame's size (the mount's, scaled; CalibrationError for
        another aspect ratio)."""
        camera = self._cameras.get((width_px, height_px))
        if camera is None:
            camera = self._cameras[(width_px, height_px)] = camera_at_size(
                self.camera_mount, width_px, height_px
            )
        return camera

    def handle(
        self, meta: CameraFrameMeta, jpeg: bytes | memoryview, taken_s: float
    ) -> DetectionBatch | None:
        """Process one frame.

        Parameters
        ----------
        meta
            The frame's metadata (validated by the codec).
        jpeg
            The JPEG payload.
        taken_s
            ``time.monotonic()`` when the frame was taken from the queue (for ``latency_s``).

        Returns
        -------
        DetectionBatch or None
            None during the background warm-up, or for a frame that cannot be used (reported).
        """
        if meta.source_id != self.camera_mount.sensor_id or meta.site != self.site.site_id:
            self.report(
                "wrong_sensor",
                f"frame of {meta.site}/{meta.source_id} on the key of "
                f"{self.site.site_id}/{self.camera_mount.sensor_id}",
            )
            return None
        detect = self.images.due(meta.stamp)
        image = _decode_jpeg(jpeg, gray=not detect)
        if image is None:
            self.report("bad_image", f"frame {meta.frame_index}: the JPEG does not decode")
            return None
        height, width = image.shape[:2]
        if (width, height) != (meta.width_px, meta.height_px):
            self.report(
                "wrong_size",
                f"frame {meta.frame_index}: image {width}x{height}, metadata "
                f"{meta.width_px}x{meta.height_px}",
            )
            return None
        try:
            self.camera(width, height)
        except CalibrationError as exc:  # another aspect ratio: not this camera's picture
            self.report("wrong_size", f"frame {meta.frame_index}: {exc}")
            return None
        roi = self.settings.roi_xyxy_px
        if roi is not None and (roi[2] > width or roi[3] > height):
            self.report(
                "wrong_size",
                f"frame {meta.frame_index}: image {width}x{height} does not contain the ROI "
                f"{roi} of the settings",
            )
            return None
        if self._follows_source and meta.rendered != self._rendered:
            self._switch_model(meta.rendered)
        new_run = self._run.observe(meta.stamp) == "new_run"
        if new_run:
            self._start_new_run(meta.stamp)
        elif self._frames_taken and meta.stamp <= self.last_stamp_s:
            self.report(
                "out_of_order",
                f"frame {meta.frame_index} stamp {meta.stamp:.6f} s is not after "
                f"{self.last_stamp_s:.6f} s",
            )
            return None
        self.last_stamp_s = meta.stamp
        self._frames_taken += 1
        result = self.process_image(image, meta.stamp, meta.frame_index, detect=detect)
        if result is None:
            return None
        return DetectionBatch(
            site=self.site.site_id,
            source_id=self.camera_mount.sensor_id,
            stamp=result.stamp_s,
            frame_index=meta.frame_index,
            detections=self._detections(result.fused),
            latency_s=max(0.0, time.monotonic() - taken_s),
        )

    def _switch_model(self, rendered: bool) -> None:
        """Take the shipped model for the simulator's renders, or for a real camera's frames
        (loaded at the first such frame, kept: a source that keeps switching costs no loads)."""
        log.info(
            "camera %s: %s frames: the detector takes %s",
            self.camera_mount.sensor_id,
            "the simulator's rendered" if rendered else "real camera",
            shipped_model(rendered).name,
        )
        if rendered not in self._shipped:
            self._shipped[rendered] = make_backend(
                self.settings, self.site, self.camera_mount, rendered, self._regions_margin_deg()
            )
        self.images.backend = self._shipped[rendered]
        self._regions_drawn = None  # drawn again at its next frame, for the pose of then
        self._rendered = rendered
        self.images.restart()

    def _start_new_run(self, stamp_s: float) -> None:
        log.warning(
            "frame stamps went back from %.3f s to %.3f s: a new run (a restarted simulation); "
            "the image tracker and the radar scan start again",
            self.last_stamp_s,
            stamp_s,
        )
        self.images.restart()
        self._scan = None
        self.runs += 1

    def process_frame(
        self, jpeg: bytes | memoryview, stamp_s: float, frame_index: int
    ) -> FrameResult | None:
        """What :meth:`handle` does with a frame whose metadata holds (in stamp order): the
        JPEG decoded in colour where the detector is due and grey elsewhere, then
        :meth:`process_image`. For evaluations that run the node's per-frame work in process.
        """
        detect = self.images.due(stamp_s)
        image = _decode_jpeg(jpeg, gray=not detect)
        if image is None:
            self.report("bad_image", f"frame {frame_index}: the JPEG does not decode")
            return None
        self.last_stamp_s = stamp_s
        self._frames_taken += 1
        return self.process_image(image, stamp_s, frame_index, detect=detect)

    def process_image(
        self, image: U8, stamp_s: float, frame_index: int, detect: bool = True
    ) -> FrameResult | None:
        """Detect (``detect``), follow, track, range and fuse one decoded frame (no checks on
        the frame's order).

        ``image``: BGR (H, W, 3), or grey (H, W) on a frame the detector skips (``detect``
        False: the tracks are followed by optical flow only).
        Returns None during the background warm-up or when the backend fails (reported).
        """
        warming_up = self.state == ServiceState.STARTING  # this frame still only teaches
        try:
            if warming_up:
                self.images.detect(image)
                return None
            step = self.images.step(image, stamp_s, detect)
        except Exception as exc:  # a backend that fails on one frame must not stop the node
            self.report("detector_error", repr(exc))
            if "detector_error" not in self._logged:
                self._logged.add("detector_error")
                log.exception("the detector failed on frame %d; going on", frame_index)
            return None
        boxes = step.detections
        tracks = step.published if self.settings.confirmed_only else step.updated
        width, height = image.shape[1], image.shape[0]
        if boxes is not None:
            self._calibrate(boxes, stamp_s, width, height)
        objects = self._camera_objects(tracks, width, height, frame_index)
        stamp_s = max(0.0, stamp_s - self.clock_offset_s)  # on the LiDAR's clock from here
        if not detect and not self.settings.publish_followed:
            # A box flow carried holds its last detection's ranging error: given to the
            # fusion tracker as a measurement of its own at each frame between, the same
            # error would be counted three times over at 30 fps (settings.publish_followed).
            return FrameResult(tracks, objects, [], stamp_s)
        return FrameResult(
            tracks, objects, self._within_range(self._fuse(objects, stamp_s)), stamp_s
        )

    def _calibrate(
        self, boxes: list[ImageDetection], stamp_s: float, width: int, height: int
    ) -> None:
        """Feed the frame's whole boxes to the camera's calibration and take its pose.

        The detector's own boxes of this frame, not the image tracks' filtered ones: a filter
        lags a moving box, and the lag would be learned as a late clock.
        """
        own = self.calibration
        if not self.settings.calibration.enabled:
            return
        whole = [
            box
            for box in boxes
            if box.score >= CALIBRATION_MIN_SCORE
            and not cut_by_view(box.box_xyxy_px, self.backend, width, height)
        ]
        own.observe(
            stamp_s,
            width,
            height,
            np.array([box.box_xyxy_px for box in whole], dtype=np.float64).reshape(-1, 4),
            [str(CLASS_SHAPES[box.class_name][0]) for box in whole],
        )
        self.follow_calibration(width, height)

    def follow_calibration(self, width_px: int, height_px: int) -> None:
        """Take the camera's learned pose, and draw the detector's regions again where it and
        its margin moved the road by :data:`REGIONS_REDRAW_DEG` or more: a camera turned by a
        degree would otherwise have its far cars cut by an ROI drawn for the site file's aim
        (``width_px`` x ``height_px``: the frames')."""
        own = self.calibration
        if own.pose != self.camera_mount.pose:
            self.camera_mount = self.camera_mount.model_copy(update={"pose": own.pose})
            self._cameras.clear()
        if not self._draws_regions or not isinstance(self.backend, YoloOnnxDetector):
            return
        pose, margin = self.camera_mount.pose, self._regions_margin_deg()
        drawn = self._regions_drawn
        if (
            drawn is not None
            and drawn[2] == margin
            and abs(pose.yaw_deg - drawn[0]) < REGIONS_REDRAW_DEG
            and abs(pose.pitch_deg - drawn[1]) < REGIONS_REDRAW_DEG
        ):
            return
        self._regions_drawn = (pose.yaw_deg, pose.pitch_deg, margin)
        self.backend.follow_frame_size(
            _geometry_regions(self.settings, self.site, self.camera_mount, self.backend, margin),
            (width_px, height_px),
        )

    def _regions_margin_deg(self) -> tuple[float, float]:
        """(yaw, pitch) [deg] the detector's regions allow for now: the set-up tolerance until
        the pose is learned (or after a knock), what the fit leaves while learning (rounded up
        to a tenth), the sway once calibrated."""
        own = self.calibration
        state = own.log.state
        if not self.settings.calibration.enabled or state in (
            CalibrationState.PRIOR,
            CalibrationState.BUMPED,
        ):
            return SETUP_MARGIN_DEG
        if state == CalibrationState.CALIBRATED:
            return CALIBRATED_MARGIN_DEG
        yaw_std, pitch_std = own.angle_std_rad

        def margin(std_rad: float, low: float, high: float) -> float:
            wanted = LEARNING_MARGIN_SIGMAS * math.degrees(std_rad)
            return min(high, max(low, math.ceil(wanted * 10.0) / 10.0))

        return (
            margin(yaw_std, CALIBRATED_MARGIN_DEG[0], SETUP_MARGIN_DEG[0]),
            margin(pitch_std, CALIBRATED_MARGIN_DEG[1], SETUP_MARGIN_DEG[1]),
        )

    def _within_range(self, fused: list[FusedObject]) -> list[FusedObject]:
        """The fused objects without the camera-only ones ranged beyond ``max_range_m``.

        A box's bottom row ranges a vehicle only while the road is seen well below the horizon:
        near it a pixel is tens of metres (a far box or a false one was ranged at 320 m, where
        no sensor of the site can confirm it, and started tracks the alerts then fired on). A
        radar-paired object keeps the radar's range and is kept.
        """
        limit_m = self.settings.max_range_m
        camera_x, camera_y = self.camera_mount.pose.x_m, self.camera_mount.pose.y_m
        return [
            obj
            for obj in fused
            if obj.source != "camera"
            or math.hypot(obj.x_m - camera_x, obj.y_m - camera_y) <= limit_m
        ]

    def _camera_objects(
        self, tracks: list[ImageTrack], width_px: int, height_px: int, frame_index: int
    ) -> list[CameraObject]:
        camera = self.camera(width_px, height_px)
        camera_xy = (float(camera.position_m[0]), float(camera.position_m[1]))
        ranged: list[tuple[ImageTrack, float, float]] = []
        for track in tracks:
            if cut_by_view(track.box_xyxy_px, self.backend, width_px, height_px):
                # Its bottom is not where it meets the road, nor its middle column the
                # vehicle's bearing. Not ranged (the LiDAR sees it).
                continue
            # Heading from where the box's contact point lies (the road's direction there).
            x0, y0 = box_to_ground(camera, track.box_xyxy_px, 0.0, 0.0, 0.0)
            if not (math.isfinite(x0) and math.isfinite(y0)):
                self.report(
                    "above_horizon",
                    f"frame {frame_index}: box {track.box_xyxy_px} reaches above the horizon",
                )
                continue
            ranged.append((track, x0, y0))
        if not ranged:
            return []
        road = self.site.road_frame
        stations, _ = road.to_road(
            np.array([x for _, x, _ in ranged]), np.array([y for _, _, y in ranged])
        )
        headings = np.atleast_1d(road.heading_at(stations))
        classes = [CLASS_SHAPES[track.class_name] for track, _, _ in ranged]
        centres = fit_boxes_to_ground(
            camera,
            [track.box_xyxy_px for track, _, _ in ranged],
            headings,
            [shape for _, shape in classes],
        )
        objects: list[CameraObject] = []
        for (track, _, _), heading_rad, (object_class, shape), (x, y) in zip(
            ranged, headings, classes, centres, strict=True
        ):
            heading, x_m, y_m = float(heading_rad), float(x), float(y)
            covariance = camera_covariance(camera_xy, (x_m, y_m), self.settings)
            if self.settings.calibration.enabled:
                covariance = covariance + self._angle_covariance(camera, (x_m, y_m))
            objects.append(
                CameraObject(
                    local_id=track.local_id,
                    x_m=x_m,
                    y_m=y_m,
                    covariance_m2=covariance,
                    object_class=object_class,
                    score=track.score,
                    heading_rad=heading,
                    length_m=shape.length_m,
                    width_m=shape.width_m,
                )
            )
        return objects

    def _angle_covariance(self, camera: PinholeCamera, xy_m: tuple[float, float]) -> F64:
        """What the camera's angles' uncertainty adds at ``xy_m`` [m^2], shape (2, 2): a yaw
        known to ``s`` moves it ``r s`` across the line of sight, a pitch known to ``s`` moves
        its range ``r^2 s / h`` along it (a ray meeting the road at a grazing angle)."""
        yaw_std, pitch_std = self.calibration.angle_std_rad
        dx, dy = xy_m[0] - float(camera.position_m[0]), xy_m[1] - float(camera.position_m[1])
        range_m = max(math.hypot(dx, dy), 1.0)
        u = np.array([dx, dy]) / range_m
        n = np.array([-u[1], u[0]])
        height = max(float(camera.position_m[2]), 1.0)
        along = min(range_m * range_m * pitch_std / height, 0.5 * range_m)
        covariance: F64 = (range_m * yaw_std) ** 2 * np.outer(n, n) + along**2 * np.outer(u, u)
        return covariance

    def _fuse(self, objects: list[CameraObject], stamp_s: float) -> list[FusedObject]:
        scan = self._scan
        if (
            self.radar_mount is None
            or scan is None
            or abs(scan.stamp - stamp_s) > self.settings.radar_max_age_s
        ):
            return [camera_only(camera) for camera in objects]
        return fuse_camera_radar(
            objects,
            scan,
            self.radar_mount,
            self.settings.association,
            self._radar_heading,
            dt_s=stamp_s - scan.stamp,
        )

    def _detections(self, fused: list[FusedObject]) -> list[Detection]:
        detections = []
        for obj in fused:
            try:
                detections.append(to_detection(obj))
            except (ValidationError, ValueError) as exc:
                self.report("bad_detection", f"{obj}: {exc}")
        return detections


def _decode_jpeg(jpeg: bytes | memoryview, gray: bool = False) -> U8 | None:
    """BGR uint8 (H, W, 3), or with ``gray`` grey (H, W) (a JPEG's luma alone: a third of
    the colour decode's time); None when the bytes are not a decodable image."""
    buffer = np.frombuffer(jpeg, dtype=np.uint8)
    if buffer.size == 0:
        return None
    try:
        image = cv2.imdecode(buffer, cv2.IMREAD_GRAYSCALE if gray else cv2.IMREAD_COLOR)
    except cv2.error:
        return None
    if image is None or image.size == 0:
        return None
    if (gray and image.ndim != 2) or (not gray and (image.ndim != 3 or image.shape[2] != 3)):
        return None
    return np.asarray(image, dtype=np.uint8)


def build_detector(site: Site, settings: CameraDetectorSettings, report: Report) -> CameraDetector:
    """The detector for the settings' camera and radar; start-up problems as SystemExit.

    Raises
    ------
    SystemExit
        With a message for the operator: an unknown sensor, or a YOLO model that is missing,
        unreadable or not a YOLOv8 model (the :class:`ModelLoadError` message).
    """
    try:
        camera = camera_mount(site, settings.camera_id)
        radar = radar_mount(site, settings.radar_id)
        return CameraDetector(site, camera, radar, settings, report)
    except (ModelLoadError, ValueError) as exc:
        raise SystemExit(f"{SERVICE}: {exc}") from exc


def run(
    runtime: ServiceRuntime,
    site: Site,
    settings: CameraDetectorSettings,
    clock: SimClock,
) -> int:
    """Build the detector on the runtime's bus and take frames until ``runtime.stop``.

    Returns the number of frames processed (batches published).
    """
    bus = runtime.bus
    camera_id = camera_mount(site, settings.camera_id).sensor_id
    raw_key = bus.keys.raw_camera(camera_id)
    detector = build_detector(
        site,
        settings,
        report=lambda reason, detail: bus.stats.count_invalid(raw_key, reason, detail),
    )
    # A ring of a few frames, the newest kept: they wait while the detector runs on one.
    frames = bus.subscribe_frames(raw_key, CameraFrameMeta, capacity=settings.frame_queue)
    scans = (
        bus.subscribe(
            bus.keys.raw_radar(detector.radar_mount.sensor_id), RadarScan, mode="ring", capacity=1
        )
        if detector.radar_mount is not None
        else None
    )
    publisher = bus.publisher(bus.keys.detections(camera_id), DetectionBatch)
    # The LiDAR's detections: what the camera and the radar learn their pose and clock from.
    lidars = [mount for mount in site.sensors if mount.intrinsics.kind == "lidar"]
    references = (
        bus.subscribe(bus.keys.detections(lidars[0].sensor_id), DetectionBatch, capacity=256)
        if lidars and settings.calibration.enabled
        else None
    )
    owners = [detector.calibration]
    if detector.radar_calibration is not None:
        owners.append(detector.radar_calibration)  # type: ignore[arg-type]
    calibrations = {
        owner.mount.sensor_id: bus.publisher(
            bus.keys.calibration(owner.mount.sensor_id), SensorCalibration
        )
        for owner in owners
    }
    calibration_sent_s = -math.inf
    log.info(
        "detecting on %s with the %s backend, fusing with %s",
        raw_key,
        settings.backend,
        detector.radar_mount.sensor_id if detector.radar_mount is not None else "no radar",
    )
    processed = 0
    runtime.state = detector.state
    while not runtime.stop.is_set():
        frame: Frame[CameraFrameMeta] | None = frames.recv(0.25)
        runtime.beat(processed=frame is not None)
        if references is not None:
            while (reference := references.recv(0.0)) is not None:
                detector.lidar_batch(reference)
        if scans is not None:
            while (scan := scans.recv(0.0)) is not None:
                detector.radar_scan(scan)
        if references is not None and (
            any(owner.log.changed for owner in owners)
            or detector.last_stamp_s >= calibration_sent_s + CALIBRATION_PERIOD_S
        ):
            for owner in owners:
                if owner.log.changed:
                    log.info(
                        "calibration of %s: %s (%s)",
                        owner.mount.sensor_id,
                        owner.log.state,
                        owner.log.detail,
                    )
                calibrations[owner.mount.sensor_id].put(owner.message())
            calibration_sent_s = detector.last_stamp_s
        if frame is None:
            continue
        taken_s = time.monotonic()
        runs = detector.runs
        batch = detector.handle(frame.meta, frame.payload, taken_s)
        runtime.state = detector.state
        if detector.runs != runs:
            clock.restart(detector.last_stamp_s)
        else:
            clock.advance_to(detector.last_stamp_s)
        if batch is not None:
            publisher.put(batch)
            processed += 1
    return processed


def main() -> None:
    node = NodeApp(SERVICE, CameraDetectorSettings)
    site = node.read_site()
    with node.fatal(ValueError):
        camera_id = camera_mount(site, node.settings.camera_id).sensor_id
    node.start_logging(site.site_id, sensor=camera_id)
    processed = node.serve(lambda runtime: run(runtime, site, node.settings, node.clock))
    log.info("stopped after %d frames", processed)


if __name__ == "__main__":
    main()
