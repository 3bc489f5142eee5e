"""A field log's sources as the bus's messages, merged in time order.

Each source of the manifest (:mod:`wz_drivers.log`) is opened with its format's reader and each
record becomes what the simulator would publish for that sensor:

- a LiDAR sweep: a LiDAR frame envelope on ``wz/<site>/raw/lidar/<sensor>`` (the LiDAR detector
  places it with the sensor's mount);
- a camera image: a camera frame envelope on ``raw/camera/<sensor>``;
- an object list of a radar or radar-camera unit: a :class:`DetectionBatch` on
  ``detections/<sensor>``, the objects placed in the site frame with the unit's mount (ground
  heading and position) and each given a covariance from the unit's range and azimuth noise
  (the site file's radar intrinsics), as the camera-radar detector does for radar echoes. A
  unit that tracks objects itself is a detector: its lists go to the fusion tracker directly.

Stamps stay Unix seconds, on each device's clock less the source's ``clock_offset_s`` (the
manifest's; 0 by default).
"""

from __future__ import annotations

import gzip
import heapq
import math
import shutil
import tempfile
import threading
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from wz_drivers.log import FieldLog, LogSource
from wz_drivers.records import CameraImage, FieldDataError, LidarSweep, ObjectList, Problems
from wz_shared import codec
from wz_shared.geometry import polar_covariance
from wz_shared.keys import Keys
from wz_shared.messages import (
    CameraFrameMeta,
    Detection,
    DetectionBatch,
    LidarFrameMeta,
    Message,
)
from wz_shared.site import RadarIntrinsics, SensorMount, Site

#: Floor of a detection's variance [m^2] (a unit that reports 0 noise is not believed).
_MIN_VARIANCE_M2 = 0.01


@dataclass(frozen=True)
class Outgoing:
    """One message of the log, ready for the bus: its key, its payload, its message (None for
    frames, which travel as envelopes), and its stamp [Unix s] for ordering and pacing."""

    stamp: float
    sensor_id: str
    key: str
    payload: bytes
    message: Message | None = None


def read_source(
    log: FieldLog, source: LogSource, problems: Problems, stop: threading.Event | None = None
) -> Iterator[Any]:
    """The records of one source, with its format's reader (imported here: a log without an
    Ouster recording does not need ouster-sdk loaded); a live source's until ``stop``."""
    path = source.path if source.live else log.path(source.path)
    if source.format == "ouster" and source.live:
        from wz_drivers.ouster import open_live

        return open_live(source.path.split("://", 1)[1], problems)
    if source.format == "udp":
        from wz_drivers.radar import listen_udp

        host, _, port = source.path.split("://", 1)[1].rpartition(":")
        return listen_udp(host, int(port), problems, stop=stop or threading.Event())
    timestamps = None if source.timestamps is None else log.path(source.timestamps)
    if source.format == "ouster":
        assert source.metadata is not None  # the manifest requires it
        return _read_ouster(log.path(source.path), log.path(source.metadata), problems)
    if source.format == "frames":
        from wz_drivers.lidar_files import read_frame_folder

        return read_frame_folder(log.path(source.path), problems, timestamps=timestamps)
    if source.format == "video":
        from wz_drivers.video import read_video

        return read_video(path, problems, timestamps=timestamps, start_unix_s=source.start_unix_s)
    from wz_drivers.radar import read_objects

    return read_objects(log.path(source.path), problems)


def _read_ouster(path: Path, metadata: Path, problems: Problems) -> Iterator[LidarSweep]:
    """An Ouster recording; a gzipped pcap (``.pcap.gz``, how logs are shipped) is unpacked to
    a temporary file first (ouster-sdk reads files), removed when the reading ends."""
    from wz_drivers.ouster import read_ouster

    if path.suffix != ".gz":
        yield from read_ouster(path, metadata, problems)
        return
    with tempfile.TemporaryDirectory(prefix="wz-ouster-") as folder:
        unpacked = Path(folder) / path.stem
        try:
            with gzip.open(path, "rb") as packed, unpacked.open("wb") as raw:
                shutil.copyfileobj(packed, raw)
        except (OSError, EOFError) as exc:  # a cut archive: what came out is still read
            problems.add(
                FieldDataError(
                    path, f"the gzip archive is damaged ({exc}); reading what could be unpacked"
                )
            )
        yield from read_ouster(unpacked, metadata, _Renamed(problems, unpacked, path))


class _Renamed(Problems):
    """Passes each problem on, naming the archive instead of its temporary unpacked copy."""

    def __init__(self, target: Problems, unpacked: Path, archive: Path) -> None:
        super().__init__()
        self._target, self._prefix, self._archive = target, str(unpacked), archive

    def add(self, error: FieldDataError) -> None:
        text = str(error)
        if text.startswith(self._prefix):
            where, _, message = text[len(self._prefix) :].partition(": ")
            error = FieldDataError(self._archive, f"unpacked{where}: {message}", line=None)
        self._target.add(error)


