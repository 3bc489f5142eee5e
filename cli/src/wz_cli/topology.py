"""``wz up --topology FILE``: the zenoh config of each process of the local stack.

A topology file (``deploy/topologies/edge-box.yaml``) names the config the router starts from
and the config each service's session opens with, the same files a deployment uses, so the
local stack runs the deployed topology (services as clients of one router) without containers::

    router:
      zenoh_config: ../zenoh/trailer-router.json5
      listen: tcp/127.0.0.1:7447   # replaces the config's listen endpoints
      connect: []                  # replaces its connect endpoints (no regional router here)
    services:
      simulator: ../zenoh/edge-service.json5
      ...

Paths are relative to the topology file. Each service's config names the router by its
deployed address (``tcp/router:7447``); ``wz up`` points the service at its local router
instead (``WZ_BUS_CONNECT_ENDPOINTS``) and lets the file decide everything else.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from pathlib import Path

import yaml
import zenoh
from pydantic import BaseModel, ConfigDict, ValidationError

from wz_cli.common import CliError
from wz_cli.stack import StackOptions
from wz_shared.settings import DEFAULT_ROUTER_ENDPOINT


class RouterEntry(BaseModel):
    """The router of a topology."""

    model_config = ConfigDict(extra="forbid")

    zenoh_config: Path
    #: Where the router listens locally (``wz up --listen`` wins over it).
    listen: str = DEFAULT_ROUTER_ENDPOINT
    #: The routers it connects to; None keeps the config's, [] connects to none.
    connect: list[str] | None = None


class Topology(BaseModel):
    """Which zenoh config each process uses; paths absolute once loaded."""

    model_config = ConfigDict(extra="forbid")

    router: RouterEntry
    #: Service name (as in :data:`wz_cli.stack.STACK`) -> its zenoh config.
    services: dict[str, Path]

    def configure(self, options: StackOptions) -> StackOptions:
        """``options`` with this topology's router and service configs."""
        return dataclasses.replace(
            options,
            router_config=self.router.zenoh_config,
            router_connect=None if self.router.connect is None else tuple(self.router.connect),
            service_configs=dict(self.services),
        )


def load_topology(path: Path, service_names: Iterable[str]) -> Topology:
    """Read and check a topology file.

    Every service of ``service_names`` must be named, and no other; every zenoh config must
    exist and be one the zenoh package accepts.

    Raises
    ------
    CliError
        With the file and what is wrong in it (exit code 2: fix the file).
    """
    try:
        raw = yaml.safe_load(path.read_text(encoding="utf-8"))
        topology = Topology.model_validate(raw)
    except OSError as exc:
        raise CliError(f"cannot read topology {path}: {exc}") from exc
    except (yaml.YAMLError, ValidationError) as exc:
        raise CliError(f"topology {path} is not valid: {exc}") from exc

    expected = set(service_names)
    named = set(topology.services)
    if named != expected:
        problems = []
        if expected - named:
            problems.append(f"missing {', '.join(sorted(expected - named))}")
        if named - expected:
            problems.append(f"unknown {', '.join(sorted(named - expected))}")
        raise CliError(
            f"topology {path} must name every service of the stack once: {'; '.join(problems)}"
        )

    base = path.resolve().parent
    topology.router.zenoh_config = _checked_config(base / topology.router.zenoh_config, path)
    topology.services = {
        name: _checked_config(base / config, path) for name, config in topology.services.items()
    }
    return topology


def _checked_config(config: Path, topology_file: Path) -> Path:
    config = config.resolve()
    if not config.is_file():
        raise CliError(f"topology {topology_file} names {config}, which does not exist")
    try:
        zenoh.Config.from_file(str(config))
    except zenoh.ZError as exc:
        raise CliError(f"topology {topology_file}: {config} is not a zenoh config: {exc}") from exc
    return config
