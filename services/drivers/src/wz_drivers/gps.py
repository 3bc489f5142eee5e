"""GPS truth: the RTK-GPS van's log (NMEA 0183 or CSV) read into :class:`GpsFix`es, and the fixes
taken to the site and road frames as a :class:`GpsTrack` of the vehicle's reference point.

Readers
-------
- :func:`read_nmea`: GGA, RMC and VTG sentences of any talker (``GP``, ``GN``, ``GL`` ...),
  checksums verified; the sentences of one epoch (same time of day) merged into one fix.
- :func:`read_gps_csv`: a CSV with a header naming its columns.
- :func:`read_gps`: either, by the file's content.

Bad sentences or rows are reported to :class:`Problems` with their line and skipped (see
:mod:`wz_drivers.records`); a missing file, or a CSV without the columns it needs, raises
:class:`FieldDataError` when the reader is called, before the first fix.

The vehicle's reference point
-----------------------------
The trackers and detectors report a vehicle at the centre of its footprint (the centre of its
box, projected on the ground; :class:`wz_shared.messages.VehicleTruth` is the same point). The
GPS antenna sits elsewhere on the roof, so :func:`gps_track` moves each fix from the antenna to
that centre, given where the antenna is on the vehicle: ``antenna_forward_m`` ahead of the
centre (negative: behind it) and ``antenna_left_m`` to its left.
"""

from __future__ import annotations

import calendar
import csv
import datetime as dt
import logging
import math
import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wz_drivers.records import FieldDataError, GpsFix, Problems
from wz_shared.arrays import F64
from wz_shared.site import Site

log = logging.getLogger(__name__)


#: One knot [m/s] (1852 m per hour).
KNOT_MPS = 1852.0 / 3600.0
_KMH_MPS = 1.0 / 3.6
_DAY_S = 86400.0
#: A time of day that drops by more than this from one epoch to the next has crossed midnight;
#: a smaller drop is time going back.
_ROLLOVER_S = 43200.0
#: Unix time of 2000-01-01: a "Unix time" before it is a relative time or GPS seconds.
_YEAR_2000_S = 946684800.0
_NMEA_ADDRESS = re.compile(r"\$[A-Z]{5},")


# --- NMEA 0183 --------------------------------------------------------------------------------


def nmea_checksum(body: str) -> str:
    """The checksum of a sentence's body (the text between ``$`` and ``*``): the XOR of its
    characters, as two upper-case hex digits."""
    value = 0
    for char in body:
        value ^= ord(char)
    return f"{value:02X}"


def _checked_fields(sentence: str) -> list[str]:
    """Fields of ``$BODY*hh`` (the address first), after verifying the checksum."""
    star = sentence.rfind("*")
    if star < 0:
        raise ValueError("no checksum (*hh) at the end of the sentence")
    body, given = sentence[1:star], sentence[star + 1 :].strip()
    computed = nmea_checksum(body)
    if given.upper() != computed:
        raise ValueError(
            f"bad checksum: the sentence says *{given}, its characters give *{computed} "
            "(a corrupted or truncated line)"
        )
    return body.split(",")


def _time_of_day_s(text: str) -> float:
    """``hhmmss.ss`` -> seconds since midnight (UTC)."""
    if len(text) < 6:
        raise ValueError(f"time {text!r} is not hhmmss.ss")
    hours, minutes, seconds = int(text[0:2]), int(text[2:4]), float(text[4:])
    if hours > 23 or minutes > 59 or not 0.0 <= seconds < 61.0:
        raise ValueError(f"time {text!r} is not a time of day (hhmmss.ss)")
    return hours * 3600.0 + minutes * 60.0 + seconds


def _angle_deg(text: str, hemisphere: str, *, latitude: bool) -> float:
    """``ddmm.mmmm`` (latitude) or ``dddmm.mmmm`` (longitude) and N/S/E/W -> signed degrees."""
    dot = text.find(".")
    whole = len(text) if dot < 0 else dot
    if whole < 3:
        raise ValueError(f"{'latitude' if latitude else 'longitude'} {text!r} is not [d]ddmm.mmmm")
    degrees = int(text[: whole - 2])
    minutes = float(text[whole - 2 :])
    value = degrees + minutes / 60.0
    signs = {"N": 1.0, "S": -1.0} if latitude else {"E": 1.0, "W": -1.0}
    if hemisphere not in signs or minutes >= 60.0 or value > (90.0 if latitude else 180.0):
        raise ValueError(
            f"{'latitude' if latitude else 'longitude'} {text!r} {hemisphere!r} is out of range"
        )
    return signs[hemisphere] * value


