"""What the gateway's API returns and accepts (pydantic), beyond the bus's own messages.

Alerts and live tracks are the bus's :class:`~wz_shared.messages.Alert` and
:class:`~wz_shared.messages.Track` as the alert service and the tracker published them; the
models here add what storage and HTTP need: stored track points, pages, keys, problems.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

from wz_gateway import webhooks
from wz_gateway.auth import Scope
from wz_gateway.conflicts import Conflict
from wz_shared.messages import (
    Alert,
    AlertPhase,
    AlertSeverity,
    CalibrationState,
    FiniteFloat,
    QueueState,
    SensorCalibration,
    Track,
    TrackStatus,
    VehicleClass,
)


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


class ConflictPage(_Model):
    """Conflicts of a window (:mod:`wz_gateway.conflicts`), by the time of their minimum TTC;
    ``next_cursor`` fetches the next page."""

    site: str
    start: float
    end: float
    max_ttc_s: float
    max_pet_s: float
    count: int
    next_cursor: str | None
    conflicts: list[Conflict]


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


class CalibrationStateChange(_Model):
    """A sensor's self-calibration entering a state, as the gateway stored it."""

    state: CalibrationState
    #: The state before; None for the first message of the sensor this gateway stored.
    previous_state: CalibrationState | None
    #: Stamp of the message that brought the change [s, the sensor's time].
    stamp: FiniteFloat
    #: Stamp the state was entered at [s, the sensor's time].
    state_since_s: FiniteFloat
    #: Why, as the detector put it (``yaw moved 2.1 deg within 12 s``).
    detail: str
    #: When the gateway received it [Unix s].
    received_at: FiniteFloat


class SensorCalibrationStatus(_Model):
    """One sensor's self-calibration: its newest message as its detector published it, when
    it arrived, and its latest changes of state, newest first."""

    sensor_id: str
    sensor_kind: Literal["lidar", "camera", "radar"]
    #: None: nothing received from this sensor of the site file (its detector is not running,
    #: or does not learn its pose).
    calibration: SensorCalibration | None
    #: When the gateway received it [Unix s], and how long ago [s].
    received_at: FiniteFloat | None
    age_s: FiniteFloat | None
    #: Nothing received for longer than ``calibration_stale_after_s``: the state may be old.
    stale: bool
    changes: list[CalibrationStateChange]


class SiteCalibration(_Model):
    """The self-calibration of each sensor of a site: the site file's sensors in its order,
    then any other sensor heard from."""

    site: str
    sensors: list[SensorCalibrationStatus]


class SiteQueue(_Model):
    """A site's queue now: the newest per-lane state its alert service published (once a
    second of track stamps), when it arrived, and whether that is longer ago than
    ``stale_after_s`` (the alert service or the tracks stopped: the state may be old)."""

    site: str
    #: None: nothing received yet.
    queue: QueueState | None
    received_at: FiniteFloat | None
    age_s: FiniteFloat | None
    stale: bool


class QueuePage(_Model):
    """A page of stored queue states (newest first unless asked otherwise)."""

    site: str
    count: int
    next_cursor: str | None
    states: list[QueueState]


class SiteSummary(_Model):
    """One site a gateway serves."""

    site_id: str
    name: str
    default: bool


class AlertPage(_Model):
    """A page of alert events (newest first unless asked otherwise); ``site`` is ``*`` for
    every site's."""

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
    #: Made while the gateway ran in dev mode: revoked when it starts outside dev mode.
    dev_mode: bool = False


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


# --- webhooks -----------------------------------------------------------------------------

#: A subscription's public id: ``wh_`` and 16 hex digits.
WEBHOOK_ID_PATTERN = r"^wh_[0-9a-f]{16}$"
#: A receiver's URL: http:// or https:// (any case), then printable ASCII without spaces (an
#: international host name in its ``xn--`` form).
WEBHOOK_URL_PATTERN = r"^[Hh][Tt][Tt][Pp][Ss]?://[!-~]+$"
WEBHOOK_URL_MAX_CHARS = 2000


class NewWebhook(_Model):
    """Subscribe a URL to alert events (admin). Each event is POSTed as signed JSON (Standard
    Webhooks); the secret to check the signatures is in the answer, once."""

    url: Annotated[
        str,
        Field(
            min_length=1,
            max_length=WEBHOOK_URL_MAX_CHARS,
            pattern=WEBHOOK_URL_PATTERN,
            description="http(s) URL the "
            "events are POSTed to; its host must resolve to public "
            "addresses unless the settings allow others",
        ),
    ]
    event_types: Annotated[
        list[str],
        Field(
            min_length=1,
            max_length=20,
            description="`alert.*` for every alert, or `alert.<type>` (`alert.speeding`...)",
        ),
    ] = [webhooks.ALL_ALERTS]
    #: Only alerts of this severity or higher; None: any.
    min_severity: AlertSeverity | None = None
    #: Only these episode phases (start, update, clear); None or empty: every phase.
    phases: Annotated[list[AlertPhase], Field(max_length=3)] | None = None
    description: Annotated[str, Field(max_length=200, pattern=r"^[^\x00-\x1f]*$")] = ""

    @field_validator("url", mode="before")
    @classmethod
    def _url_scheme(cls, value: object) -> object:
        """The scheme and credentials first, with what is wrong (the pattern says less)."""
        if isinstance(value, str) and len(value) <= WEBHOOK_URL_MAX_CHARS:
            webhooks.parse_destination(value)
        return value

    @field_validator("event_types")
    @classmethod
    def _event_types(cls, value: list[str]) -> list[str]:
        return webhooks.normalize_event_types(value)


class WebhookInfo(_Model):
    """A subscription, without its secret."""

    subscription_id: str
    url: str
    event_types: list[str]
    min_severity: AlertSeverity | None = None
    phases: list[AlertPhase] | None = None
    description: str
    created_at: FiniteFloat
    #: Set when the receiver answered 410 Gone: nothing more is sent (delete and subscribe again).
    disabled_at: FiniteFloat | None = None
    disabled_reason: str | None = None
    #: After a rotation: until when the previous secret also signs [Unix s].
    previous_secret_until: FiniteFloat | None = None


class CreatedWebhook(WebhookInfo):
    """A subscription just made: its signing secret (``whsec_...``) is shown this once."""

    secret: str


class WebhookSecret(_Model):
    """A new signing secret; the previous one also signs until ``previous_secret_until``."""

    subscription_id: str
    secret: str
    previous_secret_until: FiniteFloat | None


class WebhookTestEvent(_Model):
    """A ``webhook.test`` event queued for delivery."""

    subscription_id: str
    event_id: str
    event_type: str


class WebhookEventInfo(_Model):
    """One event for one subscription and where its delivery stands."""

    event_id: str
    event_type: str
    state: Literal["pending", "delivered", "failed", "expired"]
    attempts: int
    created_at: FiniteFloat
    next_attempt_at: FiniteFloat | None = None
    finished_at: FiniteFloat | None = None
    last_status_code: int | None = None
    last_error: str | None = None
