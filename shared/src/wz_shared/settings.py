"""Settings shared by every service, read from the environment with pydantic-settings.

Each service defines its own ``<Service>Settings(ServiceSettings)`` with its own env prefix
(``WZ_SIM_``, ``WZ_LIDAR_`` ...) and builds it in ``main()``; the bus settings below are common
and read with the prefix ``WZ_BUS_`` so one environment configures every process of a stack.
Units are in the names.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

from pydantic import Field, field_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

from wz_shared.site import DEFAULT_SITE_PATH

#: Where the local stack's router listens by default (loopback only).
DEFAULT_ROUTER_ENDPOINT = "tcp/127.0.0.1:7447"


def _split_endpoints(value: object) -> object:
    """Accept ``a,b`` or a JSON list from the environment."""
    if isinstance(value, str):
        value = value.strip()
        if value.startswith("["):
            return value  # let pydantic parse the JSON list
        return [part.strip() for part in value.split(",") if part.strip()]
    return value


class BusSettings(BaseSettings):
    """How a process joins the Zenoh bus (env prefix ``WZ_BUS_``).

    The embedded default is a peer on loopback that connects to the local router endpoint and
    listens on an ephemeral loopback port, with multicast scouting off: nothing is reachable
    from another host unless a deployment config says so.
    """

    model_config = SettingsConfigDict(env_prefix="WZ_BUS_", extra="ignore")

    mode: Literal["peer", "client", "router"] = "peer"
    connect_endpoints: Annotated[list[str], NoDecode] = Field(
        default_factory=lambda: [DEFAULT_ROUTER_ENDPOINT]
    )
    listen_endpoints: Annotated[list[str], NoDecode] = Field(
        default_factory=lambda: ["tcp/127.0.0.1:0"]
    )
    multicast_scouting: bool = False
    #: A zenoh JSON5 config file (deployments); the fields above override what it says.
    config_file: Path | None = None
    #: This session's credentials folder (``wz credentials``: ``ca.pem``, ``cert.pem``,
    #: ``key.pem``): mutual TLS with that certificate, whatever the config file's TLS paths
    #: say (:func:`wz_shared.trust.tls_config`). None: the config file's, or no TLS.
    tls_dir: Path | None = None

    @field_validator("connect_endpoints", "listen_endpoints", mode="before")
    @classmethod
    def _parse_endpoints(cls, value: object) -> object:
        return _split_endpoints(value)


class ServiceSettings(BaseSettings):
    """Fields every service has; subclasses set their own ``env_prefix``.

    These few are stack-wide, so they keep one name whatever the service's prefix:
    ``WZ_SITE_FILE``, ``WZ_STATUS_PERIOD_S``, ``WZ_LOG_LEVEL``, ``WZ_HEALTH_FILE``.
    """

    model_config = SettingsConfigDict(env_prefix="WZ_", extra="ignore", populate_by_name=True)

    site_file: Path = Field(default=DEFAULT_SITE_PATH, validation_alias="WZ_SITE_FILE")
    status_period_s: Annotated[float, Field(gt=0.0, validation_alias="WZ_STATUS_PERIOD_S")] = 1.0
    log_level: Literal["DEBUG", "INFO", "WARNING", "ERROR"] = Field(
        default="INFO", validation_alias="WZ_LOG_LEVEL"
    )
    #: Heartbeat file touched with each status message, for a container healthcheck
    #: (``python -m wz_shared.health``); None: no file (the local stack).
    health_file: Path | None = Field(default=None, validation_alias="WZ_HEALTH_FILE")
    #: A loop that has not gone round for this long is stalled [s]: every node's loop waits
    #: for its input at most 1 s at a time, so 5 s is five missed rounds, not a quiet road.
    stall_after_s: Annotated[float, Field(gt=0.0, validation_alias="WZ_STALL_AFTER_S")] = 5.0
    #: Serve Prometheus metrics (:mod:`wz_shared.metrics`) on this port; None: none.
    metrics_port: Annotated[int, Field(ge=1, le=65535)] | None = Field(
        default=None, validation_alias="WZ_METRICS_PORT"
    )
    #: ... on this address (a container: 0.0.0.0, for the monitoring profile's Prometheus).
    metrics_host: str = Field(default="127.0.0.1", validation_alias="WZ_METRICS_HOST")
