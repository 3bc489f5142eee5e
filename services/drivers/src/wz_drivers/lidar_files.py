"""LiDAR frames saved one file per sweep (PCD, PLY, NPZ) to :class:`LidarSweep` records.

Formats (parsed here with numpy only: Open3D drops intensity and organization)
-------------------------------------------------------------------------------
PCD (v0.7, and older headers with the same keywords)
    ``DATA ascii``, ``binary`` and ``binary_compressed`` (LZF, decompressed in pure Python:
    about 0.1 s per MB of points). Fields ``x y z`` and optionally ``intensity``
    in any order; other fields (rgb, normals, ring, time, PCL's ``_`` padding) are read past.
    Binary data is little-endian, as PCL writes it on every common machine. ``HEIGHT > 1`` is
    an organized frame: ``HEIGHT`` rows (beams) of ``WIDTH`` columns, row-major.
PLY
    ``ascii``, ``binary_little_endian`` and ``binary_big_endian``; the ``vertex`` element with
    properties ``x y z`` and optionally ``intensity`` (or CloudCompare's
    ``scalar_intensity``). Fixed-size elements before ``vertex`` are skipped; elements after it
    are ignored. A PLY cloud is unorganized.
NPZ
    Array ``points`` of shape ``(N, 3|4)`` (x y z [intensity]) or ``(rows, columns, 3|4)``
    (organized); optional scalars ``stamp`` (or ``stamp_s``, the simulator's export) [Unix s],
    and ``rows`` and ``columns`` to organize an ``(N, 3|4)`` array.

No-return points
----------------
The LiDAR detector marks a no-return slot of an organized frame with NaN x, y, z (its
background models skip non-finite rows). So here, in an organized frame, a point with a
non-finite coordinate or at exactly (0, 0, 0) (how Ouster and some Velodyne drivers write a
missing return) gets NaN x, y, z and keeps its slot; in an unorganized cloud such points are
dropped. A file without intensity gives NaN intensity (the detector's convention); intensity is
kept in the file's own scale (0-255 for many sensors, 0-1 in the simulator).

Time of a frame (:func:`read_frame_folder`)
-------------------------------------------
1. The ``timestamps`` CSV when given: a header with ``file`` and ``time_unix_s`` (or ``time``),
   one row per frame file (its name, relative to the folder), time in Unix seconds.
2. Else an NPZ frame's own ``stamp``.
3. Else the last number in the file name that reads as a Unix time between 2000 and 2100:
   seconds with or without a fraction (``1700000000.123456.pcd``, ROS ``bag_to_pcd``'s
   ``<sec>.<nsec>.pcd``), or an integer of milliseconds (13 digits), microseconds (16) or
   nanoseconds (19, ``lidar_1700000000123456789.pcd``). A frame counter (``000123.pcd``) is
   not a time.
4. Else the frame has no time: if no frame of the folder can have one, the folder raises
   :class:`FieldDataError`; otherwise that frame is reported and skipped.

Frames are taken in the natural order of their file names (numbers compared as numbers), and
each frame's time must be after the previous frame's: a frame whose time does not advance is
reported (naming the CSV line when its time came from the CSV) and skipped.
"""

from __future__ import annotations

import csv
import logging
import math
import re
import struct
import zipfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from decimal import Decimal
from pathlib import Path

import numpy as np
import numpy.typing as npt

from wz_drivers.records import FieldDataError, LidarSweep, Problems

log = logging.getLogger(__name__)

Float32Array = npt.NDArray[np.float32]
AnyArray = npt.NDArray[np.generic]

#: Suffixes of the files :func:`read_frame_folder` takes as frames (compared lower-case).
FRAME_SUFFIXES = (".pcd", ".ply", ".npz")
#: Field / property names taken as intensity (compared lower-case).
INTENSITY_NAMES = ("intensity", "scalar_intensity")
#: A header that has not ended within this many bytes is not a header.
MAX_HEADER_BYTES = 64 * 1024
#: Names of the timestamps CSV's columns (compared lower-case, first match wins).
FILE_COLUMN_NAMES = ("file",)
TIME_COLUMN_NAMES = ("time_unix_s", "time")
#: Unix times a file name may carry [s]: 2000-01-01 to 2100-01-01 (UTC).
PLAUSIBLE_UNIX_S = (946_684_800.0, 4_102_444_800.0)
#: Digits of an integer time in a file name -> units per second (s, ms, us, ns).
_NAME_TIME_DIVISORS = {9: 1, 10: 1, 13: 10**3, 16: 10**6, 19: 10**9}