def _field(fields: list[str], index: int) -> str:
    return fields[index].strip() if index < len(fields) else ""


def _optional_float(text: str, what: str) -> float | None:
    if not text:
        return None
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"{what} {text!r} is not a number") from None
    if not math.isfinite(value):
        raise ValueError(f"{what} {text!r} is not a finite number")
    return value


@dataclass
class _Epoch:
    """The sentences of one epoch, merged; ``line``: the first sentence's line."""

    time_key_ms: int
    time_of_day_s: float
    line: int
    date: dt.date | None = None
    latitude_deg: float | None = None
    longitude_deg: float | None = None
    altitude_m: float | None = None
    quality: int | None = None
    has_gga: bool = False
    gga_line: int | None = None
    rmc_line: int | None = None
    rmc_valid: bool | None = None
    rmc_latitude_deg: float | None = None
    rmc_longitude_deg: float | None = None
    rmc_speed_mps: float | None = None
    rmc_course_deg: float | None = None
    vtg_speed_mps: float | None = None
    vtg_course_deg: float | None = None

    def add_gga(self, fields: list[str]) -> None:
        # $--GGA,time,lat,N,lon,E,quality,satellites,hdop,altitude,M,geoid separation,M,age,station
        if self.has_gga:
            return  # the same epoch from a second talker: the first is kept
        quality = _field(fields, 6)
        latitude = longitude = None
        if _field(fields, 2):
            latitude = _angle_deg(_field(fields, 2), _field(fields, 3), latitude=True)
            longitude = _angle_deg(_field(fields, 4), _field(fields, 5), latitude=False)
        altitude = _optional_float(_field(fields, 9), "altitude")
        separation = _optional_float(_field(fields, 11), "geoid separation")
        self.has_gga = True
        self.quality = int(quality) if quality else None
        self.latitude_deg, self.longitude_deg = latitude, longitude
        # GGA's altitude is above mean sea level (the geoid); the ellipsoid height the site
        # frame uses is that plus the geoid's separation, where the receiver gives it.
        if altitude is not None:
            self.altitude_m = altitude + (separation or 0.0)

    def add_rmc(self, fields: list[str]) -> None:
        # $--RMC,time,status,lat,N,lon,E,speed [kn],course [deg true],ddmmyy,variation,E,mode
        latitude = longitude = None
        if _field(fields, 3):
            latitude = _angle_deg(_field(fields, 3), _field(fields, 4), latitude=True)
            longitude = _angle_deg(_field(fields, 5), _field(fields, 6), latitude=False)
        speed_kn = _optional_float(_field(fields, 7), "speed over ground")
        course = _optional_float(_field(fields, 8), "course over ground")
        date = _field(fields, 9)
        if date:
            if len(date) != 6 or not date.isdigit():
                raise ValueError(f"date {date!r} is not ddmmyy")
            year = int(date[4:6])
            self.date = dt.date(
                year + (2000 if year < 80 else 1900), int(date[2:4]), int(date[0:2])
            )
        self.rmc_valid = _field(fields, 2) == "A"
        self.rmc_latitude_deg, self.rmc_longitude_deg = latitude, longitude
        self.rmc_speed_mps = None if speed_kn is None else speed_kn * KNOT_MPS
        self.rmc_course_deg = course

    def add_vtg(self, fields: list[str]) -> None:
        # $--VTG,course [deg true],T,course [deg magnetic],M,speed [kn],N,speed [km/h],K,mode
        course = _optional_float(_field(fields, 1), "course over ground")
        speed_kn = _optional_float(_field(fields, 5), "speed over ground")
        speed_kmh = _optional_float(_field(fields, 7), "speed over ground")
        self.vtg_course_deg = course
        if speed_kn is not None:
            self.vtg_speed_mps = speed_kn * KNOT_MPS
        elif speed_kmh is not None:
            self.vtg_speed_mps = speed_kmh * _KMH_MPS

    def position(self) -> tuple[float, float] | None:
        """Latitude and longitude [deg]: GGA's, else RMC's; None without either."""
        if self.latitude_deg is not None and self.longitude_deg is not None:
            return self.latitude_deg, self.longitude_deg
        if self.rmc_latitude_deg is not None and self.rmc_longitude_deg is not None:
            return self.rmc_latitude_deg, self.rmc_longitude_deg
        return None

    def problem(self) -> tuple[str, int] | None:
        """Why this epoch gives no fix, and the line to blame; None if it gives one."""
        if self.has_gga and self.quality == 0:
            return "GGA fix quality 0 (no fix)", self.gga_line or self.line
        if self.rmc_valid is False:
            return "RMC status V (the receiver marks the fix invalid)", self.rmc_line or self.line
        if self.position() is None:
            return "no position in the epoch's sentences", self.line
        return None

    def fix(self, stamp: float) -> GpsFix | None:
        """The fix, or None without a position."""
        position = self.position()
        if position is None:
            return None
        speed = self.rmc_speed_mps if self.rmc_speed_mps is not None else self.vtg_speed_mps
        course = self.rmc_course_deg if self.rmc_course_deg is not None else self.vtg_course_deg
        return GpsFix(
            stamp=stamp,
            latitude_deg=position[0],
            longitude_deg=position[1],
            altitude_m=self.altitude_m,
            speed_mps=speed,
            heading_deg=course,
            quality=self.quality,
        )


