"""Object lists of a radar or radar-camera unit (CSV, JSON Lines, live UDP) to
:class:`ObjectList` records.

Columns and keys (names compared lower-case; the first listed is the canonical one)
-----------------------------------------------------------------------------------
=====================  ==========================  ==========================================
what                   accepted names              notes
=====================  ==========================  ==========================================
time (required)        ``time_unix_s``, ``time``   Unix seconds of the report
position (required)    ``x_m`` + ``y_m``           sensor frame: x along the boresight, y left
  or                   ``range_m`` + ``azimuth_deg``  range >= 0; azimuth counter-clockwise
                                                   from the boresight (positive to the left,
                                                   as y); ``x = r cos(az)``, ``y = r sin(az)``
object id              ``id``, ``object_id``       integer >= 0; optional
speed                  ``speed_mps``               as the unit reports it; optional
class                  ``class``, ``object_class`` see :data:`CLASS_NAMES`; anything else
                                                   (pedestrian, bicycle, a code) is unknown
size                   ``length_m``, ``width_m``   >= 0; optional
=====================  ==========================  ==========================================

Other columns or keys (rcs, vx, lane ...) are ignored.

CSV
    A header row is required; a file without the time or the position columns raises
    :class:`FieldDataError` (line 1, naming what is missing and the accepted names). When a
    header has both, ``x_m``/``y_m`` are used. Rows with the same time form one report; rows
    must come in time order. A row whose cells other than the time are all empty is a report
    with no objects (the unit saw nothing at that time).
JSON Lines (``.jsonl``, ``.ndjson``, ``.json``, or a file starting with ``{``)
    One report per line: ``{"time": 1700000000.05, "objects": [{"id": 3, "x_m": 41.2,
    "y_m": -1.8, "class": "car"}, ...]}`` (``time_unix_s`` also accepted); ``objects`` may be
    empty. Each object picks its own position keys. Consecutive lines with the same time are
    merged, as CSV rows are.
UDP (:func:`listen_udp`)
    Each datagram is one JSON report as a JSON Lines line (UTF-8); without a time it is stamped
    with its arrival (wall clock). Each datagram is its own report (none are merged).

Bad input
    A row, line or datagram that cannot be used (not numbers, NaN, a negative range or size,
    a time that goes back) is reported with its file and line (or sender and datagram number)
    and skipped; in a JSON report only the bad object is skipped, the others are kept.
"""

from __future__ import annotations

import csv
import json
import logging
import math
import socket
import threading
import time
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path

from wz_drivers.records import FieldDataError, ObjectList, Problems, RadarObject
from wz_shared.messages import VehicleClass

log = logging.getLogger(__name__)

#: Accepted column / key names -> the canonical key used below.
ALIASES: Mapping[str, str] = {
    "time_unix_s": "time",
    "time": "time",
    "id": "id",
    "object_id": "id",
    "x_m": "x",
    "y_m": "y",
    "range_m": "range",
    "azimuth_deg": "azimuth",
    "speed_mps": "speed",
    "class": "class",
    "object_class": "class",
    "length_m": "length",
    "width_m": "width",
}
#: Canonical key -> the name error messages show.
SHOWN: Mapping[str, str] = {
    "x": "x_m",
    "y": "y_m",
    "range": "range_m",
    "azimuth": "azimuth_deg",
    "speed": "speed_mps",
    "length": "length_m",
    "width": "width_m",
}
#: Class names (lower-case; spaces and hyphens read as underscores) -> vehicle class.
CLASS_NAMES: Mapping[str, VehicleClass] = {
    **{
        name: VehicleClass.CAR
        for name in ("car", "passenger_car", "sedan", "suv", "van", "pickup", "light_vehicle")
    },
    **{
        name: VehicleClass.TRUCK
        for name in (
            "truck",
            "lorry",
            "hgv",
            "heavy_vehicle",
            "semi",
            "semi_truck",
            "tractor_trailer",
            "trailer",
        )
    },
    **{name: VehicleClass.BUS for name in ("bus", "coach")},
    **{name: VehicleClass.MOTORCYCLE for name in ("motorcycle", "motorbike", "moto")},
}
#: What the required columns are called, for error messages.
TIME_HELP = "time (time_unix_s or time)"
POSITION_HELP = "position (x_m and y_m, or range_m and azimuth_deg)"
#: Largest UDP payload [bytes].
MAX_DATAGRAM_BYTES = 65_535


