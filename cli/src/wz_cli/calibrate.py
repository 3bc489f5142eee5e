"""``wz calibrate``: the sensors' self-calibration for the field technician (issue 39).

The detectors learn their sensors' poses and clocks by themselves, on the bus, all the time
(:mod:`wz_lidar_detector.calibration`, :mod:`wz_camera_detector.calibration`). This command
shows a technician what they learn, and turns it into a corrected site file:

- ``--recording FILE.mcap`` (a ``wz record`` file with the raw frames): the LiDAR and camera
  detectors' own per-frame code runs here, in this process, on every recorded frame in the
  order of their stamps (:class:`Calibrator`, as :func:`wz_eval.pipeline.run_pipeline` drives
  them): LiDAR frames through :meth:`LidarDetector.handle`, its detections on to the camera
  detector as the reference, radar scans and camera frames to the camera detector;
- ``--minutes N``: the stack is running; listen to the detectors' own
  ``wz/<site>/calibration/<sensor>`` messages (until every sensor of the site file is
  calibrated, or N minutes);
- ``--frame FILE`` (ground only): one LiDAR frame, no site lanes needed: the ground plane
  under the sensor (:mod:`wz_cli.calibrate_ground`).

Then it prints each sensor's correction with its uncertainty, and with ``--write-site`` writes
the site file with each calibrated sensor's pose replaced by the site file's plus the learned
correction (:func:`corrected_site`); ``--pictures DIR`` draws the before/after pictures
(:mod:`wz_cli.calibrate_pictures`).
"""

from __future__ import annotations

import heapq
import importlib.util
import json
import logging
import math
import os
import queue
import threading
import time
from collections import Counter, deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml

from wz_cli.calibrate_views import CameraShot, LidarView, SensorResult, lidar_view
from wz_cli.common import CliError, emit
from wz_cli.recording import ReadReport, RecordingError, RecordingReader, describe_report
from wz_shared import codec
from wz_shared.arrays import F32
from wz_shared.bus import Bus
from wz_shared.keys import Keys
from wz_shared.messages import (
    CalibrationState,
    CameraFrameMeta,
    LidarFrameMeta,
    Message,
    PoseCorrection,
    RadarScan,
    SensorCalibration,
)
from wz_shared.self_calibration import corrected_pose
from wz_shared.site import Pose, Site, site_document

if TYPE_CHECKING:
    from wz_camera_detector.node import CameraDetector
    from wz_lidar_detector.node import LidarDetector

log = logging.getLogger(__name__)

#: Exit codes: the recording was cut short (everything readable was used), as ``wz replay``;
#: the run went through but a sensor with data is not calibrated (too short, too little
#: traffic: the corrections printed are partial).
EXIT_INCOMPLETE = 3
EXIT_NOT_CALIBRATED = 4

#: Frames are taken in the order of their stamps within this much sensor time [s]: a recorder
#: writes them as they arrive, a little out of order across sensors.
REORDER_WINDOW_S = 0.5
#: LiDAR detections kept for the pictures: this much sensor time, at most so many boxes.
PICTURE_WINDOW_S = 90.0
PICTURE_MAX_BOXES = 40_000
#: Camera frames kept for the pictures: one every so many seconds, the newest so many.
PICTURE_FRAME_EVERY_S = 2.0
PICTURE_FRAMES = 30

#: Where the detectors live: a recording runs them here.
DETECTOR_PACKAGES = ("wz_lidar_detector", "wz_camera_detector")


# --- a recording, in stamp order ---------------------------------------------------------------


@dataclass(frozen=True)
class LidarItem:
    meta: LidarFrameMeta
    points: F32  # (N, 4) x, y, z, intensity; read-only


@dataclass(frozen=True)
class CameraItem:
    meta: CameraFrameMeta
    jpeg: bytes


Item = LidarItem | CameraItem | RadarScan