def _unix_s(date: dt.date, time_of_day_s: float) -> float:
    return float(calendar.timegm(date.timetuple())) + time_of_day_s


def _clock(seconds: float) -> str:
    """Seconds of the day as ``hh:mm:ss.ss``."""
    hours, rest = divmod(seconds, 3600.0)
    minutes, secs = divmod(rest, 60.0)
    return f"{int(hours):02d}:{int(minutes):02d}:{secs:05.2f}"


class _NmeaEpochs:
    """Dates the epochs (RMC's date, a midnight rollover, the caller's date, or back from the
    first RMC) and turns them into fixes in time order; what cannot be used goes to problems."""

    def __init__(self, path: Path, problems: Problems, date: dt.date | None) -> None:
        self.path = path
        self.problems = problems
        self.date = date  # of the last dated epoch (at first, the caller's)
        self.last_time_of_day_s: float | None = None
        self.last_stamp = -math.inf
        self.undated: list[_Epoch] = []

    def close(self, epoch: _Epoch) -> list[GpsFix]:
        """The fixes that this epoch completes (itself, and any waiting for a date)."""
        date = epoch.date
        if date is None and self.date is not None:
            date = self.date
            if self.last_time_of_day_s is not None:
                if epoch.time_of_day_s < self.last_time_of_day_s - _ROLLOVER_S:
                    date += dt.timedelta(days=1)  # past midnight
                elif epoch.time_of_day_s > self.last_time_of_day_s + _ROLLOVER_S:
                    date -= dt.timedelta(days=1)  # back across midnight: reported below
        if date is None:
            self.undated.append(epoch)  # dated when the first RMC comes
            return []
        self.date, self.last_time_of_day_s = date, epoch.time_of_day_s
        dated = self._date_back(date, epoch.time_of_day_s)
        dated.append((epoch, date))
        return [fix for e, d in dated if (fix := self._fix(e, d)) is not None]

    def _date_back(self, date: dt.date, time_of_day_s: float) -> list[tuple[_Epoch, dt.date]]:
        """The epochs before the first date, dated back from it (a midnight between them
        crossed)."""
        dated: list[tuple[_Epoch, dt.date]] = []
        for epoch in reversed(self.undated):
            if epoch.time_of_day_s > time_of_day_s + _ROLLOVER_S:
                date -= dt.timedelta(days=1)
            elif epoch.time_of_day_s < time_of_day_s - _ROLLOVER_S:
                date += dt.timedelta(days=1)
            dated.append((epoch, date))
            time_of_day_s = epoch.time_of_day_s
        self.undated.clear()
        return dated[::-1]

    def _fix(self, epoch: _Epoch, date: dt.date) -> GpsFix | None:
        problem = epoch.problem()
        stamp = _unix_s(date, epoch.time_of_day_s)
        if problem is None and stamp <= self.last_stamp:
            back = (
                f"time goes back: {_clock(epoch.time_of_day_s)} UTC is not after the "
                f"previous fix ({self.last_stamp - stamp:.3f} s earlier)"
            )
            problem = back, epoch.line
        if problem is not None:
            self.problems.add(FieldDataError(self.path, problem[0], line=problem[1]))
            return None
        self.last_stamp = stamp
        return epoch.fix(stamp)

    def finish(self) -> None:
        """Report the epochs that never got a date."""
        for epoch in self.undated:
            self.problems.add(
                FieldDataError(
                    self.path,
                    "no date for this fix: no RMC sentence in the log gives one (GGA "
                    "has only the time of day); pass the day of the drive (date=...)",
                    line=epoch.line,
                )
            )
        self.undated.clear()