class _BadValueError(ValueError):
    """Why one row, object or report cannot be used (no location: the caller adds it)."""


# --- public entry points --------------------------------------------------------------------


def read_objects(path: Path, problems: Problems) -> Iterator[ObjectList]:
    """Yield the reports of a CSV or JSON Lines object-list log, in file order.

    Parameters
    ----------
    path
        The log (format by suffix: ``.csv``; ``.jsonl``, ``.ndjson``, ``.json``; otherwise
        JSON Lines when the first character is ``{``, else CSV).
    problems
        Receives a :class:`FieldDataError` (file and line) per skipped row, line or object.

    Raises
    ------
    FieldDataError
        The file is missing or unreadable, empty, or (CSV) its header lacks the time or the
        position columns.
    """
    path = Path(path)
    try:
        # Undecodable bytes become U+FFFD: that row then fails alone, not the whole file.
        with path.open(encoding="utf-8-sig", errors="replace", newline="") as stream:
            first = stream.read(4096).lstrip()
            stream.seek(0)
            if not first:
                raise FieldDataError(path, "empty file: no header or report", line=1)
            suffix = path.suffix.lower()
            json_lines = suffix in (".jsonl", ".ndjson", ".json") or (
                suffix != ".csv" and first.startswith("{")
            )
            reader = _jsonl_reports if json_lines else _csv_reports
            reports = reader(path, stream, problems)
            yield from _grouped(path, reports, problems)
    except FileNotFoundError:
        raise FieldDataError(path, "no such file") from None
    except IsADirectoryError:
        raise FieldDataError(path, "a folder, not a file") from None
    except OSError as exc:
        raise FieldDataError(path, f"cannot read: {exc.strerror or exc}") from None


def listen_udp(
    host: str, port: int, problems: Problems, *, stop: threading.Event, poll_s: float = 0.1
) -> Iterator[ObjectList]:
    """Bind a UDP socket now and yield one report per JSON datagram until ``stop`` is set.

    The socket is bound before this returns (datagrams that arrive before iteration starts
    wait in the socket's buffer) and closed when the iterator ends or is closed; an iterator
    never started keeps it until it is garbage-collected.

    Parameters
    ----------
    host, port
        Where to listen (``0.0.0.0`` for every interface; port 0 picks a free one, logged).
    problems
        Receives a :class:`FieldDataError` per bad datagram (named by sender and datagram
        number) or bad object.
    stop
        Set to end the iteration (checked every ``poll_s`` [s] and after each datagram).

    Raises
    ------
    FieldDataError
        The address cannot be bound (in use, not an address of this machine).
    """
    where = f"udp://{host}:{port}"
    try:
        family, kind, proto, _, address = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)[0]
        sock = socket.socket(family, kind, proto)
    except OSError as exc:
        raise FieldDataError(where, f"cannot listen: {exc}") from None
    try:
        sock.bind(address)
    except OSError as exc:
        sock.close()
        raise FieldDataError(where, f"cannot listen: {exc.strerror or exc}") from None
    sock.settimeout(poll_s)
    bound = sock.getsockname()
    log.info("listening for object lists on udp://%s:%s", bound[0], bound[1])
    return _receive(sock, problems, stop)


# --- one object, one report -----------------------------------------------------------------


def _number(values: Mapping[str, object], key: str) -> float | None:
    """The finite number under ``key``; None when absent or empty."""
    value = values.get(key)
    if value is None or (isinstance(value, str) and not value.strip()):
        return None
    shown = SHOWN.get(key, key)
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise _BadValueError(f"{shown} {value!r} is not a number")
    try:
        number = float(value)
    except ValueError:
        raise _BadValueError(f"{shown} {value!r} is not a number") from None
    if not math.isfinite(number):
        raise _BadValueError(f"{shown} is {number}")
    return number