def objects_to_detections(
    objects: ObjectList, mount: SensorMount, site: Site, index: int
) -> DetectionBatch:
    """An object list in the unit's frame as a site-frame :class:`DetectionBatch`."""
    intrinsics = mount.intrinsics
    if not isinstance(intrinsics, RadarIntrinsics):
        raise ValueError(f"{mount.sensor_id} is a {mount.kind}, not a radar unit")
    heading = mount.pose.ground_heading_rad()
    c, s = math.cos(heading), math.sin(heading)
    range_var = intrinsics.range_noise_std_m**2
    azimuth_std = math.radians(intrinsics.azimuth_noise_std_deg)
    detections = []
    for obj in objects.objects:
        x = mount.pose.x_m + c * obj.x_m - s * obj.y_m
        y = mount.pose.y_m + s * obj.x_m + c * obj.y_m
        rho = max(math.hypot(obj.x_m, obj.y_m), 1.0)
        bearing = heading + math.atan2(obj.y_m, obj.x_m)
        covariance = polar_covariance(
            bearing, range_var, (rho * azimuth_std) ** 2, min_variance_m2=_MIN_VARIANCE_M2
        )
        detections.append(
            Detection(
                x_m=x,
                y_m=y,
                covariance_m2=covariance.ravel().tolist(),
                object_class=obj.object_class,
                speed_mps=obj.speed_mps,
                local_track_id=obj.object_id,
                length_m=obj.length_m,
                width_m=obj.width_m,
            )
        )
    return DetectionBatch(
        site=site.site_id,
        source_id=mount.sensor_id,
        stamp=objects.stamp,
        frame_index=index,
        detections=detections,
    )


def key_of(site: Site, source: LogSource) -> str:
    """The bus key a source's messages go on."""
    keys = Keys(site.site_id)
    if source.kind == "lidar":
        return keys.raw_lidar(source.sensor_id)
    if source.kind == "camera":
        return keys.raw_camera(source.sensor_id)
    return keys.detections(source.sensor_id)


@dataclass(frozen=True)
class SourceRecord:
    """One record of a source (stamp corrected by its ``clock_offset_s``) and where it is from:
    the source, its sensor's mount, and its number in the source."""

    source: LogSource
    mount: SensorMount
    index: int
    record: Any

    @property
    def stamp(self) -> float:
        return float(self.record.stamp)


def lidar_meta(sweep: LidarSweep, sensor_id: str, site: Site, index: int) -> LidarFrameMeta:
    """The frame metadata of a sweep, as the simulator would publish it."""
    return LidarFrameMeta(
        site=site.site_id,
        source_id=sensor_id,
        stamp=sweep.stamp,
        frame_index=index,
        rows=max(1, sweep.rows),
        columns=sweep.columns if sweep.organized else 0,
        num_points=len(sweep.points),
        sweep_duration_s=sweep.sweep_duration_s,
        organized=sweep.organized,
    )


def to_outgoing(
    record: Any, source: LogSource, mount: SensorMount, site: Site, index: int
) -> Outgoing:
    """One record of ``source`` as its bus message."""
    keys = Keys(site.site_id)
    sensor = source.sensor_id
    if isinstance(record, LidarSweep):
        meta = lidar_meta(record, sensor, site, index)
        return Outgoing(
            record.stamp,
            sensor,
            keys.raw_lidar(sensor),
            codec.encode_lidar_frame(meta, record.points),
        )
    if isinstance(record, CameraImage):
        camera_meta = CameraFrameMeta(
            site=site.site_id,
            source_id=sensor,
            stamp=record.stamp,
            frame_index=index,
            width_px=record.width_px,
            height_px=record.height_px,
        )
        return Outgoing(
            record.stamp,
            sensor,
            keys.raw_camera(sensor),
            codec.encode_camera_frame(camera_meta, record.jpeg),
        )
    if isinstance(record, ObjectList):
        batch = objects_to_detections(record, mount, site, index)
        return Outgoing(
            record.stamp, sensor, keys.detections(sensor), codec.encode_json(batch), batch
        )
    raise TypeError(f"no bus message for a {type(record).__name__}")


def source_records(
    log: FieldLog, source: LogSource, problems: Problems, stop: threading.Event | None = None
) -> Iterator[SourceRecord]:
    """One source's records in its order (a live source's as they come, until ``stop``)."""
    mount = next(m for m in log.site.sensors if m.sensor_id == source.sensor_id)
    for index, record in enumerate(read_source(log, source, problems, stop)):
        if source.clock_offset_s:
            record = replace(record, stamp=record.stamp - source.clock_offset_s)
        yield SourceRecord(source, mount, index, record)


def merged_records(
    log: FieldLog, problems: Problems, only: set[str] | None = None
) -> Iterator[SourceRecord]:
    """Every source's records in stamp order (each source is in order already: its reader
    drops what goes back); ``only``: these sensor ids."""
    streams = [
        source_records(log, source, problems)
        for source in log.sources
        if only is None or source.sensor_id in only
    ]
    return heapq.merge(*streams, key=lambda item: item.stamp)


def _outgoing(log: FieldLog, item: SourceRecord) -> Outgoing:
    return to_outgoing(item.record, item.source, item.mount, log.site, item.index)


def source_messages(
    log: FieldLog, source: LogSource, problems: Problems, stop: threading.Event | None = None
) -> Iterator[Outgoing]:
    """One source's messages in its order (a live source's as they come, until ``stop``)."""
    return (_outgoing(log, item) for item in source_records(log, source, problems, stop))


def merged(log: FieldLog, problems: Problems, only: set[str] | None = None) -> Iterator[Outgoing]:
    """Every source's messages in stamp order (see :func:`merged_records`)."""
    return (_outgoing(log, item) for item in merged_records(log, problems, only))