@dataclass
class SourceReport:
    """What was read from a recording."""

    read: ReadReport = field(default_factory=ReadReport)
    #: Frames taken, by ``lidar``, ``camera``, ``radar``.
    frames: Counter[str] = field(default_factory=Counter)
    #: Messages of the recording not used, by key.
    other_keys: Counter[str] = field(default_factory=Counter)
    #: Frames that did not decode, by (key, reason).
    undecodable: Counter[tuple[str, str]] = field(default_factory=Counter)
    first_stamp_s: float = math.inf
    last_stamp_s: float = -math.inf


def recorded_items(
    path: Path, site: Site, sensor_ids: Sequence[str], source: SourceReport
) -> Iterator[Item]:
    """The raw frames of ``site``'s sensors ``sensor_ids`` in ``path``, decoded, in the order of
    their stamps (within :data:`REORDER_WINDOW_S`); ``source`` counts what was read.

    Raises
    ------
    CliError
        When the file cannot be opened or is no MCAP recording (exit code 1).
    """
    keys = Keys(site.site_id)
    wanted: dict[str, str] = {}
    for mount in site.sensors:
        if mount.sensor_id not in sensor_ids:
            continue
        key = {
            "lidar": keys.raw_lidar,
            "camera": keys.raw_camera,
            "radar": keys.raw_radar,
        }[mount.kind](mount.sensor_id)
        wanted[key] = mount.kind
    try:
        stream = path.open("rb")
    except OSError as exc:
        raise CliError(f"cannot read {path}: {exc}", 1) from exc
    pending: list[tuple[float, int, Item]] = []
    newest = -math.inf
    with stream:
        reader = RecordingReader(stream)
        try:
            for sequence, message in enumerate(reader.messages()):
                kind = wanted.get(message.topic)
                if kind is None:
                    source.other_keys[message.topic] += 1
                    continue
                item = _decode(kind, message.payload)
                if isinstance(item, str):
                    source.undecodable[(message.topic, item)] += 1
                    continue
                stamp = item.stamp if isinstance(item, RadarScan) else item.meta.stamp
                source.frames[kind] += 1
                source.first_stamp_s = min(source.first_stamp_s, stamp)
                source.last_stamp_s = max(source.last_stamp_s, stamp)
                heapq.heappush(pending, (stamp, sequence, item))
                newest = max(newest, stamp)
                while pending and pending[0][0] < newest - REORDER_WINDOW_S:
                    yield heapq.heappop(pending)[2]
        except RecordingError as exc:
            raise CliError(f"cannot read {path}: {exc}", 1) from exc
        finally:
            source.read = reader.report
    while pending:
        yield heapq.heappop(pending)[2]


def _decode(kind: str, payload: bytes) -> Item | str:
    """The frame, or why it does not decode."""
    try:
        if kind == "lidar":
            lidar = codec.decode_frame(payload, LidarFrameMeta)
            return LidarItem(lidar.meta, lidar.points())
        if kind == "camera":
            camera = codec.decode_frame(payload, CameraFrameMeta)
            return CameraItem(camera.meta, bytes(camera.payload))
        return codec.decode_json(payload, RadarScan)
    except codec.DecodeError as exc:
        return exc.reason


# --- the detectors, in process ---------------------------------------------------------------


def require_detectors() -> None:
    """The detectors' packages are installed here, or a :class:`CliError` says so."""
    missing = [name for name in DETECTOR_PACKAGES if importlib.util.find_spec(name) is None]
    if missing:
        raise CliError(
            "wz calibrate --recording runs the detectors here and needs "
            + ", ".join(name.replace("_", "-") for name in missing)
            + " (install the workspace: `uv sync`); or listen to a running stack with --minutes",
            1,
        )


