"""What every reader yields, whatever the device's format, and how bad input is reported.

Readers are generators over one file, folder or stream. Time is Unix seconds (UTC, float) as
the device or its log recorded it; a log's clock may be off from another's (``wz eval
--truth`` estimates and reports the offset). Positions are in the *sensor's* frame (x forward
along its boresight, y left, z up, metres), as the device reports them; the site file's mount
pose of that sensor takes them to the site frame downstream.

Bad input
---------
A record that cannot be read (a bad checksum, a missing column, a time that goes back, a
truncated packet) is reported as a :class:`FieldDataError` naming the file and line (or
packet, or frame) to the reader's :class:`Problems`, and skipped: the rest of the log is
still used. A file that cannot be read at all (missing, not the format at all) raises
:class:`FieldDataError`.
"""

from __future__ import annotations

import logging
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

from wz_shared.messages import VehicleClass

log = logging.getLogger(__name__)


class FieldDataError(ValueError):
    """Bad field data, with where it is: ``<path>:<line>: <what>`` (line may be a packet or
    frame number, or absent)."""

    def __init__(
        self, path: str | Path, message: str, *, line: int | None = None, unit: str = "line"
    ) -> None:
        self.path = str(path)
        self.line = line
        self.reason = message
        where = (
            self.path
            if line is None
            else f"{self.path}:{line}"
            if unit == "line"
            else f"{self.path} ({unit} {line})"
        )
        super().__init__(f"{where}: {message}")


@dataclass
class Problems:
    """The records a reader skipped, kept for the operator's report and logged (the first few
    of each file in full, then counted)."""

    log_first: int = 5
    errors: list[FieldDataError] = field(default_factory=list)
    _per_file: Counter[str] = field(default_factory=Counter)

    def add(self, error: FieldDataError) -> None:
        self.errors.append(error)
        self._per_file[error.path] += 1
        if self._per_file[error.path] <= self.log_first:
            log.warning("skipped: %s", error)
        elif self._per_file[error.path] == self.log_first + 1:
            log.warning("%s: more bad records; only counted from now on", error.path)

    def __len__(self) -> int:
        return len(self.errors)

    def summary(self) -> dict[str, int]:
        """Skipped records per file."""
        return dict(self._per_file)


@dataclass(frozen=True)
class LidarSweep:
    """One LiDAR sweep: ``points`` (N, 4) float32, x y z [m] in the sensor frame and
    intensity; ``rows`` x ``columns`` when organized (row-major, beams by azimuth columns;
    ``columns`` 0 and organized False otherwise); ``where`` names the file and frame."""

    stamp: float
    points: npt.NDArray[np.float32]
    rows: int
    columns: int
    organized: bool
    where: str
    sweep_duration_s: float = 0.0


@dataclass(frozen=True)
class CameraImage:
    """One camera frame, JPEG-encoded (what the bus carries), and its size."""

    stamp: float
    jpeg: bytes
    width_px: int
    height_px: int
    where: str


@dataclass(frozen=True)
class RadarObject:
    """One object of a radar (or radar-camera unit's) object list, in the sensor frame.

    Position is ``x_m``/``y_m`` (x along the boresight, y to the left) whichever way the
    device gave it (range and azimuth are converted: azimuth counter-clockwise from the
    boresight, so positive to the left). ``speed_mps``: the object's speed as reported
    (ground speed for a tracking unit; None if not given).
    """

    x_m: float
    y_m: float
    object_id: int | None = None
    speed_mps: float | None = None
    object_class: VehicleClass = VehicleClass.UNKNOWN
    length_m: float | None = None
    width_m: float | None = None


@dataclass(frozen=True)
class ObjectList:
    """All objects of one radar report (possibly none)."""

    stamp: float
    objects: tuple[RadarObject, ...]
    where: str


@dataclass(frozen=True)
class GpsFix:
    """One GPS fix of the truth vehicle's antenna (WGS84). ``quality``: the GGA fix quality
    (4: RTK fixed, 5: RTK float, 1: autonomous ...) where known."""

    stamp: float
    latitude_deg: float
    longitude_deg: float
    altitude_m: float | None = None
    speed_mps: float | None = None
    heading_deg: float | None = None  # course over ground, clockwise from true north
    quality: int | None = None
