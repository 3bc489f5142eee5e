"""Point-cloud files to :class:`PointFrame`: PCD v0.7, PLY and NPZ (pure parsing, numpy only).

Shared by the LiDAR detector (``wz detect-lidar``, its background files) and the field drivers
(folders of recorded frames, :mod:`wz_drivers.lidar_files`): one parser for both.

Formats
-------
PCD (v0.7, and the older headers that use the same keywords)
    ``DATA ascii``, ``binary`` and ``binary_compressed`` (LZF, decompressed here in pure
    Python). Fields ``x y z`` and optionally ``intensity``, in any order; other fields (rgb,
    normals, ring, time, PCL's ``_`` padding) are read past and ignored. ``HEIGHT > 1`` is an
    organized frame (``HEIGHT`` rows of ``WIDTH`` columns); NaN points are kept where they are.
PLY
    ``ascii``, ``binary_little_endian`` and ``binary_big_endian``; the ``vertex`` element with
    properties ``x y z`` and optionally ``intensity`` (or CloudCompare's ``scalar_intensity``).
    Elements before ``vertex`` are skipped where their size is fixed; elements after it are
    ignored. A PLY cloud is unorganized.
NPZ
    The simulator's dataset export (``points`` of shape ``(N, 4)``, ``stamp_s``), any archive
    with ``points`` of shape ``(N, 3|4)`` or ``(rows, columns, 3|4)``, or separate ``x``, ``y``,
    ``z`` [, ``intensity``] arrays (1-D, or 2-D for an organized frame). Optional scalar ``rows``
    and ``columns`` make an ``(N, 4)`` array organized; so does ``shape_hint``.

Every problem with a file raises :class:`PointCloudFileError` naming the file and what is wrong
(``header says 144000 points, data has 1200``), never a bare numpy or zip error.
"""

from __future__ import annotations

import math
import re
import struct
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from wz_shared.arrays import F32


@dataclass(frozen=True)
class PointFrame:
    """One LiDAR frame.

    Attributes
    ----------
    points
        ``(N, 4)`` float32: x, y, z [m] in the sensor frame and intensity (NaN where the sensor
        gives none). NaN x marks a no-return slot of an organized frame.
    rows, columns
        Shape of an organized frame (``rows * columns == N``, row-major by beam then column);
        ``rows == 1`` for an unorganized cloud.
    stamp_s
        Capture time [s] (sweep start).
    """

    points: F32
    rows: int
    columns: int
    stamp_s: float = 0.0

    @property
    def organized(self) -> bool:
        return self.rows > 1 and self.rows * self.columns == len(self.points)

    @classmethod
    def unorganized(cls, points: npt.ArrayLike, stamp_s: float = 0.0) -> PointFrame:
        """A cloud without beam/column structure; a missing intensity column becomes NaN."""
        array = np.asarray(points, dtype=np.float32)
        if array.ndim != 2 or array.shape[1] not in (3, 4):
            raise ValueError(f"points must have shape (N, 3) or (N, 4), got {array.shape}")
        if array.shape[1] == 3:
            array = np.column_stack([array, np.full(len(array), np.nan, dtype=np.float32)])
        return cls(points=array, rows=1, columns=len(array), stamp_s=stamp_s)


#: A PCD or PLY header longer than this is not a header [bytes].
MAX_HEADER_BYTES = 64 * 1024
#: Names accepted for the intensity field (compared lower-case).
INTENSITY_NAMES = ("intensity", "scalar_intensity")


class PointCloudFileError(ValueError):
    """A point-cloud file that cannot be read: ``path`` and the ``problem`` in words."""

    def __init__(self, path: str | Path, problem: str) -> None:
        super().__init__(f"{path}: {problem}")
        self.path = Path(path)
        self.problem = problem