def read_nmea(path: Path, problems: Problems, *, date: dt.date | None = None) -> Iterator[GpsFix]:
    """The fixes of an NMEA 0183 log, one per epoch, in time order.

    Parameters
    ----------
    path : Path
        A text file of NMEA sentences, one a line; text before the ``$`` of a line (a logger's
        own stamp) is ignored.
    problems : Problems
        Collects the sentences and epochs skipped.
    date : datetime.date, optional
        The UTC day of the log's first epoch, for the epochs before its first RMC sentence (GGA
        carries only the time of day). Without it those epochs are dated back from the first
        RMC's date (their times of day are before it, a midnight between crossed), and reported
        if the log has no RMC at all.

    Yields
    ------
    GpsFix
        ``stamp`` in Unix seconds (UTC; a midnight crossed in GGA-only stretches moves to the
        next day), position from GGA (else RMC), ``altitude_m`` the ellipsoid height (GGA's
        altitude above sea level plus its geoid separation, where given), ``quality`` GGA's
        fix quality, ``speed_mps`` and ``heading_deg`` (course over ground, clockwise from true
        north) from RMC, else VTG.

    Raises
    ------
    FieldDataError
        When called, if the file cannot be opened.

    Notes
    -----
    Sentences are merged into an epoch while their time of day stays the same; VTG carries no
    time, so it belongs to the epoch of the sentence before it (receivers send it after the
    epoch's GGA or RMC). Reported and skipped: a line that is not a sentence, a bad or missing
    checksum, a field that cannot be read, an epoch with GGA fix quality 0 or RMC status V, an
    epoch without a position, and an epoch not after the previous fix (time going back).
    Sentences of other types (GSA, GSV, ...) are ignored. Other fix qualities (5: RTK float,
    6: dead reckoning, as an INS bridges an outage) are kept, in ``quality``, for the caller
    to filter.
    """
    path = Path(path)
    if not path.is_file():
        raise FieldDataError(path, "no such file (an NMEA log of the GPS van was expected)")
    return _read_nmea(path, problems, date)


def _read_nmea(path: Path, problems: Problems, date: dt.date | None) -> Iterator[GpsFix]:
    epochs = _NmeaEpochs(path, problems, date)
    current: _Epoch | None = None
    with path.open("r", encoding="ascii", errors="replace", newline="") as lines:
        for number, raw in enumerate(lines, start=1):
            text = raw.strip()
            if not text:
                continue
            start = text.find("$")
            if start < 0:
                problems.add(FieldDataError(path, "not an NMEA sentence (no '$')", line=number))
                continue
            try:
                kind, fields, time_key_ms, time_of_day_s = _parse_sentence(text[start:])
            except ValueError as exc:
                problems.add(FieldDataError(path, f"{text[start : start + 6]}: {exc}", line=number))
                continue
            if kind == "VTG":
                if current is None:
                    continue  # a VTG before any epoch: no time to put it at
                target = current
            elif kind in ("GGA", "RMC"):
                if current is not None and current.time_key_ms != time_key_ms:
                    yield from epochs.close(current)
                    current = None
                target = (
                    current if current is not None else _Epoch(time_key_ms, time_of_day_s, number)
                )
            else:
                continue
            try:
                {"GGA": target.add_gga, "RMC": target.add_rmc, "VTG": target.add_vtg}[kind](fields)
            except ValueError as exc:
                problems.add(FieldDataError(path, f"{text[start : start + 6]}: {exc}", line=number))
                continue  # a new epoch whose first sentence is bad is not started
            if kind == "GGA":
                target.gga_line = target.gga_line or number
            elif kind == "RMC":
                target.rmc_line = target.rmc_line or number
            current = target
    if current is not None:
        yield from epochs.close(current)
    epochs.finish()


def _parse_sentence(sentence: str) -> tuple[str, list[str], int, float]:
    """The sentence type (``GGA``; empty for proprietary ones), its fields (the address first),
    and for GGA and RMC their time of day as a key [ms] and in seconds."""
    fields = _checked_fields(sentence)
    address = fields[0]
    kind = address[2:] if len(address) == 5 and not address.startswith("P") else ""
    if kind not in ("GGA", "RMC"):
        return kind, fields, -1, math.nan
    time_of_day_s = _time_of_day_s(_field(fields, 1))
    return kind, fields, round(time_of_day_s * 1000.0), time_of_day_s