class Calibrator:
    """The LiDAR and camera detectors of ``site``, fed frames in stamp order.

    Every LiDAR of the site has its own :class:`LidarDetector` (its pose learned from the road
    and its vehicles); with ``cameras``, every camera its :class:`CameraDetector`, fed the first
    LiDAR's detections as the reference (as the camera node subscribes to them), and the site's
    first radar goes with the first camera. Settings are the services' own
    (``WZ_LIDAR_*``, ``WZ_CAMERA_*``), read from the environment as they would be.
    """

    def __init__(
        self,
        site: Site,
        *,
        cameras: bool = True,
        report: Callable[[str, str], None] | None = None,
        keep_pictures: bool = False,
    ) -> None:
        from wz_lidar_detector.node import LidarDetector
        from wz_lidar_detector.settings import LidarDetectorSettings

        self.site = site
        self.problems: Counter[str] = Counter()
        self._report = report
        self.keep_pictures = keep_pictures
        self.lidars: dict[str, LidarDetector] = {}
        for mount in site.sensors:
            if mount.kind != "lidar":
                continue
            settings = LidarDetectorSettings(sensor_id=mount.sensor_id, background_file=None)
            self.lidars[mount.sensor_id] = LidarDetector(
                site.site_id, mount, settings, self._problem, site=site
            )
        self.reference_id = next(iter(self.lidars), None)
        self.cameras: dict[str, CameraDetector] = {}
        #: radar id -> the camera detector that fuses and calibrates it.
        self.radar_owner: dict[str, str] = {}
        if cameras:
            self._build_cameras()
        #: For the pictures: each LiDAR's recent boxes, each camera's frames.
        self.views: dict[str, deque[LidarView]] = {sid: deque() for sid in self.lidars}
        self.shots: dict[str, deque[CameraShot]] = {
            sid: deque(maxlen=PICTURE_FRAMES) for sid in self.cameras
        }

    def _build_cameras(self) -> None:
        from wz_camera_detector.node import CameraDetector
        from wz_camera_detector.settings import CameraDetectorSettings
        from wz_camera_detector.yolo import ModelLoadError

        radars = [m.sensor_id for m in self.site.sensors if m.kind == "radar"]
        for mount in self.site.sensors:
            if mount.kind != "camera":
                continue
            radar_id = radars[0] if radars and not self.radar_owner else "none"
            settings = CameraDetectorSettings(camera_id=mount.sensor_id, radar_id=radar_id)
            radar = next((m for m in self.site.sensors if m.sensor_id == radar_id), None)
            try:
                self.cameras[mount.sensor_id] = CameraDetector(
                    self.site, mount, radar, settings, self._problem
                )
            except (ModelLoadError, ValueError) as exc:
                raise CliError(f"camera {mount.sensor_id}: {exc}", 1) from exc
            if radar is not None:
                self.radar_owner[radar.sensor_id] = mount.sensor_id

    def _problem(self, reason: str, detail: str) -> None:
        self.problems[reason] += 1
        if self._report is not None:
            self._report(reason, detail)

    @property
    def sensor_ids(self) -> list[str]:
        """The sensors whose frames this calibrator takes."""
        return [*self.lidars, *self.cameras, *self.radar_owner]

    def feed(self, item: Item) -> None:
        """One frame (in stamp order)."""
        if isinstance(item, LidarItem):
            self._lidar(item)
        elif isinstance(item, CameraItem):
            detector = self.cameras.get(item.meta.source_id)
            if detector is None:
                return
            detector.handle(item.meta, item.jpeg, time.monotonic())
            if self.keep_pictures:
                shots = self.shots[item.meta.source_id]
                if not shots or item.meta.stamp >= shots[-1].stamp_s + PICTURE_FRAME_EVERY_S:
                    shots.append(CameraShot(item.meta.source_id, item.meta.stamp, item.jpeg))
        else:
            owner = self.radar_owner.get(item.source_id)
            if owner is not None:
                self.cameras[owner].radar_scan(item)

    def _lidar(self, item: LidarItem) -> None:
        detector = self.lidars.get(item.meta.source_id)
        if detector is None:
            return
        batch = detector.handle(item.meta, item.points, time.monotonic())
        if batch is None:
            return
        if item.meta.source_id == self.reference_id:
            for camera in self.cameras.values():
                camera.lidar_batch(batch)
        if self.keep_pictures:
            views = self.views[item.meta.source_id]
            views.append(lidar_view(batch, detector.calibration.pose))
            boxes = sum(len(v.centres) for v in views)
            while views and (
                views[0].stamp_s < batch.stamp - PICTURE_WINDOW_S or boxes > PICTURE_MAX_BOXES
            ):
                boxes -= len(views.popleft().centres)

    def results(self, frames: Counter[str] | None = None) -> list[SensorResult]:
        """Every sensor of the site, in the site file's order; those without frames (and no
        detector) as ``no data``."""
        owners: dict[str, Any] = {}
        for sensor_id, lidar in self.lidars.items():
            owners[sensor_id] = lidar.calibration
        for sensor_id, camera in self.cameras.items():
            owners[sensor_id] = camera.calibration
            if camera.radar_calibration is not None:
                owners[camera.radar_calibration.mount.sensor_id] = camera.radar_calibration
        results = []
        for mount in self.site.sensors:
            owner = owners.get(mount.sensor_id)
            seen = frames is None or frames.get(mount.sensor_id, 0) > 0
            if owner is None or not seen:
                results.append(SensorResult(mount.sensor_id, mount.kind, mount.pose, None))
                continue
            message: SensorCalibration = owner.message()
            history = [(stamp, str(state), detail) for stamp, state, detail in owner.log.history]
            results.append(SensorResult(mount.sensor_id, mount.kind, mount.pose, message, history))
        return results