def read_point_cloud(path: str | Path, *, shape_hint: tuple[int, int] | None = None) -> PointFrame:
    """Read a PCD, PLY or NPZ file (chosen by suffix, else by the file's first bytes).

    Parameters
    ----------
    path
        The file.
    shape_hint
        ``(rows, columns)`` to organize an NPZ ``(N, 4)`` array that does not say its shape
        (the simulator's export) when ``rows * columns == N``; ignored for PCD and PLY, whose
        headers say it.

    Returns
    -------
    PointFrame
        ``(N, 4)`` float32 x, y, z [m], intensity (NaN where the file has none); organized when
        the file is. ``stamp_s`` is the file's stamp where the format has one (NPZ
        ``stamp_s``), else 0.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".pcd":
        return read_pcd(path)
    if suffix == ".ply":
        return read_ply(path)
    if suffix == ".npz":
        return read_npz(path, shape_hint=shape_hint)
    start = _read_bytes(path)[:16]
    if start.startswith(b"ply"):
        return read_ply(path)
    if start.startswith(b"PK"):
        return read_npz(path, shape_hint=shape_hint)
    if start.startswith((b"#", b"VERSION", b"FIELDS")):
        return read_pcd(path)
    raise PointCloudFileError(path, "not a PCD, PLY or NPZ file (unknown suffix and contents)")


def _read_bytes(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except OSError as exc:
        raise PointCloudFileError(path, f"cannot read: {exc.strerror or exc}") from exc


def _assemble(
    path: Path,
    xyz: Sequence[npt.NDArray[np.generic]],
    intensity: npt.NDArray[np.generic] | None,
    rows: int,
    columns: int,
    stamp_s: float = 0.0,
) -> PointFrame:
    """Stack x, y, z [, intensity] columns into the ``(N, 4)`` float32 of a :class:`PointFrame`."""
    count = len(xyz[0])
    points = np.empty((count, 4), dtype=np.float32)
    for column, values in enumerate(xyz):
        points[:, column] = values
    points[:, 3] = np.nan if intensity is None else intensity
    if rows > 1 and rows * columns != count:  # callers check; this guards the invariant
        raise PointCloudFileError(path, f"{rows} x {columns} organized but {count} points")
    if rows <= 1:
        rows, columns = 1, count
    return PointFrame(points=points, rows=rows, columns=columns, stamp_s=stamp_s)


def _header_lines(path: Path, data: bytes, last: re.Pattern[bytes]) -> tuple[list[str], int]:
    """Header lines (decoded) up to and including the first line matching ``last``.

    Returns the lines and the offset where the body starts.
    """
    lines: list[str] = []
    offset = 0
    while True:
        end = data.find(b"\n", offset)
        if end < 0:
            end = len(data)
        raw = data[offset:end]
        if end >= MAX_HEADER_BYTES:
            raise PointCloudFileError(
                path, f"no end of header in the first {MAX_HEADER_BYTES} bytes"
            )
        try:
            line = raw.decode("ascii").strip()
        except UnicodeDecodeError as exc:
            raise PointCloudFileError(
                path, f"header line {len(lines) + 1} is not ASCII text (not a point-cloud file?)"
            ) from exc
        lines.append(line)
        offset = end + 1
        if last.match(raw.strip()):
            return lines, min(offset, len(data))
        if end >= len(data):
            raise PointCloudFileError(path, "file ends inside the header")


# --- PCD ------------------------------------------------------------------------------------

_PCD_KEYWORDS = (
    "VERSION",
    "FIELDS",
    "COLUMNS",
    "SIZE",
    "TYPE",
    "COUNT",
    "WIDTH",
    "HEIGHT",
    "VIEWPOINT",
    "POINTS",
    "DATA",
)
_PCD_TYPES = {
    ("F", 4): "f4",
    ("F", 8): "f8",
    ("I", 1): "i1",
    ("I", 2): "i2",
    ("I", 4): "i4",
    ("I", 8): "i8",
    ("U", 1): "u1",
    ("U", 2): "u2",
    ("U", 4): "u4",
    ("U", 8): "u8",
}


@dataclass(frozen=True)
class PcdHeader:
    """What a PCD header says (one entry per field in ``fields``, ``sizes`` ...)."""

    fields: tuple[str, ...]
    sizes: tuple[int, ...]
    types: tuple[str, ...]
    counts: tuple[int, ...]
    width: int
    height: int
    points: int
    data: str

    def dtype(self, byte_order: str = "<") -> np.dtype[np.void]:
        """One packed record per point; fields are named ``f0, f1 ...`` (PCD allows repeats)."""
        return np.dtype(
            [
                (f"f{i}", byte_order + _PCD_TYPES[(kind, size)], (count,))
                for i, (kind, size, count) in enumerate(
                    zip(self.types, self.sizes, self.counts, strict=True)
                )
            ]
        )


def _pcd_int(path: Path, keyword: str, value: str, minimum: int) -> int:
    try:
        number = int(value)
    except ValueError:
        raise PointCloudFileError(path, f"{keyword} {value!r} is not an integer") from None
    if number < minimum:
        raise PointCloudFileError(path, f"{keyword} {number} must be at least {minimum}")
    return number


def parse_pcd_header(path: Path, lines: Sequence[str]) -> PcdHeader:
    """Validate the header lines of a PCD file (comments and blank lines allowed)."""
    entries: dict[str, list[str]] = {}
    for number, line in enumerate(lines, start=1):
        if not line or line.startswith("#"):
            continue
        keyword, *values = line.split()
        keyword = keyword.upper()
        if keyword not in _PCD_KEYWORDS:
            raise PointCloudFileError(path, f"header line {number} {line[:60]!r} is not PCD")
        entries["FIELDS" if keyword == "COLUMNS" else keyword] = values
    for required in ("FIELDS", "SIZE", "TYPE", "WIDTH", "DATA"):
        if required not in entries:
            raise PointCloudFileError(path, f"PCD header has no {required} line")
    fields = tuple(entries["FIELDS"])
    if not fields:
        raise PointCloudFileError(path, "PCD header lists no FIELDS")
    sizes = tuple(_pcd_int(path, "SIZE", v, 1) for v in entries["SIZE"])
    types = tuple(v.upper() for v in entries["TYPE"])
    counts = tuple(_pcd_int(path, "COUNT", v, 1) for v in entries.get("COUNT", ["1"] * len(fields)))
    for name, length in (("SIZE", len(sizes)), ("TYPE", len(types)), ("COUNT", len(counts))):
        if length != len(fields):
            raise PointCloudFileError(
                path, f"{len(fields)} FIELDS ({' '.join(fields)}) but {length} {name} values"
            )
    for name, kind, size in zip(fields, types, sizes, strict=True):
        if (kind, size) not in _PCD_TYPES:
            raise PointCloudFileError(
                path, f"field {name}: TYPE {kind} with SIZE {size} is not PCD"
            )
    for axis in ("x", "y", "z"):
        if axis not in fields:
            raise PointCloudFileError(path, f"no {axis} field (FIELDS {' '.join(fields)})")
        if counts[fields.index(axis)] != 1:
            raise PointCloudFileError(path, f"field {axis} has COUNT {counts[fields.index(axis)]}")
    if len(entries["WIDTH"]) != 1:
        raise PointCloudFileError(path, "WIDTH must be one integer")
    width = _pcd_int(path, "WIDTH", entries["WIDTH"][0], 0)
    height = _pcd_int(path, "HEIGHT", (entries.get("HEIGHT") or ["1"])[0], 1)
    points = width * height
    if "POINTS" in entries:
        points = _pcd_int(path, "POINTS", (entries["POINTS"] or ["?"])[0], 0)
        if points != width * height:
            raise PointCloudFileError(
                path, f"POINTS {points} is not WIDTH x HEIGHT = {width} x {height}"
            )
    data = " ".join(entries["DATA"]).lower()
    if data not in ("ascii", "binary", "binary_compressed"):
        raise PointCloudFileError(
            path, f"DATA {data!r}: expected ascii, binary or binary_compressed"
        )
    return PcdHeader(fields, sizes, types, counts, width, height, points, data)


def read_pcd(path: str | Path) -> PointFrame:
    """Read a PCD file (see the module docstring); raise :class:`PointCloudFileError`."""
    path = Path(path)
    data = _read_bytes(path)
    lines, body_start = _header_lines(path, data, re.compile(rb"^DATA\b", re.IGNORECASE))
    header = parse_pcd_header(path, lines)
    body = memoryview(data)[body_start:]
    if header.data == "ascii":
        columns = _pcd_ascii(path, header, body)
    elif header.data == "binary":
        columns = _pcd_binary(path, header, body)
    else:
        columns = _pcd_binary_compressed(path, header, body)
    lowered = [name.lower() for name in header.fields]
    intensity_index = next((lowered.index(n) for n in INTENSITY_NAMES if n in lowered), None)
    xyz = [columns[header.fields.index(axis)] for axis in ("x", "y", "z")]
    intensity = None if intensity_index is None else columns[intensity_index]
    return _assemble(path, xyz, intensity, header.height, header.width)


def _pcd_ascii(path: Path, header: PcdHeader, body: memoryview) -> list[npt.NDArray[np.generic]]:
    """Each field's first value per point, from whitespace-separated text lines."""
    lines = [line for line in bytes(body).split(b"\n") if line.strip()]
    per_point = sum(header.counts)
    if len(lines) != header.points:
        raise PointCloudFileError(
            path, f"header says {header.points} points, data has {len(lines)}"
        )
    try:
        values = np.array(b" ".join(lines).split(), dtype=np.float64)
    except ValueError:
        for number, line in enumerate(lines, start=1):
            try:
                np.array(line.split(), dtype=np.float64)
            except ValueError:
                raise PointCloudFileError(
                    path,
                    f"data line {number} is not numbers: {line[:60].decode(errors='replace')!r}",
                ) from None
        raise  # pragma: no cover - every line parsed alone, so the join did too
    if values.size != header.points * per_point:
        for number, line in enumerate(lines, start=1):
            if len(line.split()) != per_point:
                raise PointCloudFileError(
                    path,
                    f"data line {number} has {len(line.split())} values, expected {per_point} "
                    f"({' '.join(header.fields)})",
                )
    table = values.reshape(header.points, per_point)
    starts = np.cumsum((0, *header.counts[:-1]))
    return [table[:, start] for start in starts]


