"""Settings of the gateway (env prefix ``WZ_GATEWAY_``), units in the names.

Outside a development machine the gateway refuses to start without an API key: set
``WZ_GATEWAY_API_KEYS=admin:<secret>`` (``python -m wz_gateway.keys`` makes a secret), or
``WZ_GATEWAY_DEV_MODE=true`` on a development machine, where reads need no key, the gateway
listens on loopback only and an admin key is made up and logged at start.
"""

from __future__ import annotations

import ipaddress
import os
from pathlib import Path
from typing import Annotated

from pydantic import Field, field_validator, model_validator
from pydantic_settings import NoDecode, SettingsConfigDict

from wz_gateway.auth import parse_configured_key
from wz_shared.settings import ServiceSettings

#: The database file's name under ``data_dir`` when no ``database_url`` is set.
DEFAULT_DATABASE_FILE = "gateway.sqlite3"


def _default_data_dir() -> Path:
    base = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return Path(base) / "wz" / "gateway"


def _split_list(value: object) -> object:
    """Accept ``a,b`` or a JSON list from the environment."""
    if isinstance(value, str):
        value = value.strip()
        if value.startswith("["):
            return value  # pydantic parses the JSON list
        return [part.strip() for part in value.split(",") if part.strip()]
    return value


def is_loopback(host: str) -> bool:
    """Whether ``host`` (an address or ``localhost``) is reachable from this machine only."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class GatewaySettings(ServiceSettings):
    """The gateway's settings; build it in ``main()``, tests pass keyword arguments."""

    model_config = SettingsConfigDict(env_prefix="WZ_GATEWAY_", extra="ignore")

    #: The sites served: site files or folders of them (``*.yaml``), comma-separated. Empty:
    #: the one in ``WZ_SITE_FILE`` (a trailer's gateway). A central gateway on the regional
    #: router lists every trailer's and stores all of them; the first is the API's default.
    site_files: Annotated[list[Path], NoDecode] = Field(default_factory=list)
    #: Address and port of the HTTP server; port 0 takes any free port (tests).
    host: str = "127.0.0.1"
    port: Annotated[int, Field(ge=0, le=65535)] = 8000
    #: Folder of the default SQLite file (created when missing).
    data_dir: Path = Field(default_factory=_default_data_dir)
    #: SQLAlchemy URL, e.g. ``postgresql+psycopg://wz:...@db/wz``; None: the SQLite file
    #: ``<data_dir>/gateway.sqlite3``.
    database_url: str | None = None
    #: Keys accepted at start, ``<scope>:<secret>`` with scope ``read`` or ``admin``,
    #: comma-separated; stored hashed. Keys made through the API live in the database.
    api_keys: Annotated[list[str], NoDecode] = Field(default_factory=list, repr=False)
    #: A development machine: reads need no key, loopback only, an admin key is made and logged.
    #: Keys made in dev mode (that one, and those made through the API) are revoked when the
    #: gateway starts with dev mode off.
    dev_mode: bool = False
    #: Most keys live at once; making one more through the API gets 409 (revoke some first).
    #: Keys from the settings are not refused, but count.
    max_api_keys: Annotated[int, Field(ge=1, le=1_000_000)] = 1000
    #: Origins allowed to call the API from a browser (CORS); empty: none.
    cors_origins: Annotated[list[str], NoDecode] = Field(default_factory=list)
    #: Largest request body [bytes]; larger ones get 413.
    max_body_bytes: Annotated[int, Field(ge=1024, le=64 * 1024 * 1024)] = 64 * 1024
    #: Requests per second allowed to one key (or one address without a key), and the burst.
    rate_limit_per_s: Annotated[float, Field(gt=0.0, le=1e6)] = 50.0
    rate_limit_burst: Annotated[int, Field(ge=1, le=1_000_000)] = 200
    #: Largest page of points or alerts.
    max_page_size: Annotated[int, Field(ge=10, le=100_000)] = 10_000
    #: Track points, device states and the sensors' changes of calibration state are deleted
    #: this long after they arrived [days].
    retention_days: Annotated[float, Field(gt=0.0, le=36500.0)] = 30.0
    #: Alerts are kept longer: they are the record DOTs ask for [days].
    alert_retention_days: Annotated[float, Field(gt=0.0, le=36500.0)] = 365.0
    #: How often the retention runs [s].
    retention_period_s: Annotated[float, Field(gt=0.0)] = 3600.0
    #: Messages held for the database writer; beyond it the bus waits (nothing is dropped).
    queue_capacity: Annotated[int, Field(ge=1, le=1_000_000)] = 4096
    #: A device whose data (or whose service's status) is older than this is in error [s].
    stale_after_s: Annotated[float, Field(gt=0.0, le=3600.0)] = 10.0
    #: A sensor's self-calibration older than this is not judged (its detector sends one every
    #: 5 s of sensor time; the device's own freshness says when the detector stopped) [s].
    calibration_stale_after_s: Annotated[float, Field(gt=0.0, le=3600.0)] = 30.0
    #: A sensor still ``prior`` or ``learning`` this long after it entered that state puts its
    #: WZDx device in ``warning`` [s of the sensor's time].
    calibration_learning_warning_s: Annotated[float, Field(gt=0.0, le=86400.0)] = 900.0
    #: The WZDx traffic sensor's collection interval [s] (counts over the newest interval).
    traffic_interval_s: Annotated[float, Field(ge=10.0, le=86400.0)] = 300.0
    #: Station of the virtual detector the traffic sensor counts at [m]; None: where the site's
    #: LiDARs see every lane best, upstream of the taper and the mast
    #: (:func:`wz_gateway.wzdx.detector_station_m`).
    traffic_detector_station_m: Annotated[float, Field(ge=0.0)] | None = None
    #: WZDx ``feed_info``: who publishes the feed.
    publisher: Annotated[str, Field(min_length=1, max_length=200)] = "Work-zone edge gateway"
    contact_email: Annotated[str, Field(max_length=200)] | None = None
    #: A track missing from the track batches for longer than this has ended, and its stored
    #: trajectory is smoothed, with the process noise the tracker's batches carried [s of
    #: stamps]; no batch at all for ``track_end_silence_s`` [s of wall clock] ends every track
    #: (the tracker stopped).
    track_end_after_s: Annotated[float, Field(gt=0.0, le=3600.0)] = 3.0
    track_end_silence_s: Annotated[float, Field(gt=0.0, le=86400.0)] = 30.0
    #: The live stream (/v1/stream): most track batches a second to one client [Hz], events
    #: held for a slow client (beyond, its oldest are dropped), the heartbeat comment's
    #: period [s], and the most clients at once.
    stream_max_hz: Annotated[float, Field(gt=0.0, le=50.0)] = 10.0
    stream_queue_capacity: Annotated[int, Field(ge=1, le=10_000)] = 64
    stream_heartbeat_s: Annotated[float, Field(gt=0.0, le=300.0)] = 15.0
    stream_max_clients: Annotated[int, Field(ge=1, le=10_000)] = 32

    #: Webhooks. Receivers must be at public addresses (no SSRF into the site's network)
    #: unless their addresses are in ``webhook_allowed_networks`` (CIDRs, e.g.
    #: ``10.20.0.0/16,fd00::/8``) or ``webhook_allow_private``; dev mode allows loopback.
    webhook_allow_private: bool = False
    webhook_allowed_networks: Annotated[list[str], NoDecode] = Field(default_factory=list)
    #: An event not delivered this long after it was stored expires (for safety alerts, late
    #: is as bad as never) [s].
    webhook_event_ttl_s: Annotated[float, Field(gt=0.0, le=7 * 86400.0)] = 900.0
    #: Retries: full-jitter exponential backoff, uniform in [0, min(cap, base * 2^(n-1))] [s].
    webhook_backoff_base_s: Annotated[float, Field(gt=0.0, le=3600.0)] = 1.0
    webhook_backoff_cap_s: Annotated[float, Field(gt=0.0, le=86400.0)] = 300.0
    #: One attempt's time limit (connect, send, each read) [s], and the claim's lease: an event
    #: claimed by a gateway that died is taken again after it [s] (more than the timeout).
    webhook_timeout_s: Annotated[float, Field(gt=0.0, le=120.0)] = 10.0
    webhook_lease_s: Annotated[float, Field(gt=0.0, le=3600.0)] = 30.0
    #: Subscriptions delivered to at once (one request in flight per subscription).
    webhook_workers: Annotated[int, Field(ge=1, le=256)] = 8
    #: How often the outbox is looked at when nothing wakes the delivery [s].
    webhook_poll_interval_s: Annotated[float, Field(gt=0.0, le=60.0)] = 0.5
    #: After a secret rotation, how long the previous secret still signs too [s].
    webhook_secret_grace_s: Annotated[float, Field(ge=0.0, le=30 * 86400.0)] = 86400.0

    @field_validator("webhook_allowed_networks", "site_files", mode="before")
    @classmethod
    def _parse_networks(cls, value: object) -> object:
        return _split_list(value)

    @property
    def site_entries(self) -> list[Path]:
        """The site files (or folders) to serve: ``site_files``, else ``site_file``."""
        return list(self.site_files) or [self.site_file]

    @field_validator("webhook_allowed_networks")
    @classmethod
    def _networks(cls, value: list[str]) -> list[str]:
        for entry in value:
            try:
                ipaddress.ip_network(entry, strict=False)
            except ValueError as exc:
                raise ValueError(
                    f"WZ_GATEWAY_WEBHOOK_ALLOWED_NETWORKS: {entry!r} is not a "
                    "network (write CIDRs such as 10.20.0.0/16)"
                ) from exc
        return value

    @model_validator(mode="after")
    def _webhook_lease(self) -> GatewaySettings:
        if self.webhook_lease_s <= self.webhook_timeout_s:
            raise ValueError(
                f"webhook_lease_s ({self.webhook_lease_s}) must be longer than "
                f"webhook_timeout_s ({self.webhook_timeout_s}): a lease running out while its "
                "attempt still waits would let a second attempt start"
            )
        return self

    @field_validator("api_keys", "cors_origins", mode="before")
    @classmethod
    def _parse_list(cls, value: object) -> object:
        return _split_list(value)

    @field_validator("api_keys")
    @classmethod
    def _keys(cls, value: list[str]) -> list[str]:
        for number, entry in enumerate(value, start=1):
            parse_configured_key(entry, where=f"WZ_GATEWAY_API_KEYS entry {number}")
        return value

    @model_validator(mode="after")
    def _secure(self) -> GatewaySettings:
        if self.dev_mode:
            if not is_loopback(self.host):
                raise ValueError(
                    f"dev mode lets anyone read without a key, so it listens on loopback only; "
                    f"host {self.host!r} is not a loopback address (use 127.0.0.1, or set "
                    "WZ_GATEWAY_API_KEYS and leave dev mode off)"
                )
            return self
        if not self.api_keys:
            raise ValueError(
                "no API key: set WZ_GATEWAY_API_KEYS=admin:<secret> (make one with "
                "`python -m wz_gateway.keys`), or WZ_GATEWAY_DEV_MODE=true on a development "
                "machine"
            )
        return self

    def resolved_database_url(self) -> str:
        """``database_url``, or the SQLite file under ``data_dir``."""
        if self.database_url:
            return self.database_url
        return f"sqlite:///{(self.data_dir / DEFAULT_DATABASE_FILE).resolve()}"