@dataclass
class RecordingRun:
    """What :func:`calibrate_recording` did."""

    results: list[SensorResult]
    source: SourceReport
    #: Frames taken per sensor.
    frames_by_sensor: Counter[str]
    problems: Counter[str]
    wall_s: float
    calibrator: Calibrator


def calibrate_recording(
    path: Path,
    site: Site,
    *,
    cameras: bool = True,
    keep_pictures: bool = False,
    progress: Callable[[float, float], None] | None = None,
) -> RecordingRun:
    """Run the detectors over ``path``'s raw frames of ``site``'s sensors.

    Raises
    ------
    CliError
        The recording cannot be read, or holds no raw frame of the site's sensors.
    """
    require_detectors()
    started = time.perf_counter()
    calibrator = Calibrator(site, cameras=cameras, keep_pictures=keep_pictures)
    source = SourceReport()
    by_sensor: Counter[str] = Counter()
    next_progress_s = -math.inf
    for item in recorded_items(path, site, calibrator.sensor_ids, source):
        calibrator.feed(item)
        sensor_id = item.source_id if isinstance(item, RadarScan) else item.meta.source_id
        by_sensor[sensor_id] += 1
        stamp = item.stamp if isinstance(item, RadarScan) else item.meta.stamp
        if progress is not None and stamp >= next_progress_s:
            progress(stamp, source.first_stamp_s)
            next_progress_s = stamp + 10.0
    if not sum(source.frames.values()):
        raise CliError(_no_frames(path, site, calibrator, source), 1)
    return RecordingRun(
        calibrator.results(by_sensor),
        source,
        by_sensor,
        calibrator.problems,
        time.perf_counter() - started,
        calibrator,
    )


def _no_frames(path: Path, site: Site, calibrator: Calibrator, source: SourceReport) -> str:
    keys = Keys(site.site_id)
    wanted = ", ".join(
        f"{keys.prefix}/raw/{m.kind}/{m.sensor_id}"
        for m in site.sensors
        if m.sensor_id in calibrator.sensor_ids
    )
    heard = sorted(source.other_keys)
    text = f"{path} holds no raw frame of site {site.site_id}'s sensors (looked for {wanted})"
    if source.undecodable:
        bad = ", ".join(f"{key} {reason} x{n}" for (key, reason), n in source.undecodable.items())
        text += f"; frames that do not decode: {bad}"
    if heard:
        shown = ", ".join(heard[:8]) + (f" and {len(heard) - 8} more" if len(heard) > 8 else "")
        text += f"; it has {shown}"
    else:
        text += f"; {describe_report(source.read)}"
    if heard and not any("/raw/" in key for key in heard):
        text += " (record the raw frames: `wz record OUT.mcap 'wz/*/raw/**'`)"
    elif heard:
        text += " (give the recording's own site file with --site)"
    return text