def _pcd_binary(path: Path, header: PcdHeader, body: memoryview) -> list[npt.NDArray[np.generic]]:
    """Each field's first value per point, from packed little-endian records."""
    dtype = header.dtype()
    expected = header.points * dtype.itemsize
    if len(body) < expected:
        raise PointCloudFileError(
            path,
            f"header says {header.points} points, data has {len(body) // dtype.itemsize} "
            f"({len(body)} of {expected} bytes; the file is truncated)",
        )
    if len(body) > expected and bytes(body[expected:]).strip(b"\r\n\x00 "):
        raise PointCloudFileError(
            path,
            f"header says {header.points} points ({expected} bytes), data has {len(body)} bytes",
        )
    records = np.frombuffer(body, dtype=dtype, count=header.points)
    return [records[f"f{i}"][:, 0] for i in range(len(header.fields))]


def _pcd_binary_compressed(
    path: Path, header: PcdHeader, body: memoryview
) -> list[npt.NDArray[np.generic]]:
    """Fields stored one after another (all x, then all y ...), LZF-compressed as one block."""
    if len(body) < 8:
        raise PointCloudFileError(path, "binary_compressed data has no size words")
    compressed_size, raw_size = struct.unpack_from("<II", body, 0)
    dtype = header.dtype()
    expected = header.points * dtype.itemsize
    if raw_size != expected:
        raise PointCloudFileError(
            path,
            f"header says {header.points} points ({expected} bytes), compressed block "
            f"holds {raw_size} bytes",
        )
    if len(body) - 8 < compressed_size:
        raise PointCloudFileError(
            path,
            f"compressed block of {compressed_size} bytes, file has {len(body) - 8} "
            "(the file is truncated)",
        )
    try:
        raw = lzf_decompress(bytes(body[8 : 8 + compressed_size]), raw_size)
    except ValueError as exc:
        raise PointCloudFileError(path, f"corrupt LZF data: {exc}") from exc
    columns: list[npt.NDArray[np.generic]] = []
    offset = 0
    for i in range(len(header.fields)):
        field_dtype = np.dtype(dtype[f"f{i}"].base)
        count = header.counts[i]
        values = np.frombuffer(raw, dtype=field_dtype, count=header.points * count, offset=offset)
        columns.append(values.reshape(header.points, count)[:, 0])
        offset += header.points * count * field_dtype.itemsize
    return columns