# --- CSV -------------------------------------------------------------------------------------

#: Required columns: the accepted names of each, the first preferred.
CSV_REQUIRED = {
    "time_unix_s": ("time_unix_s", "time"),
    "latitude_deg": ("latitude_deg", "lat"),
    "longitude_deg": ("longitude_deg", "lon"),
}
CSV_OPTIONAL = ("altitude_m", "speed_mps", "heading_deg", "quality")


def _accepted_names() -> str:
    required = ", ".join(
        f"{names[0]} (or {', '.join(names[1:])})" for names in CSV_REQUIRED.values()
    )
    return f"a GPS CSV needs {required}, and may have {', '.join(CSV_OPTIONAL)}"


def _csv_columns(path: Path, header: list[str]) -> dict[str, int]:
    """Column index of each known column, by its canonical name."""
    names = [name.strip().lower() for name in header]
    columns: dict[str, int] = {}
    missing = []
    for canonical, accepted in CSV_REQUIRED.items():
        found = [name for name in accepted if name in names]
        if not found:
            missing.append(canonical)
        elif len(found) > 1:
            raise FieldDataError(
                path, f"columns {' and '.join(found)} both give {canonical}: keep one", line=1
            )
        else:
            columns[canonical] = names.index(found[0])
    if missing:
        raise FieldDataError(
            path,
            f"missing column(s) {', '.join(missing)}; {_accepted_names()}; the header has "
            f"{', '.join(repr(n) for n in header) or 'no columns'}",
            line=1,
        )
    for name in CSV_OPTIONAL:
        if name in names:
            columns[name] = names.index(name)
    return columns


def _csv_time(text: str) -> float:
    """Unix seconds, or an ISO 8601 time with its UTC offset."""
    try:
        value = float(text)
    except ValueError:
        try:
            moment = dt.datetime.fromisoformat(text.replace("Z", "+00:00"))
        except ValueError:
            raise ValueError(f"time {text!r} is neither Unix seconds nor ISO 8601") from None
        if moment.tzinfo is None:
            raise ValueError(f"time {text!r} has no UTC offset (add Z or +00:00)") from None
        return moment.timestamp()
    if not math.isfinite(value):
        raise ValueError(f"time {text!r} is not a finite number")
    if value < _YEAR_2000_S:
        raise ValueError(
            f"time {text!r} is before 2000: not Unix seconds (a relative time, or "
            "GPS seconds of the week?)"
        )
    return value


def read_gps_csv(path: Path, problems: Problems) -> Iterator[GpsFix]:
    """The fixes of a CSV log, in time order.

    The first line is the header: ``time_unix_s`` (or ``time``; Unix seconds, or ISO 8601 with
    a UTC offset), ``latitude_deg`` (or ``lat``), ``longitude_deg`` (or ``lon``) and,
    optionally, ``altitude_m`` (ellipsoid height), ``speed_mps``, ``heading_deg`` (course over
    ground, clockwise from true north) and ``quality`` (GGA's fix quality); names are matched
    ignoring case, other columns are ignored. An empty optional cell is unknown.

    Raises
    ------
    FieldDataError
        When called, if the file cannot be opened or its header lacks a required column (line
        1, naming the missing columns and the accepted names).

    Notes
    -----
    Reported and skipped: a row with the wrong number of cells, a value that cannot be read or
    is out of range, quality 0 (no fix), and a row not after the previous fix.
    """
    path = Path(path)
    try:
        with path.open("r", encoding="utf-8-sig", newline="") as stream:
            header = next(csv.reader(stream), [])
    except (OSError, UnicodeDecodeError) as exc:
        raise FieldDataError(path, f"cannot read the GPS CSV: {exc}") from exc
    columns = _csv_columns(path, header)
    return _read_gps_csv(path, problems, columns, len(header))