# --- the stack's own messages ----------------------------------------------------------------


def listen(bus: Bus, site: Site, minutes: float, stop: threading.Event) -> list[SensorResult]:
    """The newest ``calibration/<sensor>`` message of each sensor of ``site`` heard within
    ``minutes`` (returns early once every sensor of the site is calibrated)."""
    keys = Keys(site.site_id)
    arrivals: queue.Queue[tuple[str, Message]] = queue.Queue()
    bus.on(keys.calibration_all, SensorCalibration, lambda key, m: arrivals.put((key, m)))
    newest: dict[str, SensorCalibration] = {}
    ids = {m.sensor_id for m in site.sensors}
    deadline = time.monotonic() + 60.0 * minutes
    next_note = time.monotonic() + 30.0
    while not stop.is_set():
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            break
        try:
            _, message = arrivals.get(timeout=min(remaining, 1.0))
        except queue.Empty:
            message = None
        if isinstance(message, SensorCalibration) and message.source_id in ids:
            if message.source_id not in newest or message.state != newest[message.source_id].state:
                log.info("%s: %s (%s)", message.source_id, message.state, message.detail)
            newest[message.source_id] = message
        if ids <= newest.keys() and all(
            m.state == CalibrationState.CALIBRATED for m in newest.values()
        ):
            break
        if time.monotonic() >= next_note:
            next_note += 30.0
            waiting = sorted(
                sid
                for sid in ids
                if sid not in newest or newest[sid].state != CalibrationState.CALIBRATED
            )
            log.info("waiting for %s to be calibrated", ", ".join(waiting))
    return [
        SensorResult(m.sensor_id, m.kind, m.pose, newest.get(m.sensor_id)) for m in site.sensors
    ]


# --- output ----------------------------------------------------------------------------------


def _value(value: float, std: float | None, unit: str, scale: float = 1.0, digits: int = 2) -> str:
    if std is None:
        return "not observed (the site file's)"
    spread = scale * std
    # A tight estimate keeps a significant digit of its std (± 0.004, not ± 0.00).
    extra = 1 if 0 < spread < 0.5 * 10.0**-digits and digits > 0 else 0
    return f"{scale * value:+.{digits}f} {unit} ± {spread:.{digits + extra}f}"


def describe_result(result: SensorResult) -> list[str]:
    """A few lines for people: the state, each part of the correction, the clock."""
    head = f"{result.sensor_id} ({result.kind}): {result.state}"
    message = result.message
    if message is None:
        return [head + ": no frames of it, no estimate"]
    if message.detail:
        head += f" since {message.state_since_s:.1f} s: {message.detail}"
    c = message.correction
    lines = [head]
    if message.state == CalibrationState.PRIOR:
        lines.append("  nothing learned yet (the site file's pose)")
    else:
        for name, value, std, unit, digits in (
            ("yaw", c.yaw_deg, c.yaw_std_deg, "deg", 2),
            ("pitch", c.pitch_deg, c.pitch_std_deg, "deg", 2),
            ("roll", c.roll_deg, c.roll_std_deg, "deg", 2),
            ("x", c.x_m, c.x_std_m, "m", 2),
            ("y", c.y_m, c.y_std_m, "m", 2),
            ("z", c.z_m, c.z_std_m, "m", 2),
        ):
            lines.append(f"  {name:<6}{_value(value, std, unit, digits=digits)}")
    if result.kind == "lidar":
        lines.append("  clock the reference (the other sensors' clocks are learned against it)")
    elif message.clock_offset_std_s is None and message.state == CalibrationState.PRIOR:
        lines.append("  clock not observed")
    else:
        lines.append(
            "  clock "
            + _value(message.clock_offset_s, message.clock_offset_std_s, "ms", 1000.0, 0)
            + " (its stamps are this late)"
        )
    lines.append(f"  samples {message.samples}")
    n, learned = result.nominal, result.learned
    lines.append(
        f"  pose: site file {_pose_text(n)} -> learned {_pose_text(learned)}"
        if message.state != CalibrationState.PRIOR
        else f"  pose: site file {_pose_text(n)}"
    )
    return lines