def lzf_decompress(data: bytes, size: int) -> bytes:
    """Decompress one LZF block (liblzf's format, as PCL and Open3D write it).

    Parameters
    ----------
    data
        The compressed bytes.
    size
        The decompressed size the container says [bytes].

    Raises
    ------
    ValueError
        When the stream is corrupt or does not decompress to exactly ``size`` bytes.
    """
    out = bytearray(size)
    ip = op = 0
    end = len(data)
    while ip < end:
        ctrl = data[ip]
        ip += 1
        if ctrl < 32:  # a literal run of ctrl + 1 bytes
            length = ctrl + 1
            if ip + length > end:
                raise ValueError(f"literal run of {length} bytes overruns the input at {ip}")
            if op + length > size:
                raise ValueError(f"output exceeds the {size} bytes announced")
            out[op : op + length] = data[ip : ip + length]
            ip += length
            op += length
            continue
        # A back reference: length in the top 3 bits (7 = more in the next byte), offset in
        # the low 5 bits and the next byte.
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
        if ref < 0:
            raise ValueError(f"back reference before the start of the output at {op}")
        if op + length > size:
            raise ValueError(f"output exceeds the {size} bytes announced")
        distance = op - ref
        if distance >= length:
            out[op : op + length] = out[ref : ref + length]
        else:  # overlapping: the last ``distance`` bytes repeat
            pattern = bytes(out[ref:op])
            out[op : op + length] = (pattern * (length // distance + 1))[:length]
        op += length
    if op != size:
        raise ValueError(f"decompressed to {op} bytes, expected {size}")
    return bytes(out)


# --- PLY ------------------------------------------------------------------------------------

_PLY_TYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}


@dataclass(frozen=True)
class PlyElement:
    name: str
    count: int
    #: (name, numpy type) of each scalar property; list properties make ``fixed`` False.
    properties: tuple[tuple[str, str], ...]
    fixed: bool


def parse_ply_header(path: Path, lines: Sequence[str]) -> tuple[str, list[PlyElement]]:
    """The format and the elements of a PLY header."""
    if not lines or lines[0] != "ply":
        raise PointCloudFileError(path, "not a PLY file (first line is not 'ply')")
    fmt = ""
    # (name, count, properties) of each element, in file order
    declared: list[tuple[str, int, list[tuple[str, str]]]] = []
    for number, line in enumerate(lines[1:-1], start=2):
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format" and len(words) == 3:
            fmt = words[1]
        elif words[0] == "element" and len(words) == 3:
            count = _pcd_int(path, f"element {words[1]} count", words[2], 0)
            declared.append((words[1], count, []))
        elif words[0] == "property" and declared and len(words) == 5 and words[1] == "list":
            declared[-1][2].append((words[4], "list"))
        elif words[0] == "property" and declared and len(words) == 3 and words[1] in _PLY_TYPES:
            declared[-1][2].append((words[2], _PLY_TYPES[words[1]]))
        else:
            raise PointCloudFileError(path, f"header line {number} {line[:60]!r} is not PLY")
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise PointCloudFileError(path, f"PLY format {fmt or '(none)'!r} is not supported")
    elements = [
        PlyElement(name, count, tuple(props), all(kind != "list" for _, kind in props))
        for name, count, props in declared
    ]
    return fmt, elements


def read_ply(path: str | Path) -> PointFrame:
    """Read the vertices of a PLY file (see the module docstring)."""
    path = Path(path)
    data = _read_bytes(path)
    lines, body_start = _header_lines(path, data, re.compile(rb"^end_header$"))
    fmt, elements = parse_ply_header(path, lines)
    names = [element.name for element in elements]
    if "vertex" not in names:
        raise PointCloudFileError(path, f"no vertex element (elements: {', '.join(names)})")
    vertex = elements[names.index("vertex")]
    if not vertex.fixed:
        raise PointCloudFileError(path, "vertex element has list properties: not a point cloud")
    properties = [name.lower() for name, _ in vertex.properties]
    for axis in ("x", "y", "z"):
        if axis not in properties:
            raise PointCloudFileError(path, f"vertex has no {axis} property")
    before = elements[: names.index("vertex")]
    body = memoryview(data)[body_start:]
    if fmt == "ascii":
        table = _ply_ascii(path, vertex, sum(e.count for e in before), body)
    else:
        table = _ply_binary(path, vertex, before, body, "<" if "little" in fmt else ">")
    xyz = [table[properties.index(axis)] for axis in ("x", "y", "z")]
    intensity_index = next((properties.index(n) for n in INTENSITY_NAMES if n in properties), None)
    intensity = None if intensity_index is None else table[intensity_index]
    return _assemble(path, xyz, intensity, 1, vertex.count)


def _ply_ascii(
    path: Path, vertex: PlyElement, skip_lines: int, body: memoryview
) -> list[npt.NDArray[np.generic]]:
    lines = [line for line in bytes(body).split(b"\n") if line.strip()]
    rows = lines[skip_lines : skip_lines + vertex.count]
    if len(rows) != vertex.count:
        raise PointCloudFileError(path, f"header says {vertex.count} points, data has {len(rows)}")
    per_point = len(vertex.properties)
    try:
        values = np.array(b" ".join(rows).split(), dtype=np.float64)
    except ValueError:
        raise PointCloudFileError(path, "vertex data is not numbers") from None
    if values.size != vertex.count * per_point:
        for number, line in enumerate(rows, start=1):
            if len(line.split()) != per_point:
                raise PointCloudFileError(
                    path, f"vertex {number} has {len(line.split())} values, expected {per_point}"
                )
    table = values.reshape(vertex.count, per_point)
    return [table[:, i] for i in range(per_point)]


def _ply_binary(
    path: Path, vertex: PlyElement, before: Sequence[PlyElement], body: memoryview, order: str
) -> list[npt.NDArray[np.generic]]:
    offset = 0
    for element in before:
        if not element.fixed:
            raise PointCloudFileError(
                path, f"element {element.name} with list properties comes before vertex"
            )
        offset += (
            element.count
            * np.dtype(
                [(f"p{i}", order + t) for i, (_, t) in enumerate(element.properties)]
            ).itemsize
        )
    dtype = np.dtype([(f"p{i}", order + t) for i, (_, t) in enumerate(vertex.properties)])
    available = max(0, len(body) - offset)
    if available < vertex.count * dtype.itemsize:
        raise PointCloudFileError(
            path,
            f"header says {vertex.count} points, data has {available // dtype.itemsize} "
            "(the file is truncated)",
        )
    records = np.frombuffer(body, dtype=dtype, count=vertex.count, offset=offset)
    return [records[f"p{i}"] for i in range(len(vertex.properties))]


# --- NPZ ------------------------------------------------------------------------------------


def read_npz(path: str | Path, *, shape_hint: tuple[int, int] | None = None) -> PointFrame:
    """Read points from an NPZ archive (see the module docstring)."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as archive:
            arrays = {name: archive[name] for name in archive.files}
    except FileNotFoundError as exc:
        raise PointCloudFileError(path, "cannot read: no such file") from exc
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError) as exc:
        raise PointCloudFileError(path, f"not a readable NPZ archive: {exc}") from exc
    stamp_s = _npz_scalar(path, arrays, "stamp_s")
    if stamp_s is None:  # a recorder's Unix time, e.g. a field log's frame
        stamp_s = _npz_scalar(path, arrays, "stamp")
    stamp_s = stamp_s or 0.0
    if not math.isfinite(stamp_s) or stamp_s < 0:
        raise PointCloudFileError(path, f"stamp_s {stamp_s} is not a time")
    if "points" in arrays:
        points = arrays["points"]
        if points.ndim == 3 and points.shape[2] in (3, 4):
            rows, columns = points.shape[:2]
            points = points.reshape(-1, points.shape[2])
        elif points.ndim == 2 and points.shape[1] in (3, 4):
            rows, columns = 1, len(points)
        else:
            raise PointCloudFileError(
                path, f"points has shape {points.shape}, expected (N, 3|4) or (rows, columns, 3|4)"
            )
        xyz = [points[:, i] for i in range(3)]
        intensity = points[:, 3] if points.shape[1] == 4 else None
    elif all(axis in arrays for axis in ("x", "y", "z")):
        shapes = {arrays[name].shape for name in ("x", "y", "z", "intensity") if name in arrays}
        if len(shapes) != 1 or len(next(iter(shapes))) not in (1, 2):
            raise PointCloudFileError(
                path, f"x, y, z [, intensity] shapes differ: {sorted(shapes)}"
            )
        shape = next(iter(shapes))
        rows, columns = (shape[0], shape[1]) if len(shape) == 2 else (1, shape[0])
        xyz = [arrays[axis].reshape(-1) for axis in ("x", "y", "z")]
        intensity = arrays["intensity"].reshape(-1) if "intensity" in arrays else None
    else:
        raise PointCloudFileError(
            path, f"no points array and no x, y, z arrays (arrays: {', '.join(arrays) or 'none'})"
        )
    for values in (*xyz, *(() if intensity is None else (intensity,))):
        if values.dtype.kind not in "fiu":
            raise PointCloudFileError(path, f"point values of type {values.dtype} are not numbers")
    count = len(xyz[0])
    declared_rows = _npz_scalar(path, arrays, "rows")
    declared_columns = _npz_scalar(path, arrays, "columns")
    if rows == 1 and declared_rows is not None and declared_columns is not None:
        rows, columns = int(declared_rows), int(declared_columns)
        if rows < 1 or rows * columns != count:
            raise PointCloudFileError(path, f"rows x columns = {rows} x {columns}, {count} points")
    elif rows == 1 and shape_hint is not None and shape_hint[0] * shape_hint[1] == count:
        rows, columns = shape_hint
    return _assemble(path, xyz, intensity, rows, columns, stamp_s)


def _npz_scalar(path: Path, arrays: dict[str, npt.NDArray[np.generic]], name: str) -> float | None:
    if name not in arrays:
        return None
    value = arrays[name]
    if value.size != 1 or value.dtype.kind not in "fiu":
        raise PointCloudFileError(
            path, f"{name} must be one number, got {value.dtype} {value.shape}"
        )
    return float(value.reshape(-1)[0])