def _read_gps_csv(
    path: Path, problems: Problems, columns: dict[str, int], width: int
) -> Iterator[GpsFix]:
    last_stamp = -math.inf
    with path.open("r", encoding="utf-8-sig", newline="") as stream:
        reader = csv.reader(stream)
        next(reader, None)
        for row in reader:
            number = reader.line_num
            if not any(cell.strip() for cell in row):
                continue
            try:
                if len(row) != width:
                    raise ValueError(f"{len(row)} cells, the header has {width}")
                cell = {name: row[index].strip() for name, index in columns.items()}
                stamp = _csv_time(cell["time_unix_s"])
                latitude = _optional_float(cell["latitude_deg"], "latitude_deg")
                longitude = _optional_float(cell["longitude_deg"], "longitude_deg")
                if latitude is None or longitude is None:
                    raise ValueError("no position")
                if abs(latitude) > 90.0 or abs(longitude) > 180.0:
                    raise ValueError(f"position {latitude}, {longitude} is not in degrees")
                quality_text = cell.get("quality", "")
                quality = int(quality_text) if quality_text else None
                if quality == 0:
                    raise ValueError("quality 0 (no fix)")
                speed = _optional_float(cell.get("speed_mps", ""), "speed_mps")
                if speed is not None and speed < 0.0:
                    raise ValueError(f"speed_mps {speed} is negative")
                if stamp <= last_stamp:
                    raise ValueError(
                        f"time goes back: {stamp:.3f} is not after the previous "
                        f"fix {last_stamp:.3f}"
                    )
            except ValueError as exc:
                problems.add(FieldDataError(path, str(exc), line=number))
                continue
            last_stamp = stamp
            yield GpsFix(
                stamp=stamp,
                latitude_deg=latitude,
                longitude_deg=longitude,
                altitude_m=_optional_float(cell.get("altitude_m", ""), "altitude_m"),
                speed_mps=speed,
                heading_deg=_optional_float(cell.get("heading_deg", ""), "heading_deg"),
                quality=quality,
            )


def read_gps(path: Path, problems: Problems, *, date: dt.date | None = None) -> Iterator[GpsFix]:
    """The fixes of a GPS log, NMEA 0183 or CSV, told apart by content: NMEA if one of its first
    lines holds a sentence (``$GPGGA,`` ...), else a CSV with a header (a ``.csv`` file always).

    Raises
    ------
    FieldDataError
        If the file is missing, or neither NMEA nor a CSV with the needed columns.
    """
    path = Path(path)
    if not path.is_file():
        raise FieldDataError(path, "no such file (a GPS log, NMEA or CSV, was expected)")
    if path.suffix.lower() != ".csv":
        with path.open("r", encoding="ascii", errors="replace") as stream:
            head = [stream.readline() for _ in range(20)]
        if any(_NMEA_ADDRESS.search(line) for line in head):
            return read_nmea(path, problems, date=date)
    return read_gps_csv(path, problems)


# --- to the site and road frames ---------------------------------------------------------------


@dataclass(frozen=True)
class GpsTrack:
    """The GPS vehicle's reference point (the centre of its footprint) over time.

    All arrays have shape (N,), in time order: ``t`` Unix seconds; ``x_m``, ``y_m`` site frame
    (east, north) [m]; ``station_m``, ``offset_m`` road frame [m] (offset positive to the
    left); ``speed_mps`` ground speed (NaN where unknown); ``heading_rad`` the vehicle's heading,
    counter-clockwise from the site x axis (east), in (-pi, pi].
    """

    t: F64
    x_m: F64
    y_m: F64
    station_m: F64
    offset_m: F64
    speed_mps: F64
    heading_rad: F64

    def __len__(self) -> int:
        return int(self.t.size)


def _track_headings(x_m: F64, y_m: F64, baseline_m: float) -> F64:
    """Heading of the direction the track moves at each point [rad], NaN where it never moves
    ``baseline_m``.

    Points are kept as keyframes when at least ``baseline_m`` from the previous keyframe, so a
    stop (whose fixes jitter by centimetres) adds none; each point takes the direction of the
    chord from its keyframe to the next one (the last keyframe's points: of the last chord).
    """
    keyframes = [0]
    for i in range(1, x_m.size):
        k = keyframes[-1]
        if math.hypot(x_m[i] - x_m[k], y_m[i] - y_m[k]) >= baseline_m:
            keyframes.append(i)
    if len(keyframes) < 2:
        return np.full(x_m.shape, np.nan)
    keys = np.asarray(keyframes)
    chord_heading = np.arctan2(np.diff(y_m[keys]), np.diff(x_m[keys]))
    segment = np.searchsorted(keys, np.arange(x_m.size), side="right") - 1
    result: F64 = chord_heading[np.minimum(segment, chord_heading.size - 1)]
    return result


