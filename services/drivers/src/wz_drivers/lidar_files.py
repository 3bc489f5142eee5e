"""LiDAR frames saved one file per sweep (PCD, PLY, NPZ) to :class:`LidarSweep` records.

Formats: PCD v0.7 (ascii, binary, binary_compressed), PLY (ascii, binary either endianness)
and NPZ, parsed by :mod:`wz_shared.pointcloud_files` (numpy only; the LiDAR detector's own
reader: Open3D drops intensity and organization). An NPZ may carry its Unix time as ``stamp``
(or ``stamp_s``).

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

import logging
import re
from collections.abc import Iterator
from decimal import Decimal
from pathlib import Path

import numpy as np

from wz_drivers.frame_times import read_frame_times
from wz_drivers.records import FieldDataError, LidarSweep, Problems
from wz_shared.arrays import F32
from wz_shared.pointcloud_files import PointCloudFileError, PointFrame, read_point_cloud

log = logging.getLogger(__name__)


#: Suffixes of the files :func:`read_frame_folder` takes as frames (compared lower-case).
FRAME_SUFFIXES = (".pcd", ".ply", ".npz")
#: Unix times a file name may carry [s]: 2000-01-01 to 2100-01-01 (UTC).
PLAUSIBLE_UNIX_S = (946_684_800.0, 4_102_444_800.0)
#: Digits of an integer time in a file name -> units per second (s, ms, us, ns).
_NAME_TIME_DIVISORS = {9: 1, 10: 1, 13: 10**3, 16: 10**6, 19: 10**9}


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
        stamp = csv_row[0] if csv_row is not None else _stamp_of(cloud)
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
        stamp = _stamp_of(cloud)
        stamp = time_from_name(path) if stamp is None else stamp
    return _sweep(cloud, 0.0 if stamp is None else stamp, str(path))


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


def _load(path: Path) -> PointFrame:
    """Parse one frame file; its problems as :class:`FieldDataError` (naming the file)."""
    if not path.is_file():
        raise FieldDataError(path, "no such file" if not path.exists() else "not a file")
    try:
        return read_point_cloud(path)
    except PointCloudFileError as exc:
        raise FieldDataError(path, exc.problem) from None


def _stamp_of(frame: PointFrame) -> float | None:
    """The frame's own time [Unix s] (an NPZ's ``stamp``), or None (0: none given)."""
    return frame.stamp_s if frame.stamp_s > 0.0 else None


def _sweep(frame: PointFrame, stamp: float, where: str) -> LidarSweep:
    """A frame as a sweep, marking no-return points: in an organized frame a point with a
    non-finite coordinate or at exactly (0, 0, 0) gets NaN x, y, z and keeps its slot; in an
    unorganized cloud such points are dropped."""
    points = np.array(frame.points, dtype=np.float32, copy=True)
    xyz = points[:, :3]
    no_return = ~np.isfinite(xyz).all(axis=1) | ~xyz.any(axis=1)
    if frame.organized:
        points[no_return, :3] = np.nan
        return LidarSweep(
            stamp=stamp,
            points=points,
            rows=frame.rows,
            columns=frame.columns,
            organized=True,
            where=where,
        )
    kept: F32 = np.ascontiguousarray(points[~no_return])
    return LidarSweep(stamp=stamp, points=kept, rows=1, columns=0, organized=False, where=where)


# --- timestamps CSV -------------------------------------------------------------------------


def _read_timestamps(
    path: Path, frame_names: set[str], problems: Problems
) -> tuple[dict[str, tuple[float, int]], set[str]]:
    """``file name -> (time [Unix s], CSV line)`` of the folder's frames, and the names of
    frames whose row was bad (reported and left out)."""
    table, rejected = read_frame_times(
        path,
        problems,
        key="file",
        parse_key=lambda cell: Path(cell.strip()).name,
        describe=lambda name: name,
    )
    for name, (_, number) in list(table.items()):
        if name not in frame_names:
            problems.add(FieldDataError(path, f"no frame file {name!r} in the folder", line=number))
            del table[name]
    return table, rejected