def _pose_text(pose: Pose) -> str:
    return (
        f"x {pose.x_m:.2f} y {pose.y_m:.2f} z {pose.z_m:.2f} m, yaw {pose.yaw_deg:.2f} "
        f"pitch {pose.pitch_deg:.2f} roll {pose.roll_deg:.2f} deg"
    )


def result_json(result: SensorResult) -> dict[str, Any]:
    message = result.message
    return {
        "sensor_id": result.sensor_id,
        "kind": result.kind,
        "state": result.state,
        "calibration": None if message is None else message.model_dump(mode="json"),
        "nominal_pose": result.nominal.model_dump(mode="json"),
        "learned_pose": result.learned.model_dump(mode="json"),
        "history": [
            {"stamp_s": stamp, "state": state, "detail": detail}
            for stamp, state, detail in result.history
        ],
    }


# --- the corrected site file -----------------------------------------------------------------


def corrected_site(
    site: Site, results: Sequence[SensorResult], *, include_learning: bool = False
) -> tuple[Site, list[str]]:
    """``site`` with each calibrated sensor's pose replaced by the site file's plus its learned
    correction (with ``include_learning``, a sensor still learning too); everything else as it
    was. Returns the site and one line per sensor saying what was done."""
    by_id = {r.sensor_id: r for r in results}
    sensors = []
    notes = []
    for mount in site.sensors:
        result = by_id.get(mount.sensor_id)
        message = result.message if result is not None else None
        use = message is not None and (
            message.state == CalibrationState.CALIBRATED
            or (include_learning and message.state == CalibrationState.LEARNING)
        )
        if message is None or not use:
            state = "no data" if message is None else str(message.state)
            notes.append(f"{mount.sensor_id}: kept the site file's pose ({state})")
            sensors.append(mount)
            continue
        pose = corrected_pose(mount.pose, message.correction)
        sensors.append(mount.model_copy(update={"pose": _rounded(pose)}))
        extra = "" if message.state == CalibrationState.CALIBRATED else " (still learning)"
        notes.append(f"{mount.sensor_id}: pose corrected{extra}: {_correction_text(message)}")
    return site.model_copy(update={"sensors": sensors}), notes


def _rounded(pose: Pose) -> Pose:
    """Millimetres and thousandths of a degree: what a site file needs, no float noise."""
    return Pose(
        x_m=round(pose.x_m, 3),
        y_m=round(pose.y_m, 3),
        z_m=round(pose.z_m, 3),
        yaw_deg=round(pose.yaw_deg, 3),
        pitch_deg=round(pose.pitch_deg, 3),
        roll_deg=round(pose.roll_deg, 3),
    )


def _correction_text(message: SensorCalibration) -> str:
    c: PoseCorrection = message.correction
    return (
        f"yaw {c.yaw_deg:+.2f}, pitch {c.pitch_deg:+.2f}, roll {c.roll_deg:+.2f} deg, "
        f"x {c.x_m:+.2f}, y {c.y_m:+.2f}, z {c.z_m:+.2f} m"
    )