def _required(values: Mapping[str, object], key: str) -> float:
    number = _number(values, key)
    if number is None:
        raise _BadValueError(f"no {SHOWN.get(key, key)}")
    return number


def _vehicle_class(value: object) -> VehicleClass:
    if not isinstance(value, str):
        return VehicleClass.UNKNOWN
    name = value.strip().lower().replace(" ", "_").replace("-", "_")
    return CLASS_NAMES.get(name, VehicleClass.UNKNOWN)


def _object(values: Mapping[str, object]) -> RadarObject:
    """One object from canonical keys (see :data:`ALIASES`); raise :class:`_BadValueError`."""
    if values.get("x") not in (None, "") or values.get("y") not in (None, ""):
        x_m, y_m = _required(values, "x"), _required(values, "y")
    elif values.get("range") not in (None, "") or values.get("azimuth") not in (None, ""):
        range_m, azimuth_deg = _required(values, "range"), _required(values, "azimuth")
        if range_m < 0.0:
            raise _BadValueError(f"range_m {range_m} is negative")
        azimuth_rad = math.radians(azimuth_deg)
        x_m, y_m = range_m * math.cos(azimuth_rad), range_m * math.sin(azimuth_rad)
    else:
        raise _BadValueError(f"no {POSITION_HELP}")
    object_id: int | None = None
    raw_id = _number(values, "id")
    if raw_id is not None:
        if raw_id < 0 or raw_id != int(raw_id):
            raise _BadValueError(f"id {values.get('id')!r} is not an integer >= 0")
        object_id = int(raw_id)
    sizes = {key: _number(values, key) for key in ("length", "width")}
    for key, size in sizes.items():
        if size is not None and size < 0.0:
            raise _BadValueError(f"{SHOWN[key]} {size} is negative")
    return RadarObject(
        x_m=x_m,
        y_m=y_m,
        object_id=object_id,
        speed_mps=_number(values, "speed"),
        object_class=_vehicle_class(values.get("class")),
        length_m=sizes["length"],
        width_m=sizes["width"],
    )


def _time(values: Mapping[str, object]) -> float:
    stamp = _required(values, "time")
    if stamp < 0.0:
        raise _BadValueError(f"time {stamp} is before 1970")
    return stamp


def _canonical(document: Mapping[str, object]) -> dict[str, object]:
    result: dict[str, object] = {}
    for key, value in document.items():
        name = ALIASES.get(str(key).strip().lower())
        if name is not None and name not in result:
            result[name] = value
    return result


def _json_report(text: str | bytes) -> tuple[float | None, list[RadarObject], list[str]]:
    """``(time or None, good objects, reasons for the bad ones)`` of one JSON report; raise
    :class:`_BadValueError` when the report as a whole is unusable."""
    try:
        document = json.loads(text)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise _BadValueError(f"not JSON: {exc}") from None
    if not isinstance(document, dict):
        raise _BadValueError(
            f"a JSON {type(document).__name__}, expected an object with time and objects"
        )
    report = _canonical(document)
    stamp = _time(report) if report.get("time") is not None else None
    entries = document.get("objects")
    if not isinstance(entries, list):
        raise _BadValueError('no objects list ("objects": [...], possibly empty)')
    objects: list[RadarObject] = []
    reasons: list[str] = []
    for index, entry in enumerate(entries):
        try:
            if not isinstance(entry, dict):
                raise _BadValueError(f"a JSON {type(entry).__name__}, expected an object")
            objects.append(_object(_canonical(entry)))
        except _BadValueError as bad:
            reasons.append(f"object {index}: {bad}: object skipped")
    return stamp, objects, reasons


# --- files ----------------------------------------------------------------------------------

#: (time, objects, line) of one row or line.
_Report = tuple[float, list[RadarObject], int]


