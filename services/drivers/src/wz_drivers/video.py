"""Video files and live streams (RTSP, HTTP ...) to JPEG :class:`CameraImage` records, via
OpenCV (its FFmpeg backend).

Time of a frame
---------------
Video file
    1. The ``timestamps`` CSV when given: a header with ``frame`` and ``time_unix_s`` (or
       ``time``); ``frame`` counts the decoded frames of the file from 0; one row per frame.
       A frame without a row, or whose row is bad, is skipped (the row, or the frame when it
       has no row, is reported).
    2. Else ``start_unix_s`` + the container's time of the frame (OpenCV's
       ``CAP_PROP_POS_MSEC``: the presentation time, 0 for the first frame).
    3. Neither: :class:`FieldDataError` (a file has no wall-clock time of its own).
Live stream (a URL: ``rtsp://``, ``rtsps://``, ``http(s)://``, ``rtmp://``, ``udp://``,
``tcp://``, ``srt://``)
    The wall clock (``time.time()``) when the frame was grabbed: this includes the network
    and decoder delay (typically 0.1-1 s for RTSP; the fusion's clock-offset estimate takes
    it up). A sidecar CSV or ``start_unix_s`` cannot apply and raise :class:`ValueError`.

Each frame's time must be after the previous one's; a frame whose time does not advance is
reported (the CSV line, or the frame of the file) and skipped. Credentials in a URL
(``rtsp://user:password@host``) are never logged: the password shows as ``***``.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Iterator
from pathlib import Path
from urllib.parse import urlsplit, urlunsplit

import cv2
import numpy as np
import numpy.typing as npt

from wz_drivers.frame_times import read_frame_times
from wz_drivers.records import CameraImage, FieldDataError, Problems

log = logging.getLogger(__name__)

#: URL schemes read as live streams; anything else is a file path.
STREAM_SCHEMES = ("rtsp", "rtsps", "rtmp", "http", "https", "udp", "tcp", "srt")


def is_stream_url(source: str | Path) -> bool:
    """Whether ``source`` names a live stream (see :data:`STREAM_SCHEMES`), not a file."""
    return isinstance(source, str) and urlsplit(source).scheme.lower() in STREAM_SCHEMES


def redact_url(url: str) -> str:
    """``url`` with its password, if any, replaced by ``***`` (for logs and errors)."""
    parts = urlsplit(url)
    if parts.password is None:
        return url
    host = parts.hostname or ""
    host = f"[{host}]" if ":" in host else host  # IPv6
    netloc = f"{parts.username}:***@{host}" + (f":{parts.port}" if parts.port else "")
    return urlunsplit(parts._replace(netloc=netloc))


def read_video(
    source: str | Path,
    problems: Problems,
    *,
    timestamps: Path | None = None,
    start_unix_s: float | None = None,
    jpeg_quality: int = 90,
    open_timeout_s: float = 10.0,
    read_timeout_s: float = 10.0,
) -> Iterator[CameraImage]:
    """Yield the frames of a video file or live stream as JPEG images.

    Parameters
    ----------
    source
        A video file (any container and codec OpenCV's FFmpeg reads: MP4/H.264, AVI/MJPG,
        MKV ...) or a stream URL (see the module docstring).
    problems
        Receives a :class:`FieldDataError` per skipped frame or bad CSV row, and one when a
        live stream stops.
    timestamps
        File only: CSV with columns ``frame`` and ``time_unix_s`` [Unix s].
    start_unix_s
        File only, without ``timestamps``: the Unix time of the file's time 0 [s].
    jpeg_quality
        JPEG quality of the re-encoded frames, 1-100.
    open_timeout_s, read_timeout_s
        Stream only: how long to wait for the stream to open, and for each frame [s].

    Raises
    ------
    FieldDataError
        The file is missing or OpenCV cannot open it, it gives no frame at all, it has no
        time (neither ``timestamps`` nor ``start_unix_s``), the CSV cannot be read as a whole,
        or the stream does not open within ``open_timeout_s``.
    ValueError
        A bad argument (``jpeg_quality`` out of range, a CSV or start time for a stream).
    """
    if not 1 <= jpeg_quality <= 100:
        raise ValueError(f"jpeg_quality must be 1-100, got {jpeg_quality}")
    encode_params = [int(cv2.IMWRITE_JPEG_QUALITY), int(jpeg_quality)]
    if is_stream_url(source):
        if timestamps is not None or start_unix_s is not None:
            raise ValueError(
                "a live stream is stamped with the wall clock at grab: timestamps and "
                "start_unix_s apply to files only"
            )
        yield from _read_stream(
            str(source), problems, encode_params, open_timeout_s, read_timeout_s
        )
        return
    path = Path(source)
    if not path.is_file():
        raise FieldDataError(path, "no such file" if not path.exists() else "not a file")
    table: dict[int, tuple[float, int]] | None = None
    rejected: set[int] = set()
    if timestamps is not None:
        table, rejected = _read_timestamps(Path(timestamps), problems)
    elif start_unix_s is None or not math.isfinite(start_unix_s):
        raise FieldDataError(
            path,
            "no time for the frames: give a timestamps CSV (frame,time_unix_s) or the "
            "Unix time of the video's start (start_unix_s)",
        )
    capture = cv2.VideoCapture(str(path))
    try:
        if not capture.isOpened():
            raise FieldDataError(
                path, "OpenCV cannot open it as a video (not a video, or a codec its FFmpeg lacks)"
            )
        index = -1
        previous: tuple[float, int] | None = None  # (time, frame)
        while capture.grab():
            index += 1
            if table is not None and timestamps is not None:
                row = table.get(index)
                if row is None:
                    if index not in rejected:
                        problems.add(
                            FieldDataError(
                                path,
                                f"no row in {timestamps}: frame skipped",
                                line=index,
                                unit="frame",
                            )
                        )
                    continue
                stamp, csv_line = row
                # A time that goes back is the CSV's fault: name its line.
                source_of_time: tuple[Path, int, str] = (timestamps, csv_line, "line")
            else:
                assert start_unix_s is not None  # checked above
                stamp = start_unix_s + capture.get(cv2.CAP_PROP_POS_MSEC) / 1e3
                source_of_time = (path, index, "frame")
            if previous is not None and stamp <= previous[0]:
                where, line, unit = source_of_time
                problems.add(
                    FieldDataError(
                        where,
                        f"time {stamp:.6f} of frame {index} is not after {previous[0]:.6f} "
                        f"(frame {previous[1]}): frame skipped",
                        line=line,
                        unit=unit,
                    )
                )
                continue
            image = _retrieve(capture, encode_params, stamp, f"{path} (frame {index})")
            if image is None:
                problems.add(
                    FieldDataError(
                        path, "cannot decode or encode the frame: skipped", line=index, unit="frame"
                    )
                )
                continue
            previous = (stamp, index)
            yield image
        if index < 0:
            raise FieldDataError(path, "OpenCV opened it but decodes no frame")
        if table is not None and timestamps is not None:
            beyond = sorted(frame for frame in table if frame > index)
            if beyond:
                problems.add(
                    FieldDataError(
                        timestamps,
                        f"rows for frames {beyond[0]}-{beyond[-1]}, the video ends at "
                        f"frame {index}",
                        line=table[beyond[0]][1],
                    )
                )
    finally:
        capture.release()


def _read_stream(
    url: str,
    problems: Problems,
    encode_params: list[int],
    open_timeout_s: float,
    read_timeout_s: float,
) -> Iterator[CameraImage]:
    shown = redact_url(url)
    params = [
        int(cv2.CAP_PROP_OPEN_TIMEOUT_MSEC),
        int(open_timeout_s * 1e3),
        int(cv2.CAP_PROP_READ_TIMEOUT_MSEC),
        int(read_timeout_s * 1e3),
    ]
    log.info("opening stream %s", shown)
    capture = cv2.VideoCapture(url, cv2.CAP_FFMPEG, params)
    try:
        if not capture.isOpened():
            raise FieldDataError(
                shown,
                f"cannot open the stream: nothing answered within {open_timeout_s:g} s, "
                "refused, or not a stream OpenCV's FFmpeg reads",
            )
        index = -1
        previous: float | None = None
        while True:
            if not capture.grab():
                problems.add(
                    FieldDataError(
                        shown,
                        f"the stream stopped after {index + 1} frames (no frame within "
                        f"{read_timeout_s:g} s, or the sender closed it)",
                    )
                )
                return
            stamp = time.time()  # at grab: before decoding, as close to arrival as we can
            index += 1
            if previous is not None and stamp <= previous:
                problems.add(
                    FieldDataError(
                        shown,
                        f"the wall clock went back ({stamp:.6f} after {previous:.6f}): "
                        "frame skipped",
                        line=index,
                        unit="frame",
                    )
                )
                continue
            image = _retrieve(capture, encode_params, stamp, f"{shown} (frame {index})")
            if image is None:
                problems.add(
                    FieldDataError(
                        shown,
                        "cannot decode or encode the frame: skipped",
                        line=index,
                        unit="frame",
                    )
                )
                continue
            previous = stamp
            yield image
    finally:
        capture.release()


def _retrieve(
    capture: cv2.VideoCapture, encode_params: list[int], stamp: float, where: str
) -> CameraImage | None:
    """Decode the grabbed frame and encode it as JPEG; None when either fails."""
    ok, frame = capture.retrieve()
    if not ok or frame is None:
        return None
    pixels: npt.NDArray[np.uint8] = np.asarray(frame, dtype=np.uint8)
    encoded, jpeg = cv2.imencode(".jpg", pixels, encode_params)
    if not encoded:
        return None
    height, width = pixels.shape[:2]
    return CameraImage(
        stamp=stamp, jpeg=jpeg.tobytes(), width_px=int(width), height_px=int(height), where=where
    )


def _frame_number(cell: str) -> int:
    try:
        frame = int(cell)
    except ValueError:
        frame = -1
    if frame < 0:
        raise ValueError(f"frame {cell.strip()!r} is not a frame number (0, 1 ...)")
    return frame


def _read_timestamps(
    path: Path, problems: Problems
) -> tuple[dict[int, tuple[float, int]], set[int]]:
    """``frame -> (time [Unix s], CSV line)``, and the frames whose row was bad (reported)."""
    return read_frame_times(
        path,
        problems,
        key="frame",
        parse_key=_frame_number,
        describe=lambda frame: f"frame {frame}",
    )