@dataclass(frozen=True)
class _Cloud:
    """What a file holds, before the no-return handling: columns of any numeric type."""

    xyz: tuple[AnyArray, AnyArray, AnyArray]
    intensity: AnyArray | None
    rows: int  # > 1: organized, rows x columns == N
    columns: int
    stamp: float | None = None  # the file's own time (NPZ) [Unix s]


# --- public entry points --------------------------------------------------------------------


def read_frame_folder(
    folder: Path, problems: Problems, *, timestamps: Path | None = None
) -> Iterator[LidarSweep]:
    """Yield the sweeps of a folder of PCD, PLY or NPZ frames, in file-name order.

    Parameters
    ----------
    folder
        The folder; files with other suffixes (a README, the timestamps CSV) are ignored.
    problems
        Receives a :class:`FieldDataError` per skipped frame: unreadable (named by file, and
        line for ASCII data), without a time, or with a time that does not advance.
    timestamps
        CSV with columns ``file`` and ``time_unix_s`` (see the module docstring); without it
        times come from NPZ ``stamp`` or the file names.

    Raises
    ------
    FieldDataError
        The folder is missing, holds no frame files, none of them can have a time, or the
        timestamps CSV cannot be read as a whole.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise FieldDataError(folder, "no such folder" if not folder.exists() else "not a folder")
    files = sorted(
        (p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in FRAME_SUFFIXES),
        key=_natural_key,
    )
    if not files:
        raise FieldDataError(folder, f"no frame files ({', '.join(FRAME_SUFFIXES)}) in the folder")
    table: dict[str, tuple[float, int]] | None = None
    rejected: set[str] = set()  # frames whose CSV row was bad (reported already)
    if timestamps is not None:
        table, rejected = _read_timestamps(Path(timestamps), {p.name for p in files}, problems)
    if table is None and not any(
        p.suffix.lower() == ".npz" or time_from_name(p) is not None for p in files
    ):
        raise FieldDataError(
            folder,
            "no time for the frames: the file names carry no Unix time (seconds such as "
            "1700000000.123456, or 13/16/19-digit ms/us/ns) and no timestamps CSV was given",
        )
    previous: tuple[float, str] | None = None
    for path in files:
        csv_row = table.get(path.name) if table is not None else None
        if table is not None and csv_row is None:
            if path.name in rejected:
                continue
            problems.add(FieldDataError(path, f"no row in {timestamps}: frame skipped"))
            continue
        name_time = time_from_name(path)
        if csv_row is None and name_time is None and path.suffix.lower() != ".npz":
            problems.add(FieldDataError(path, "no time in the file name: frame skipped"))
            continue
        try:
            cloud = _load(path)
        except FieldDataError as error:
            problems.add(error)
            continue
        stamp = csv_row[0] if csv_row is not None else cloud.stamp
        stamp = name_time if stamp is None else stamp
        if stamp is None:
            problems.add(FieldDataError(path, "no stamp in the NPZ, no time in the file name"))
            continue
        if previous is not None and stamp <= previous[0]:
            what = (
                f"time {stamp:.6f} of {path.name} is not after {previous[0]:.6f} "
                f"({previous[1]}): frame skipped"
            )
            if csv_row is not None and timestamps is not None:
                problems.add(FieldDataError(timestamps, what, line=csv_row[1]))
            else:
                problems.add(FieldDataError(path, what))
            continue
        previous = (stamp, path.name)
        yield _sweep(cloud, stamp, str(path))


def read_frame(path: Path, *, stamp: float | None = None) -> LidarSweep:
    """Read one PCD, PLY or NPZ frame (by suffix, else by its first bytes).

    Parameters
    ----------
    path
        The file.
    stamp
        Its time [Unix s]; None: the NPZ's ``stamp``, else the time in the file name, else 0.0
        (unknown).

    Raises
    ------
    FieldDataError
        The file cannot be read (see the module docstring for what is accepted).
    """
    path = Path(path)
    cloud = _load(path)
    if stamp is None:
        stamp = cloud.stamp if cloud.stamp is not None else time_from_name(path)
    return _sweep(cloud, 0.0 if stamp is None else stamp, str(path))


def read_pcd(path: Path, *, stamp: float | None = None) -> LidarSweep:
    """Read one PCD file (see :func:`read_frame` for ``stamp``); raise FieldDataError."""
    path = Path(path)
    cloud = _read_pcd(path, _read_bytes(path))
    return _sweep(cloud, _default_stamp(path, stamp), str(path))


def read_ply(path: Path, *, stamp: float | None = None) -> LidarSweep:
    """Read the vertices of one PLY file (see :func:`read_frame`); raise FieldDataError."""
    path = Path(path)
    cloud = _read_ply(path, _read_bytes(path))
    return _sweep(cloud, _default_stamp(path, stamp), str(path))


def time_from_name(path: Path) -> float | None:
    """The Unix time [s] a file name carries (see the module docstring), or None."""
    for match in reversed(list(re.finditer(r"\d+(?:\.\d+)?", Path(path).name))):
        text = match.group()
        whole, _, fraction = text.partition(".")
        seconds: float | None = None
        if fraction:
            seconds = float(text) if len(whole) in (9, 10) else None
        elif len(whole) in _NAME_TIME_DIVISORS:
            seconds = int(whole) / _NAME_TIME_DIVISORS[len(whole)]  # exact, then rounded once
        if seconds is not None and PLAUSIBLE_UNIX_S[0] <= seconds < PLAUSIBLE_UNIX_S[1]:
            return seconds
    return None


# --- shared helpers -------------------------------------------------------------------------


def _natural_key(path: Path) -> tuple[list[str | Decimal], str]:
    # re.split with one group alternates text, number, text ...: positions compare alike.
    parts: list[str | Decimal] = [
        Decimal(part) if index % 2 else part.lower()
        for index, part in enumerate(re.split(r"(\d+(?:\.\d+)?)", path.name))
    ]
    return parts, path.name


def _default_stamp(path: Path, stamp: float | None) -> float:
    if stamp is not None:
        return stamp
    from_name = time_from_name(path)
    return 0.0 if from_name is None else from_name


def _read_bytes(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise FieldDataError(path, "no such file") from None
    except OSError as exc:
        raise FieldDataError(path, f"cannot read: {exc.strerror or exc}") from None


def _load(path: Path) -> _Cloud:
    suffix = path.suffix.lower()
    if suffix == ".npz":
        return _read_npz(path)
    data = _read_bytes(path)
    if suffix == ".pcd":
        return _read_pcd(path, data)
    if suffix == ".ply" or data.startswith(b"ply"):
        return _read_ply(path, data)
    if data.startswith(b"PK"):
        return _read_npz(path)
    if data.startswith((b"#", b"VERSION", b"FIELDS")):
        return _read_pcd(path, data)
    raise FieldDataError(path, "not a PCD, PLY or NPZ file (unknown suffix and contents)")


def _sweep(cloud: _Cloud, stamp: float, where: str) -> LidarSweep:
    """Stack a cloud into the ``(N, 4)`` float32 of a sweep, marking no-return points."""
    count = len(cloud.xyz[0])
    points = np.empty((count, 4), dtype=np.float32)
    for column, values in enumerate(cloud.xyz):
        points[:, column] = values
    points[:, 3] = np.nan if cloud.intensity is None else cloud.intensity
    xyz = points[:, :3]
    no_return = ~np.isfinite(xyz).all(axis=1) | ~xyz.any(axis=1)
    if cloud.rows > 1:
        points[no_return, :3] = np.nan
        return LidarSweep(stamp=stamp, points=points, rows=cloud.rows, columns=cloud.columns,
                          organized=True, where=where)  # fmt: skip
    kept: Float32Array = np.ascontiguousarray(points[~no_return])
    return LidarSweep(stamp=stamp, points=kept, rows=1, columns=0, organized=False, where=where)


def _header(path: Path, data: bytes, last: re.Pattern[bytes]) -> tuple[list[str], int]:
    """Header lines (decoded, stripped) up to and including the first matching ``last``, and
    the offset where the body starts."""
    lines: list[str] = []
    offset = 0
    while True:
        end = data.find(b"\n", offset)
        end = len(data) if end < 0 else end
        if end > MAX_HEADER_BYTES:
            raise FieldDataError(path, f"no end of header in the first {MAX_HEADER_BYTES} bytes")
        raw = data[offset:end].strip()
        try:
            lines.append(raw.decode("ascii"))
        except UnicodeDecodeError:
            raise FieldDataError(
                path, "header is not ASCII text (not a point-cloud file?)", line=len(lines) + 1
            ) from None
        offset = end + 1
        if last.match(raw):
            return lines, min(offset, len(data))
        if end >= len(data):
            raise FieldDataError(path, "the file ends inside the header")


def _int(path: Path, line: int, keyword: str, value: str, minimum: int) -> int:
    try:
        number = int(value)
    except ValueError:
        raise FieldDataError(path, f"{keyword} {value!r} is not an integer", line=line) from None
    if number < minimum:
        raise FieldDataError(path, f"{keyword} {number} must be at least {minimum}", line=line)
    return number


def _ascii_table(
    path: Path, body: bytes, first_line: int, count: int, per_point: int, names: str
) -> npt.NDArray[np.float64]:
    """``(count, per_point)`` numbers from text lines, blank lines ignored; an error names the
    file line (``first_line`` is the line number of the body's first line)."""
    lines = body.split(b"\n")
    if lines and not lines[-1].strip():
        lines.pop()
    text_lines = [line for line in lines if line.strip()]
    if len(text_lines) == count:
        try:
            values = np.array(b" ".join(text_lines).split(), dtype=np.float64)
        except ValueError:
            values = np.empty(0)
        if values.size == count * per_point:
            return values.reshape(count, per_point)
    # Slow path, only for a bad file: find the first line that is wrong.
    seen = 0
    for index, line in enumerate(lines):
        words = line.split()
        if not words:
            continue
        number = first_line + index
        if seen == count:
            raise FieldDataError(path, f"header says {count} points, data has more", line=number)
        if len(words) != per_point:
            raise FieldDataError(
                path, f"{len(words)} values, expected {per_point} ({names})", line=number
            )
        try:
            np.array(words, dtype=np.float64)
        except ValueError:
            shown = line.strip()[:60].decode(errors="replace")
            raise FieldDataError(path, f"not numbers: {shown!r}", line=number) from None
        seen += 1
    raise FieldDataError(
        path,
        f"header says {count} points, the data ends after {seen} (the file is truncated)",
        line=first_line + len(lines),
    )


# --- PCD ------------------------------------------------------------------------------------

_PCD_KEYWORDS = ("VERSION", "FIELDS", "COLUMNS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT",
                 "VIEWPOINT", "POINTS", "DATA")  # fmt: skip
_PCD_TYPES = {("F", 4): "f4", ("F", 8): "f8", ("I", 1): "i1", ("I", 2): "i2", ("I", 4): "i4",
              ("I", 8): "i8", ("U", 1): "u1", ("U", 2): "u2", ("U", 4): "u4", ("U", 8): "u8"}  # fmt: skip


@dataclass(frozen=True)
class _PcdHeader:
    fields: tuple[str, ...]
    types: tuple[str, ...]  # numpy type codes, e.g. "f4"
    counts: tuple[int, ...]
    width: int
    height: int
    points: int
    data: str
    body_line: int  # line number of the first data line

    def dtype(self) -> np.dtype[np.void]:
        # Named f0, f1 ...: PCD allows repeated names (PCL's "_" padding).
        return np.dtype([(f"f{i}", "<" + kind, (count,))
                         for i, (kind, count) in enumerate(zip(self.types, self.counts, strict=True))])  # fmt: skip


def _parse_pcd_header(path: Path, lines: Sequence[str]) -> _PcdHeader:
    entries: dict[str, tuple[int, list[str]]] = {}
    for number, line in enumerate(lines, start=1):
        if not line or line.startswith("#"):
            continue
        keyword, *values = line.split()
        keyword = keyword.upper()
        if keyword not in _PCD_KEYWORDS:
            raise FieldDataError(path, f"{line[:60]!r} is not a PCD header line", line=number)
        entries["FIELDS" if keyword == "COLUMNS" else keyword] = (number, values)
    for required in ("FIELDS", "SIZE", "TYPE", "WIDTH", "DATA"):
        if required not in entries:
            raise FieldDataError(path, f"PCD header has no {required} line")
    fields_line, fields_list = entries["FIELDS"]
    fields = tuple(fields_list)
    size_line, size_values = entries["SIZE"]
    sizes = tuple(_int(path, size_line, "SIZE", v, 1) for v in size_values)
    type_line, type_values = entries["TYPE"]
    count_line, count_values = entries.get("COUNT", (fields_line, ["1"] * len(fields)))
    counts = tuple(_int(path, count_line, "COUNT", v, 1) for v in count_values)
    for keyword, number, length in (("SIZE", size_line, len(sizes)),
                                    ("TYPE", type_line, len(type_values)),
                                    ("COUNT", count_line, len(counts))):  # fmt: skip
        if length != len(fields):
            raise FieldDataError(
                path, f"{len(fields)} FIELDS ({' '.join(fields)}) but {length} {keyword} values",
                line=number,
            )  # fmt: skip
    types: list[str] = []
    for name, kind, size in zip(fields, type_values, sizes, strict=True):
        code = _PCD_TYPES.get((kind.upper(), size))
        if code is None:
            raise FieldDataError(
                path, f"field {name}: TYPE {kind} with SIZE {size} is not PCD", line=type_line
            )
        types.append(code)
    lowered = [name.lower() for name in fields]
    missing = [axis for axis in ("x", "y", "z") if axis not in lowered]
    if missing:
        raise FieldDataError(
            path, f"no {', '.join(missing)} field: FIELDS {' '.join(fields) or '(none)'}; a "
            "point cloud needs x, y and z", line=fields_line,
        )  # fmt: skip
    width_line, width_values = entries["WIDTH"]
    width = _int(path, width_line, "WIDTH", (width_values or ["?"])[0], 0)
    height_line, height_values = entries.get("HEIGHT", (width_line, ["1"]))
    height = _int(path, height_line, "HEIGHT", (height_values or ["?"])[0], 1)
    points = width * height
    if "POINTS" in entries:
        points_line, points_values = entries["POINTS"]
        points = _int(path, points_line, "POINTS", (points_values or ["?"])[0], 0)
        if points != width * height:
            raise FieldDataError(
                path, f"POINTS {points} is not WIDTH x HEIGHT = {width} x {height}",
                line=points_line,
            )  # fmt: skip
    data_line, data_values = entries["DATA"]
    data = " ".join(data_values).lower()
    if data not in ("ascii", "binary", "binary_compressed"):
        raise FieldDataError(
            path, f"DATA {data!r}: expected ascii, binary or binary_compressed", line=data_line
        )
    return _PcdHeader(fields, tuple(types), counts, width, height, points, data, len(lines) + 1)


def _read_pcd(path: Path, data: bytes) -> _Cloud:
    lines, body_start = _header(path, data, re.compile(rb"^DATA\b", re.IGNORECASE))
    header = _parse_pcd_header(path, lines)
    body = data[body_start:]
    if header.data == "ascii":
        table = _ascii_table(path, body, header.body_line, header.points, sum(header.counts),
                             " ".join(header.fields))  # fmt: skip
        starts = np.cumsum((0, *header.counts[:-1]))
        columns: list[AnyArray] = [table[:, start] for start in starts]
    elif header.data == "binary":
        columns = _pcd_binary(path, header, body)
    else:
        columns = _pcd_binary_compressed(path, header, body)
    lowered = [name.lower() for name in header.fields]
    x, y, z = (columns[lowered.index(axis)] for axis in ("x", "y", "z"))
    intensity_index = next((lowered.index(n) for n in INTENSITY_NAMES if n in lowered), None)
    intensity = None if intensity_index is None else columns[intensity_index]
    return _Cloud((x, y, z), intensity, header.height, header.width)


def _pcd_binary(path: Path, header: _PcdHeader, body: bytes) -> list[AnyArray]:
    """Each field's first value per point, from packed little-endian records."""
    dtype = header.dtype()
    expected = header.points * dtype.itemsize
    if len(body) < expected:
        raise FieldDataError(
            path,
            f"header says {header.points} points, data has {len(body) // dtype.itemsize} "
            f"({len(body)} of {expected} bytes): the file is truncated",
        )
    records = np.frombuffer(body, dtype=dtype, count=header.points)
    return [records[f"f{i}"][:, 0] for i in range(len(header.fields))]


def _pcd_binary_compressed(path: Path, header: _PcdHeader, body: bytes) -> list[AnyArray]:
    """Fields stored one after another (all x, then all y ...), LZF-compressed as one block."""
    if len(body) < 8:
        raise FieldDataError(path, "binary_compressed data has no size words: truncated")
    compressed_size, raw_size = struct.unpack_from("<II", body, 0)
    dtype = header.dtype()
    expected = header.points * dtype.itemsize
    if raw_size != expected:
        raise FieldDataError(
            path, f"header says {header.points} points ({expected} bytes), the compressed "
            f"block holds {raw_size} bytes",
        )  # fmt: skip
    if len(body) - 8 < compressed_size:
        raise FieldDataError(
            path, f"compressed block of {compressed_size} bytes, the file has {len(body) - 8}: "
            "the file is truncated",
        )  # fmt: skip
    try:
        raw = lzf_decompress(body[8 : 8 + compressed_size], raw_size)
    except ValueError as exc:
        raise FieldDataError(path, f"corrupt LZF data: {exc}") from None
    columns: list[AnyArray] = []
    offset = 0
    for i, count in enumerate(header.counts):
        base = np.dtype("<" + header.types[i])
        values = np.frombuffer(raw, dtype=base, count=header.points * count, offset=offset)
        columns.append(values.reshape(header.points, count)[:, 0])
        offset += header.points * count * base.itemsize
    return columns


def lzf_decompress(data: bytes, size: int) -> bytes:
    """Decompress one LZF block (liblzf's format, as PCL and Open3D write it).

    Parameters
    ----------
    data
        The compressed bytes.
    size
        The decompressed size the container announces [bytes].

    Raises
    ------
    ValueError
        The stream is corrupt or does not decompress to exactly ``size`` bytes.
    """
    out = bytearray(size)
    ip = op = 0
    end = len(data)
    while ip < end:
        ctrl = data[ip]
        ip += 1
        if ctrl < 32:  # a literal run of ctrl + 1 bytes
            length = ctrl + 1
            if ip + length > end or op + length > size:
                raise ValueError(f"literal run of {length} bytes overruns at input byte {ip}")
            out[op : op + length] = data[ip : ip + length]
            ip += length
            op += length
            continue
        # A back reference: length - 2 in the top 3 bits (7: more in the next byte), offset - 1
        # in the low 5 bits and the next byte.
        length = ctrl >> 5
        if length == 7:
            if ip >= end:
                raise ValueError("back reference cut short")
            length += data[ip]
            ip += 1
        if ip >= end:
            raise ValueError("back reference cut short")
        ref = op - ((ctrl & 0x1F) << 8) - data[ip] - 1
        ip += 1
        length += 2
        if ref < 0 or op + length > size:
            raise ValueError(f"back reference out of bounds at output byte {op}")
        distance = op - ref
        if distance >= length:
            out[op : op + length] = out[ref : ref + length]
        else:  # overlapping: the last `distance` bytes repeat
            pattern = bytes(out[ref:op])
            out[op : op + length] = (pattern * (length // distance + 1))[:length]
        op += length
    if op != size:
        raise ValueError(f"decompressed to {op} bytes, expected {size}")
    return bytes(out)


# --- PLY ------------------------------------------------------------------------------------

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
    "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip


@dataclass(frozen=True)
class _PlyElement:
    name: str
    count: int
    properties: tuple[tuple[str, str], ...]  # (name lower-case, numpy code or "list")

    @property
    def fixed(self) -> bool:
        return all(kind != "list" for _, kind in self.properties)

    def dtype(self, order: str) -> np.dtype[np.void]:
        return np.dtype([(f"p{i}", order + kind) for i, (_, kind) in enumerate(self.properties)])


def _parse_ply_header(path: Path, lines: Sequence[str]) -> tuple[str, list[_PlyElement]]:
    if not lines or lines[0] != "ply":
        raise FieldDataError(path, "not a PLY file (the first line is not 'ply')", line=1)
    fmt = ""
    declared: list[tuple[str, int, list[tuple[str, str]]]] = []
    for number, line in enumerate(lines[1:-1], start=2):
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format" and len(words) == 3:
            fmt = words[1]
        elif words[0] == "element" and len(words) == 3:
            declared.append((words[1], _int(path, number, "element count", words[2], 0), []))
        elif words[0] == "property" and declared and len(words) == 5 and words[1] == "list":
            declared[-1][2].append((words[4].lower(), "list"))
        elif words[0] == "property" and declared and len(words) == 3 and words[1] in _PLY_TYPES:
            declared[-1][2].append((words[2].lower(), _PLY_TYPES[words[1]]))
        else:
            raise FieldDataError(path, f"{line[:60]!r} is not a PLY header line", line=number)
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise FieldDataError(path, f"PLY format {fmt or '(none)'!r} is not supported")
    return fmt, [_PlyElement(name, count, tuple(props)) for name, count, props in declared]


def _read_ply(path: Path, data: bytes) -> _Cloud:
    lines, body_start = _header(path, data, re.compile(rb"^end_header$"))
    fmt, elements = _parse_ply_header(path, lines)
    names = [element.name for element in elements]
    if "vertex" not in names:
        raise FieldDataError(path, f"no vertex element (elements: {', '.join(names) or 'none'})")
    vertex = elements[names.index("vertex")]
    if not vertex.fixed:
        raise FieldDataError(path, "the vertex element has list properties: not a point cloud")
    properties = [name for name, _ in vertex.properties]
    missing = [axis for axis in ("x", "y", "z") if axis not in properties]
    if missing:
        raise FieldDataError(
            path, f"vertex has no {', '.join(missing)} property (properties: "
            f"{' '.join(properties)}); a point cloud needs x, y and z",
        )  # fmt: skip
    before = elements[: names.index("vertex")]
    body = data[body_start:]
    columns: list[AnyArray]
    if fmt == "ascii":
        # Each element instance is one line: skip those of the elements before the vertices.
        skip = sum(element.count for element in before)
        kept = b"\n".join(body.split(b"\n")[skip : skip + vertex.count])
        table = _ascii_table(path, kept, len(lines) + 1 + skip, vertex.count, len(properties),
                             " ".join(properties))  # fmt: skip
        columns = [table[:, i] for i in range(len(properties))]
    else:
        order = "<" if fmt == "binary_little_endian" else ">"
        offset = 0
        for element in before:
            if not element.fixed:
                raise FieldDataError(
                    path, f"element {element.name} with list properties comes before vertex"
                )
            offset += element.count * element.dtype(order).itemsize
        dtype = vertex.dtype(order)
        available = max(0, len(body) - offset)
        if available < vertex.count * dtype.itemsize:
            raise FieldDataError(
                path, f"header says {vertex.count} points, data has "
                f"{available // dtype.itemsize}: the file is truncated",
            )  # fmt: skip
        records = np.frombuffer(body, dtype=dtype, count=vertex.count, offset=offset)
        columns = [records[f"p{i}"] for i in range(len(properties))]
    x, y, z = (columns[properties.index(axis)] for axis in ("x", "y", "z"))
    intensity_index = next((properties.index(n) for n in INTENSITY_NAMES if n in properties), None)
    intensity = None if intensity_index is None else columns[intensity_index]
    return _Cloud((x, y, z), intensity, 1, vertex.count)


# --- NPZ ------------------------------------------------------------------------------------


def _read_npz(path: Path) -> _Cloud:
    try:
        with np.load(path, allow_pickle=False) as archive:
            arrays: dict[str, AnyArray] = {name: archive[name] for name in archive.files}
    except FileNotFoundError:
        raise FieldDataError(path, "no such file") from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError) as exc:
        raise FieldDataError(path, f"not a readable NPZ archive: {exc}") from None
    if "points" not in arrays:
        raise FieldDataError(path, f"no 'points' array (arrays: {', '.join(arrays) or 'none'})")
    points = arrays["points"]
    if points.dtype.kind not in "fiu":
        raise FieldDataError(path, f"points of type {points.dtype} are not numbers")
    if points.ndim == 3 and points.shape[2] in (3, 4):
        rows, columns = int(points.shape[0]), int(points.shape[1])
        points = points.reshape(-1, points.shape[2])
    elif points.ndim == 2 and points.shape[1] in (3, 4):
        rows, columns = 1, len(points)
        declared_rows = _npz_scalar(path, arrays, "rows")
        declared_columns = _npz_scalar(path, arrays, "columns")
        if declared_rows is not None and declared_columns is not None:
            rows, columns = int(declared_rows), int(declared_columns)
            if rows < 1 or rows * columns != len(points):
                raise FieldDataError(
                    path, f"rows x columns = {rows} x {columns}, but {len(points)} points"
                )
    else:
        raise FieldDataError(
            path, f"points has shape {points.shape}: expected (N, 3|4) or (rows, columns, 3|4)"
        )
    stamp = _npz_scalar(path, arrays, "stamp")
    stamp = _npz_scalar(path, arrays, "stamp_s") if stamp is None else stamp
    if stamp is not None and not (math.isfinite(stamp) and stamp >= 0.0):
        raise FieldDataError(path, f"stamp {stamp} is not a Unix time")
    intensity = points[:, 3] if points.shape[1] == 4 else None
    return _Cloud((points[:, 0], points[:, 1], points[:, 2]), intensity, rows, columns, stamp)


def _npz_scalar(path: Path, arrays: dict[str, AnyArray], name: str) -> float | None:
    if name not in arrays:
        return None
    value = arrays[name]
    if value.size != 1 or value.dtype.kind not in "fiu":
        raise FieldDataError(path, f"{name} must be one number, got {value.dtype} {value.shape}")
    return float(value.reshape(-1)[0])


# --- timestamps CSV -------------------------------------------------------------------------


def _read_timestamps(
    path: Path, frame_names: set[str], problems: Problems
) -> tuple[dict[str, tuple[float, int]], set[str]]:
    """``file name -> (time [Unix s], CSV line)``, and the names of frames whose row was bad
    (reported and left out)."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise FieldDataError(path, "no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise FieldDataError(path, f"cannot read: {exc}") from None
    reader = csv.reader(text.splitlines())
    header = [name.strip().lower() for name in next(reader, [])]
    file_column = next((header.index(n) for n in FILE_COLUMN_NAMES if n in header), None)
    time_column = next((header.index(n) for n in TIME_COLUMN_NAMES if n in header), None)
    if file_column is None or time_column is None:
        missing = [f"{what} ({' or '.join(names)})" for what, names, column in (
            ("file", FILE_COLUMN_NAMES, file_column), ("time", TIME_COLUMN_NAMES, time_column))
            if column is None]  # fmt: skip
        raise FieldDataError(
            path, f"missing columns: {', '.join(missing)}; header: {','.join(header)}", line=1
        )
    table: dict[str, tuple[float, int]] = {}
    rejected: set[str] = set()
    for row in reader:
        number = reader.line_num
        if not any(cell.strip() for cell in row):
            continue
        if len(row) <= max(file_column, time_column):
            problems.add(FieldDataError(path, f"{len(row)} cells, expected {len(header)}",
                                        line=number))  # fmt: skip
            continue
        name = Path(row[file_column].strip()).name
        try:
            stamp = float(row[time_column])
        except ValueError:
            stamp = math.nan
        if not (math.isfinite(stamp) and stamp >= 0.0):
            problems.add(FieldDataError(
                path, f"time {row[time_column].strip()!r} of {name} is not a Unix time [s]: "
                "frame skipped", line=number))  # fmt: skip
            rejected.add(name)
            continue
        if name in table:
            problems.add(
                FieldDataError(
                    path, f"{name} again (first at line {table[name][1]}): row ignored", line=number
                )
            )
            continue
        if name not in frame_names:
            problems.add(FieldDataError(path, f"no frame file {name!r} in the folder",
                                        line=number))  # fmt: skip
            continue
        table[name] = (stamp, number)
    return table, rejected - table.keys()