def _csv_reports(path: Path, stream: Iterable[str], problems: Problems) -> Iterator[_Report]:
    reader = csv.reader(stream)
    header = next(reader, [])
    columns: dict[str, int] = {}
    for index, name in enumerate(header):
        key = ALIASES.get(name.strip().lower())
        if key is not None and key not in columns:
            columns[key] = index
    missing = [] if "time" in columns else [TIME_HELP]
    if not ({"x", "y"} <= columns.keys() or {"range", "azimuth"} <= columns.keys()):
        missing.append(POSITION_HELP)
    if missing:
        raise FieldDataError(
            path, f"missing columns: {'; '.join(missing)}; header: {','.join(header)}", line=1
        )
    if {"x", "y"} <= columns.keys():  # both forms given: use x, y only
        columns.pop("range", None)
        columns.pop("azimuth", None)
    for row in reader:
        line = reader.line_num
        if not any(cell.strip() for cell in row):
            continue
        if len(row) != len(header):
            problems.add(
                FieldDataError(
                    path, f"{len(row)} cells, the header has {len(header)}: row skipped", line=line
                )
            )
            continue
        values = {key: row[index] for key, index in columns.items()}
        try:
            stamp = _time(values)
            if not any(cell.strip() for i, cell in enumerate(row) if i != columns["time"]):
                yield stamp, [], line  # a report with no objects
                continue
            yield stamp, [_object(values)], line
        except _BadValueError as bad:
            problems.add(FieldDataError(path, f"{bad}: row skipped", line=line))


def _jsonl_reports(path: Path, stream: Iterable[str], problems: Problems) -> Iterator[_Report]:
    for line, text in enumerate(stream, start=1):
        if not text.strip():
            continue
        try:
            stamp, objects, reasons = _json_report(text)
            if stamp is None:
                raise _BadValueError(f"no {TIME_HELP}")
        except _BadValueError as bad:
            problems.add(FieldDataError(path, f"{bad}: report skipped", line=line))
            continue
        for reason in reasons:
            problems.add(FieldDataError(path, reason, line=line))
        yield stamp, objects, line


def _grouped(path: Path, reports: Iterator[_Report], problems: Problems) -> Iterator[ObjectList]:
    """Merge consecutive reports of the same time; report and skip those that go back."""
    current: float | None = None
    objects: list[RadarObject] = []
    first_line = 0
    for stamp, found, line in reports:
        if current is not None and stamp < current:
            problems.add(
                FieldDataError(
                    path,
                    f"time {stamp:.6f} goes back from {current:.6f} (line {first_line}): skipped",
                    line=line,
                )
            )
            continue
        if current is not None and stamp > current:
            yield ObjectList(stamp=current, objects=tuple(objects), where=f"{path}:{first_line}")
            objects = []
        if current is None or stamp > current:
            current, first_line = stamp, line
        objects.extend(found)
    if current is not None:
        yield ObjectList(stamp=current, objects=tuple(objects), where=f"{path}:{first_line}")


# --- UDP ------------------------------------------------------------------------------------


def _receive(
    sock: socket.socket, problems: Problems, stop: threading.Event
) -> Iterator[ObjectList]:
    host, port = sock.getsockname()[:2]
    count = 0
    previous: float | None = None
    try:
        while not stop.is_set():
            try:
                data, sender = sock.recvfrom(MAX_DATAGRAM_BYTES + 1)
            except TimeoutError:
                continue
            arrival = time.time()
            count += 1
            source = f"udp {sender[0]}:{sender[1]} -> {host}:{port}"
            try:
                stamp, objects, reasons = _json_report(data)
            except _BadValueError as bad:
                problems.add(
                    FieldDataError(source, f"{bad}: datagram skipped", line=count, unit="datagram")
                )
                continue
            stamp = arrival if stamp is None else stamp
            if previous is not None and stamp < previous:
                problems.add(
                    FieldDataError(
                        source,
                        f"time {stamp:.6f} goes back from {previous:.6f}: datagram skipped",
                        line=count,
                        unit="datagram",
                    )
                )
                continue
            for reason in reasons:
                problems.add(FieldDataError(source, reason, line=count, unit="datagram"))
            previous = stamp
            yield ObjectList(
                stamp=stamp, objects=tuple(objects), where=f"{source} (datagram {count})"
            )
    finally:
        sock.close()
