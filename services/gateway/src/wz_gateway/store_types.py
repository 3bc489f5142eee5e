"""The storage's cursors, queries and results: what :class:`~wz_gateway.storage.Storage` takes
and gives, apart from it (and re-exported by :mod:`wz_gateway.storage`)."""

from __future__ import annotations

import base64
import json
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from wz_shared.messages import CalibrationState


class CursorError(ValueError):
    """A page cursor that this API did not give out (or from another query order)."""


# --- cursors ------------------------------------------------------------------------------


def encode_cursor(stamp: float, row_id: int) -> str:
    """An opaque cursor for the row after (``stamp``, ``row_id``)."""
    raw = json.dumps([stamp, row_id], separators=(",", ":")).encode()
    return base64.urlsafe_b64encode(raw).decode().rstrip("=")


def decode_cursor(cursor: str) -> tuple[float, int]:
    """The (stamp, id) of a cursor; :class:`CursorError` if it is not one of ours."""
    try:
        padded = cursor + "=" * (-len(cursor) % 4)
        stamp, row_id = json.loads(base64.urlsafe_b64decode(padded.encode("ascii")))
    except (ValueError, TypeError, UnicodeError) as exc:
        raise CursorError("not a cursor this API gave out; use the next_cursor of a page") from exc
    if (
        not isinstance(stamp, int | float)
        or isinstance(stamp, bool)
        or not math.isfinite(stamp)
        or not isinstance(row_id, int)
        or isinstance(row_id, bool)
        or not 0 <= row_id < 2**63
    ):
        raise CursorError("not a cursor this API gave out; use the next_cursor of a page")
    return float(stamp), row_id


# --- queries and results ------------------------------------------------------------------


@dataclass(frozen=True)
class PointQuery:
    """Track points wanted: every filter is optional and they combine with AND.

    ``bbox_deg`` is (min longitude, min latitude, max longitude, max latitude) [deg]; stations
    and stamps are inclusive bounds. ``smoothed`` None returns both kinds of point.
    """

    site: str
    start_stamp: float | None = None
    end_stamp: float | None = None
    track_id: int | None = None
    station_min_m: float | None = None
    station_max_m: float | None = None
    bbox_deg: tuple[float, float, float, float] | None = None
    lane_index: int | None = None
    min_speed_mps: float | None = None
    max_speed_mps: float | None = None
    smoothed: bool | None = None
    limit: int = 1000
    cursor: str | None = None


@dataclass(frozen=True)
class AlertQuery:
    """Alert events wanted; empty tuples mean any type, severity or phase; site None: every
    site's."""

    site: str | None
    alert_types: tuple[str, ...] = ()
    severities: tuple[str, ...] = ()
    phases: tuple[str, ...] = ()
    start_stamp: float | None = None
    end_stamp: float | None = None
    track_id: int | None = None
    episode_id: str | None = None
    newest_first: bool = True
    limit: int = 100
    cursor: str | None = None


@dataclass(frozen=True)
class QueueQuery:
    """Stored queue states of one site wanted; ``conditions`` empty: any worst condition."""

    site: str
    start_stamp: float | None = None
    end_stamp: float | None = None
    conditions: tuple[str, ...] = ()
    newest_first: bool = True
    limit: int = 100
    cursor: str | None = None


@dataclass(frozen=True)
class Page:
    """Rows of one page and the cursor of the next (None on the last page)."""

    items: list[Any]
    next_cursor: str | None


@dataclass(frozen=True)
class LatestRow:
    """The newest message of one kind: its JSON, capture stamp and arrival (wall clock)."""

    name: str
    stamp: float
    received_at: float
    body: str


@dataclass(frozen=True)
class CalibrationChange:
    """A sensor's self-calibration entering a state (a row of ``calibration_changes``).

    ``stamp`` is the stamp of the message that brought it and ``state_since_s`` the stamp the
    state was entered at [s, the sensor's time]; ``received_at`` the gateway's wall clock
    [Unix s]; ``previous_state`` None for the first message of the sensor stored.
    """

    sensor_id: str
    sensor_kind: str
    state: CalibrationState
    previous_state: CalibrationState | None
    stamp: float
    state_since_s: float
    detail: str
    received_at: float


@dataclass
class IngestResult:
    """What one :meth:`Storage.ingest` wrote."""

    track_batches: int = 0
    points: int = 0
    alerts: int = 0
    duplicate_alerts: int = 0
    device_states: int = 0
    queue_states: int = 0
    statuses: int = 0
    #: Sensor calibrations stored, and those that changed a sensor's state.
    calibrations: int = 0
    calibration_changes: int = 0
    #: Upstream point speed sensors' readings (each the sensor's latest).
    point_readings: int = 0
    #: Webhook events queued (one per alert and subscription that wants it).
    webhook_events: int = 0


@dataclass(frozen=True)
class TrafficPoints:
    """Track points near a station over a window, as arrays of one length N."""

    track_id: npt.NDArray[np.int64]
    stamp: npt.NDArray[np.float64]
    station_m: npt.NDArray[np.float64]
    lane_index: npt.NDArray[np.int64]
    offset_m: npt.NDArray[np.float64]
    speed_mps: npt.NDArray[np.float64]
    vx_mps: npt.NDArray[np.float64]
    vy_mps: npt.NDArray[np.float64]
    length_m: npt.NDArray[np.float64]  # NaN where the tracker gave no length
    # Where the vehicle stands and what it is, for the sight of the lanes (lane_sight).
    x_m: npt.NDArray[np.float64]
    y_m: npt.NDArray[np.float64]
    heading_rad: npt.NDArray[np.float64]
    width_m: npt.NDArray[np.float64]  # NaN where the tracker gave no width
    object_class: list[str]