def write_site_file(
    site: Site, source_path: Path, out: Path, header: Sequence[str], *, overwrite: bool = False
) -> None:
    """Write ``site`` as a site file at ``out`` (the repository's writer,
    :func:`wz_shared.site.site_document`), with ``header`` as comments; a camera's calibration
    file (relative to the site file) is named relative to ``out``'s folder."""
    if out.exists() and not overwrite:
        raise CliError(f"{out} exists: give another name, or --overwrite", 1)
    if out.resolve() == source_path.resolve():
        raise CliError(f"{out} is the site file read: write the corrected one beside it", 1)
    document = site_document(site)
    for sensor in document.get("sensors", []):
        intrinsics = sensor.get("intrinsics", {})
        name = intrinsics.get("calibration_file")
        if name and not Path(name).is_absolute():
            moved = os.path.relpath(source_path.parent / name, out.parent)
            intrinsics["calibration_file"] = Path(moved).as_posix()
    text = "".join(f"# {line}\n" for line in header)
    text += yaml.safe_dump(document, sort_keys=False)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise CliError(f"cannot write {out}: {exc}", 1) from exc


def site_header(site_path: Path, source: str, notes: Sequence[str]) -> list[str]:
    stamp = datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
    return [
        f"Written by `wz calibrate` at {stamp} from {site_path} and {source}:",
        "each calibrated sensor's pose is the site file's plus the correction its detector",
        "learned from the road and the traffic (docs/calibration.md). The clock offsets are not",
        "site-file settings: the detectors keep learning them. Comments of the original are not",
        "carried over.",
        *notes,
    ]


# --- the command -----------------------------------------------------------------------------


def exit_code(results: Sequence[SensorResult], read: ReadReport | None) -> int:
    if read is not None and read.problem is not None:
        return EXIT_INCOMPLETE
    with_data = [r for r in results if r.message is not None]
    if not with_data or not all(r.calibrated for r in with_data):
        return EXIT_NOT_CALIBRATED
    return 0


def report_run(
    results: Sequence[SensorResult],
    *,
    as_json: bool,
    header: Sequence[str],
    extra: dict[str, Any] | None = None,
) -> None:
    """Print the results: lines for people, or one JSON object."""
    if as_json:
        document = {**(extra or {}), "sensors": [result_json(r) for r in results]}
        emit(json.dumps(document, indent=1))
        return
    for line in header:
        emit(line)
    for result in results:
        for line in describe_result(result):
            emit(line)
    waiting = [r.sensor_id for r in results if r.message is not None and not r.calibrated]
    if waiting:
        emit(
            f"NOT CALIBRATED: {', '.join(waiting)} (more traffic needed: a longer recording, "
            "or wait longer); their corrections above are partial"
        )


def run_command(
    args: Any,
    site: Site | None,
    site_path: Path,
    stop: threading.Event,
    bus_factory: Callable[[], Bus],
) -> int:
    """``wz calibrate`` with parsed ``args`` (see ``wz calibrate --help``); ``site`` None only
    for ``--frame`` without ``--site``."""
    if args.frame is not None:
        return _ground_command(args, site)
    assert site is not None
    read: ReadReport | None = None
    extra: dict[str, Any] = {"site": site.site_id}
    if args.recording is not None:
        if not args.recording.is_file():
            raise CliError(f"no such recording: {args.recording}", 1)

        def progress(stamp_s: float, first_s: float) -> None:
            log.info("at %.1f s of sensor time (%.0f s in)", stamp_s, stamp_s - first_s)

        run = calibrate_recording(
            args.recording,
            site,
            cameras=not args.no_camera,
            keep_pictures=args.pictures is not None,
            progress=progress,
        )
        results, read, source_name = run.results, run.source.read, str(args.recording)
        source = run.source
        span = max(0.0, source.last_stamp_s - source.first_stamp_s)
        frames = ", ".join(f"{n} {kind}" for kind, n in sorted(source.frames.items()))
        header = [
            f"wz calibrate: {args.recording}: {describe_report(read)}; {frames} frame(s) over "
            f"{span:.1f} s of sensor time ({source.first_stamp_s:.1f}-"
            f"{source.last_stamp_s:.1f} s), run in {run.wall_s:.1f} s"
        ]
        if source.undecodable:
            header.append(
                "frames that did not decode: "
                + ", ".join(f"{k} {r} x{n}" for (k, r), n in sorted(source.undecodable.items()))
            )
        if run.problems:
            header.append(
                "the detectors reported: "
                + ", ".join(f"{reason} x{n}" for reason, n in sorted(run.problems.items()))
            )
        extra.update(
            recording=str(args.recording),
            complete=read.complete,
            problem=read.problem,
            frames=dict(source.frames),
            sensor_time_s=[source.first_stamp_s, source.last_stamp_s],
            wall_s=round(run.wall_s, 2),
        )
    else:
        with bus_factory() as bus:
            results = listen(bus, site, args.minutes, stop)
        source_name = f"the stack's calibration messages ({args.minutes:g} min at most)"
        heard = sum(r.message is not None for r in results)
        if not heard:
            raise CliError(
                f"no calibration heard on {Keys(site.site_id).calibration_all} in "
                f"{args.minutes:g} min: are the detectors of site {site.site_id} running "
                "(`wz status`)?",
                1,
            )
        header = [f"wz calibrate: {heard} of {len(results)} sensor(s) heard on the bus"]
    if args.pictures is not None and args.recording is not None:
        extra["pictures"] = [str(p) for p in draw_pictures(site, run, args.pictures, header)]
    if args.write_site is not None:
        corrected, notes = corrected_site(site, results, include_learning=args.include_learning)
        write_site_file(
            corrected,
            site_path,
            args.write_site,
            site_header(site_path, source_name, notes),
            overwrite=args.overwrite,
        )
        header += [f"wrote {args.write_site}:", *(f"  {note}" for note in notes)]
        extra["site_file"] = str(args.write_site)
    report_run(results, as_json=args.json, header=header, extra=extra)
    if read is not None and read.problem is not None and not args.json:
        emit(describe_report(read))
    return exit_code(results, read)


