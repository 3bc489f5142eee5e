"""A field log: a folder of device recordings and the manifest that says what each one is.

``<LOG_DIR>/log.yaml``::

    format: wz-field-log/1
    site: site.yaml                   # the site: road, work zone, and a mount for each sensor
    sources:
      - sensor_id: lidar-mast         # a sensor of the site file (its pose places the data)
        kind: lidar                   # lidar | camera | objects
        format: ouster                # lidar: ouster | frames (PCD/PLY/NPZ folder)
        path: lidar/os-32.pcap        #   ouster: the pcap (or OSF) and its metadata JSON
        metadata: lidar/os-32.json
      - sensor_id: camera-mast
        kind: camera
        format: video                 # a video file (or an rtsp:// URL), OpenCV
        path: camera/video.avi
        timestamps: camera/frames.csv # frame,time_unix_s (optional: else start_unix_s)
      - sensor_id: radar-camera
        kind: objects                 # a radar or radar-camera unit's object lists
        format: csv                   # csv | jsonl
        path: radar-camera/objects.csv
        clock_offset_s: 0.12          # its clock minus the GPS's (optional; wz eval --log)

A live source names its device instead of a file (the drivers node reads it as it comes):
``path: ouster://os-992xxx.local`` (an Ouster by hostname; metadata from the sensor),
``path: rtsp://camera.local/stream`` (format video), ``path: udp://0.0.0.0:5005`` (format udp:
one JSON object list a datagram).
    truth:                            # optional: the probe vehicle's GPS
      path: gps/probe.nmea            # NMEA (GGA/RMC/VTG) or CSV
      antenna_forward_m: 1.2          # antenna ahead of the vehicle's centre
      antenna_left_m: 0.0
      vehicle_id: probe               # (the simulated log's truth id, for the record)

Paths are relative to the folder. Every time in the recordings is Unix seconds, each on the
device's own clock (``wz eval --truth`` estimates the offsets). :func:`load_log` checks the
manifest against the site (every ``sensor_id`` a sensor of the right kind) and that every file
is there, and says what is wrong in words for the field engineer.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from wz_drivers.records import FieldDataError
from wz_shared.site import Site, SiteFileError, load_site

MANIFEST = "log.yaml"
FORMAT = "wz-field-log/1"
SensorId = Annotated[str, Field(pattern=r"^[a-z0-9][a-z0-9_-]{0,62}$")]
#: Which site sensor kind each source kind needs.
SITE_KIND = {"lidar": "lidar", "camera": "camera", "objects": "radar"}


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class LogSource(_Strict):
    sensor_id: SensorId
    kind: Literal["lidar", "camera", "objects"]
    format: Literal["ouster", "frames", "video", "csv", "jsonl", "udp"]
    path: str
    metadata: str | None = None
    timestamps: str | None = None
    start_unix_s: float | None = None
    #: This source's clock minus the reference (GPS) clock [s], taken off every stamp before
    #: anything uses it; ``wz eval --log`` estimates it (e.g. a unit on its own NTP: 0.12).
    clock_offset_s: Annotated[float, Field(ge=-60.0, le=60.0)] = 0.0

    @model_validator(mode="after")
    def _format_fits_kind(self) -> LogSource:
        allowed = {
            "lidar": {"ouster", "frames"},
            "camera": {"video"},
            "objects": {"csv", "jsonl", "udp"},
        }[self.kind]
        if self.format not in allowed:
            raise ValueError(
                f"a {self.kind} source is one of {sorted(allowed)}, not {self.format!r}"
            )
        if self.format == "udp" and not self.path.startswith("udp://"):
            raise ValueError("a udp source's path is udp://<host>:<port> to listen on")
        if self.format == "ouster" and self.metadata is None and not self.live:
            raise ValueError("an Ouster recording needs its metadata JSON (metadata: ...)")
        return self

    @property
    def live(self) -> bool:
        """A device, not a file: ``ouster://<hostname>``, ``rtsp://...``, ``udp://host:port``."""
        return "://" in self.path


class LogTruth(_Strict):
    path: str
    antenna_forward_m: float = 0.0
    antenna_left_m: float = 0.0
    vehicle_id: str | None = None


class LogManifest(_Strict):
    format: Literal["wz-field-log/1"]
    site: str
    sources: Annotated[list[LogSource], Field(min_length=1)]
    truth: LogTruth | None = None
    description: str = ""


class FieldLog:
    """A loaded field log: its manifest, site, and absolute paths."""

    def __init__(self, folder: Path, manifest: LogManifest, site: Site) -> None:
        self.folder = folder
        self.manifest = manifest
        self.site = site

    @property
    def sources(self) -> list[LogSource]:
        return list(self.manifest.sources)

    def path(self, relative: str) -> Path:
        return self.folder / relative

    def truth_path(self) -> Path | None:
        truth = self.manifest.truth
        return None if truth is None else self.path(truth.path)


def load_log(folder: str | Path) -> FieldLog:
    """Read and check ``<folder>/log.yaml``; :class:`FieldDataError` says what is wrong."""
    folder = Path(folder)
    manifest_path = folder / MANIFEST
    if not folder.is_dir():
        raise FieldDataError(folder, "not a folder (a field log is a folder with a log.yaml)")
    try:
        raw = yaml.safe_load(manifest_path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise FieldDataError(manifest_path, f"cannot read the manifest: {exc.strerror}") from exc
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        raise FieldDataError(
            manifest_path,
            f"not YAML: {getattr(exc, 'problem', exc)}",
            line=None if mark is None else mark.line + 1,
        ) from exc
    try:
        manifest = LogManifest.model_validate(raw)
    except ValidationError as exc:
        problems = "; ".join(
            f"{'.'.join(str(p) for p in e['loc']) or 'manifest'}: {e['msg']}" for e in exc.errors()
        )
        raise FieldDataError(manifest_path, problems) from exc
    try:
        site = load_site(folder / manifest.site)
    except SiteFileError as exc:
        raise FieldDataError(manifest_path, f"site: {exc}") from exc
    mounts = {mount.sensor_id: mount for mount in site.sensors}
    for source in manifest.sources:
        mount = mounts.get(source.sensor_id)
        if mount is None:
            raise FieldDataError(
                manifest_path,
                f"source {source.sensor_id}: the site "
                f"{site.site_id} has no such sensor (it has "
                f"{', '.join(mounts)})",
            )
        if mount.kind != SITE_KIND[source.kind]:
            raise FieldDataError(
                manifest_path,
                f"source {source.sensor_id} is {source.kind} "
                f"data but the site's sensor is a {mount.kind}",
            )
        for relative in (source.path, source.metadata, source.timestamps):
            if (
                relative is not None
                and not (source.live and relative == source.path)
                and not (folder / relative).exists()
            ):
                raise FieldDataError(
                    manifest_path, f"source {source.sensor_id}: {relative} is missing"
                )
    if manifest.truth is not None and not (folder / manifest.truth.path).is_file():
        raise FieldDataError(manifest_path, f"truth: {manifest.truth.path} is missing")
    return FieldLog(folder, manifest, site)
