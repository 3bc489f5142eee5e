"""What the gateway's API returns and accepts (pydantic), beyond the bus's own messages.

Alerts and live tracks are the bus's :class:`~wz_shared.messages.Alert` and
:class:`~wz_shared.messages.Track` as the alert service and the tracker published them; the
models here add what storage and HTTP need: stored track points, pages, keys, problems.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field

from wz_gateway.auth import Scope
from wz_shared.messages import Alert, FiniteFloat, Track, TrackStatus, VehicleClass


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class TrackPoint(_Model):
    """One stored point of a trajectory: a track at one tracker cycle."""

    track_id: Annotated[int, Field(ge=0)]
    stamp: FiniteFloat
    x_m: FiniteFloat
    y_m: FiniteFloat
    latitude_deg: FiniteFloat
    longitude_deg: FiniteFloat
    station_m: FiniteFloat
    offset_m: FiniteFloat
    lane_index: int
    speed_mps: FiniteFloat
    heading_rad: FiniteFloat
    vx_mps: FiniteFloat
    vy_mps: FiniteFloat
    object_class: VehicleClass
    status: TrackStatus
    length_m: FiniteFloat | None = None
    width_m: FiniteFloat | None = None
    #: False: the fused estimate at the time; True: smoothed after the track ended.
    smoothed: bool = False


#: The columns of a CSV export, in order (also the GeoJSON properties, less the coordinates).
TRACK_POINT_FIELDS: tuple[str, ...] = tuple(TrackPoint.model_fields)


class PointPage(_Model):
    """A page of stored track points, oldest first; ``next_cursor`` fetches the next page."""

    site: str
    count: int
    next_cursor: str | None
    points: list[TrackPoint]


class Trajectory(_Model):
    """One track's stored points, oldest first, a page at a time."""

    site: str
    track_id: int
    count: int
    next_cursor: str | None
    points: list[TrackPoint]


class LiveTrack(Track):
    """A track of the newest batch, with its WGS84 position."""

    latitude_deg: FiniteFloat
    longitude_deg: FiniteFloat


class LiveTracks(_Model):
    """The newest track batch the gateway received; empty before the first."""

    site: str
    stamp: FiniteFloat | None
    cycle_index: int | None
    #: Seconds since the gateway received the batch (wall clock); None before the first.
    age_s: FiniteFloat | None
    tracks: list[LiveTrack]


class AlertPage(_Model):
    """A page of alert events (newest first unless asked otherwise)."""

    site: str
    count: int
    next_cursor: str | None
    alerts: list[Alert]


#: Where a key came from: the settings, the admin API, or dev mode (made at start, logged).
KeyOrigin = Literal["settings", "api", "dev"]


class ApiKeyInfo(_Model):
    """A stored API key, without its secret."""

    key_id: str
    scope: Scope
    name: str
    origin: KeyOrigin
    created_at: FiniteFloat
    revoked_at: FiniteFloat | None = None


class NewApiKey(_Model):
    """Ask for a new key (admin)."""

    scope: Scope
    name: Annotated[str, Field(min_length=1, max_length=100, pattern=r"^[^\x00-\x1f]*$")]


class CreatedApiKey(ApiKeyInfo):
    """A key just made: the secret is shown this once, only its hash is kept."""

    secret: str


class Health(_Model):
    status: Literal["ok"]


class Readiness(_Model):
    """``ready`` when every check passes; each check says ``ok`` or what is wrong."""

    status: Literal["ready", "not_ready"]
    checks: dict[str, str]


class ProblemField(_Model):
    """One invalid input: where (``query.limit``) and why."""

    location: str
    message: str


class Problem(_Model):
    """An error, as RFC 9457 (RFC 7807) problem details."""

    type: str = "about:blank"
    title: str
    status: int
    detail: str
    instance: str | None = None
    errors: list[ProblemField] | None = None