def draw_pictures(site: Site, run: RecordingRun, folder: Path, header: list[str]) -> list[Path]:
    """The before/after pictures of ``run`` in ``folder``; a line in ``header`` for each."""
    from wz_cli.calibrate_pictures import camera_picture, lanes_picture

    by_id = {r.sensor_id: r for r in run.results}
    written: list[Path] = []
    calibrator = run.calibrator
    for sensor_id, views in calibrator.views.items():
        out = folder / f"{sensor_id}-lanes.png"
        figures = lanes_picture(site, by_id[sensor_id], list(views), out)
        if figures is None:
            header.append(f"picture: no detections of {sensor_id} to draw")
            continue
        written.append(out)
        header.append(
            f"picture {out}: {figures.boxes} detections on the road ({figures.off_road} off "
            "it, not scored), median distance to a lane centre "
            f"{figures.median_before_m:.2f} m with the site file's pose, "
            f"{figures.median_after_m:.2f} m with the learned one"
        )
    reference = calibrator.reference_id
    for sensor_id, shots in calibrator.shots.items():
        if reference is None:
            break
        out = folder / f"{sensor_id}-projection.png"
        shot = camera_picture(
            site,
            by_id[sensor_id],
            by_id[reference],
            list(calibrator.views[reference]),
            list(shots),
            out,
            calibrator.cameras[sensor_id].backend.detect,
        )
        if shot is None:
            header.append(f"picture: no frame of {sensor_id} with the LiDAR's vehicles in view")
            continue
        written.append(out)
        header.append(f"picture {out}: the frame stamped {shot.stamp_s:.2f} s")
    return written


def _ground_command(args: Any, site: Site | None) -> int:
    from wz_cli.calibrate_ground import ground_of_frame

    pose = None
    if site is not None:
        lidar = next((m for m in site.sensors if m.kind == "lidar"), None)
        if lidar is None:
            raise CliError(f"site {site.site_id} has no LiDAR", 2)
        pose = lidar.pose
    report = ground_of_frame(
        args.frame, site_pose=pose, height_m=args.height, range_m=tuple(args.ground_range)
    )
    if args.json:
        emit(json.dumps(report.as_json(), indent=1))
    else:
        for line in report.lines():
            emit(line)
    return 0 if report.fit.height_m is not None else 1
