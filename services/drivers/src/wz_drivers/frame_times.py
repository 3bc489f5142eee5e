"""The sidecar CSV that gives each recorded frame its time: ``<key>,time_unix_s``.

A folder of LiDAR frames names each frame by file (``file,time_unix_s``); a video by its
number (``frame,time_unix_s``). Both read the table here: a missing column raises
:class:`FieldDataError` at line 1 with the accepted names; a row that cannot be used is
reported with its line and left out.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

from wz_drivers.records import FieldDataError, Problems

#: Names of the time column (compared lower-case, first match wins).
TIME_COLUMN_NAMES = ("time_unix_s", "time")

K = TypeVar("K")


def read_frame_times(
    path: Path,
    problems: Problems,
    *,
    key: str,
    parse_key: Callable[[str], K],
    describe: Callable[[K], str],
) -> tuple[dict[K, tuple[float, int]], set[K]]:
    """``key -> (time [Unix s], CSV line)``, and the keys whose row had a bad time (reported;
    their frames are to be skipped, not reported again).

    Parameters
    ----------
    key
        The key column's name (``file``, ``frame``).
    parse_key
        A cell to its key; ``ValueError`` with the reason for a cell that is none.
    describe
        A key in words, for the messages (``a.pcd``, ``frame 3``).
    """
    try:
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise FieldDataError(path, "no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise FieldDataError(path, f"cannot read: {exc}") from None
    reader = csv.reader(text.splitlines())
    header = [name.strip().lower() for name in next(reader, [])]
    key_column = header.index(key) if key in header else None
    time_column = next((header.index(n) for n in TIME_COLUMN_NAMES if n in header), None)
    if key_column is None or time_column is None:
        missing = [
            f"{what} ({' or '.join(names)})"
            for what, names, column in (
                (key, (key,), key_column),
                ("time", TIME_COLUMN_NAMES, time_column),
            )
            if column is None
        ]
        raise FieldDataError(
            path, f"missing columns: {', '.join(missing)}; header: {','.join(header)}", line=1
        )
    table: dict[K, tuple[float, int]] = {}
    rejected: set[K] = set()
    for row in reader:
        number = reader.line_num
        if not any(cell.strip() for cell in row):
            continue
        if len(row) <= max(key_column, time_column):
            problems.add(
                FieldDataError(path, f"{len(row)} cells, expected {len(header)}", line=number)
            )
            continue
        try:
            frame = parse_key(row[key_column])
        except ValueError as exc:
            problems.add(FieldDataError(path, str(exc), line=number))
            continue
        try:
            stamp = float(row[time_column])
        except ValueError:
            stamp = math.nan
        if not (math.isfinite(stamp) and stamp >= 0.0):
            problems.add(
                FieldDataError(
                    path,
                    f"time {row[time_column].strip()!r} of {describe(frame)} is not a Unix "
                    "time [s]: frame skipped",
                    line=number,
                )
            )
            rejected.add(frame)
            continue
        if frame in table:
            problems.add(
                FieldDataError(
                    path,
                    f"{describe(frame)} again (first at line {table[frame][1]}): row ignored",
                    line=number,
                )
            )
            continue
        table[frame] = (stamp, number)
    return table, rejected - table.keys()
