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
    dev_mode: bool = False
    #: Origins allowed to call the API from a browser (CORS); empty: none.
    cors_origins: Annotated[list[str], NoDecode] = Field(default_factory=list)
    #: Largest request body [bytes]; larger ones get 413.
    max_body_bytes: Annotated[int, Field(ge=1024, le=64 * 1024 * 1024)] = 64 * 1024
    #: Requests per second allowed to one key (or one address without a key), and the burst.
    rate_limit_per_s: Annotated[float, Field(gt=0.0, le=1e6)] = 50.0
    rate_limit_burst: Annotated[int, Field(ge=1, le=1_000_000)] = 200
    #: Largest page of points or alerts.
    max_page_size: Annotated[int, Field(ge=10, le=100_000)] = 10_000
    #: Track points and device states are deleted this long after they arrived [days].
    retention_days: Annotated[float, Field(gt=0.0, le=36500.0)] = 30.0
    #: Alerts are kept longer: they are the record DOTs ask for [days].
    alert_retention_days: Annotated[float, Field(gt=0.0, le=36500.0)] = 365.0
    #: How often the retention runs [s].
    retention_period_s: Annotated[float, Field(gt=0.0)] = 3600.0
    #: Messages held for the database writer; beyond it the bus waits (nothing is dropped).
    queue_capacity: Annotated[int, Field(ge=1, le=1_000_000)] = 4096
    #: A device whose data (or whose service's status) is older than this is in error [s].
    stale_after_s: Annotated[float, Field(gt=0.0, le=3600.0)] = 10.0
    #: The WZDx traffic sensor's collection interval [s] (counts over the newest interval).
    traffic_interval_s: Annotated[float, Field(ge=10.0, le=86400.0)] = 300.0
    #: Station of the virtual detector the traffic sensor counts at [m]; None: 30 m upstream
    #: of the LiDAR mast, where every sensor on the mast sees the road.
    traffic_detector_station_m: Annotated[float, Field(ge=0.0)] | None = None
    #: WZDx ``feed_info``: who publishes the feed.
    publisher: Annotated[str, Field(min_length=1, max_length=200)] = "Work-zone edge gateway"
    contact_email: Annotated[str, Field(max_length=200)] | None = None

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