def gps_track(
    fixes: Iterable[GpsFix],
    site: Site,
    *,
    antenna_forward_m: float = 0.0,
    antenna_left_m: float = 0.0,
    moving_speed_mps: float = 1.0,
    heading_baseline_m: float = 1.0,
) -> GpsTrack:
    """The fixes in the site and road frames, moved from the antenna to the reference point.

    Parameters
    ----------
    fixes : iterable of GpsFix
        In strictly increasing time order (as the readers give them).
    site : Site
        Its ``geo_frame`` (local ENU at the site origin, with pyproj) takes WGS84 to the site
        frame (a fix without altitude takes the origin's); its ``road_frame`` gives station and
        offset.
    antenna_forward_m, antenna_left_m : float
        Where the antenna is on the vehicle: ahead of and to the left of the centre of its
        footprint [m] (negative: behind, to the right).
    moving_speed_mps : float
        Below this speed the course over ground is not used for the heading.
    heading_baseline_m : float
        Distance [m] over which the track's own direction is taken where there is no course.

    Returns
    -------
    GpsTrack
        The reference point: ``antenna - R(heading) [forward, left]``.

    Raises
    ------
    ValueError
        If there are no fixes or their stamps do not increase.

    Notes
    -----
    The heading is the course over ground (``90 deg - course``, in the site frame) where the
    fix has one and the vehicle moves at ``moving_speed_mps`` or more; elsewhere the direction
    of the antenna's own track (see :func:`_track_headings`); where the vehicle never moved
    that far, the road's heading at its station. The vehicle is assumed to drive forwards. The
    site frame's north is true north at the origin, off by under 0.01 deg within 1 km of it.
    ``speed_mps`` is the fix's speed where given, else the antenna's speed by central
    differences (the two points differ only while turning, by yaw rate x lever arm).
    """
    listed = list(fixes)
    if not listed:
        raise ValueError("no GPS fixes")
    t = np.array([fix.stamp for fix in listed], dtype=np.float64)
    if np.any(np.diff(t) <= 0.0):
        i = int(np.flatnonzero(np.diff(t) <= 0.0)[0])
        raise ValueError(
            f"GPS fix stamps must increase: fix {i + 1} at {t[i + 1]:.3f} s is not "
            f"after fix {i} at {t[i]:.3f} s"
        )
    geo = site.geo_frame
    latitude = np.array([fix.latitude_deg for fix in listed], dtype=np.float64)
    longitude = np.array([fix.longitude_deg for fix in listed], dtype=np.float64)
    altitude = np.array(
        [geo.altitude_m if fix.altitude_m is None else fix.altitude_m for fix in listed],
        dtype=np.float64,
    )
    antenna_x, antenna_y, _ = geo.to_site(latitude, longitude, altitude)

    speed = np.array(
        [np.nan if fix.speed_mps is None else fix.speed_mps for fix in listed], dtype=np.float64
    )
    if t.size >= 2:
        differentiated = np.hypot(np.gradient(antenna_x, t), np.gradient(antenna_y, t))
        speed = np.where(np.isnan(speed), differentiated, speed)

    course_deg = np.array(
        [np.nan if fix.heading_deg is None else fix.heading_deg for fix in listed], dtype=np.float64
    )
    heading = np.where(speed >= moving_speed_mps, np.radians(90.0 - course_deg), np.nan)
    heading = np.where(
        np.isnan(heading), _track_headings(antenna_x, antenna_y, heading_baseline_m), heading
    )
    if np.any(np.isnan(heading)):
        road = site.road_frame
        station, _ = road.to_road(antenna_x, antenna_y)
        heading = np.where(np.isnan(heading), road.heading_at(station), heading)
    heading = np.arctan2(np.sin(heading), np.cos(heading))

    # antenna = reference + R(heading) [forward, left]
    cos_h, sin_h = np.cos(heading), np.sin(heading)
    x = antenna_x - (antenna_forward_m * cos_h - antenna_left_m * sin_h)
    y = antenna_y - (antenna_forward_m * sin_h + antenna_left_m * cos_h)
    station_m, offset_m = site.road_frame.to_road(x, y)
    return GpsTrack(
        t=t,
        x_m=x,
        y_m=y,
        station_m=station_m,
        offset_m=offset_m,
        speed_mps=speed,
        heading_rad=heading,
    )
