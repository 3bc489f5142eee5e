"""The local stack: which processes ``wz up`` runs, in start order, and the environment of each.

To add a service, append one :class:`ServiceSpec` to :data:`STACK` (in pipeline order, so a
producer starts before its consumers); ``wz up``, ``wz up --only`` and ``wz demo`` pick it up.

Every child learns where the bus is and which site it serves from the environment:

- ``WZ_BUS_MODE=peer``, ``WZ_BUS_CONNECT_ENDPOINTS=<the router>``,
  ``WZ_BUS_LISTEN_ENDPOINTS=tcp/127.0.0.1:0`` (loopback only, an ephemeral port);
- ``WZ_SITE_FILE`` and ``<prefix>SITE_FILE`` (each service reads its settings with its own env
  prefix, e.g. ``WZ_SIM_``);
- ``WZ_LOG_FORMAT=json``: one JSON log line per event, re-emitted by the supervisor;
- the options of ``wz up`` that a service takes (``--realtime-factor``, ``--seed``,
  ``--mount-errors``) as ``<prefix>REALTIME_FACTOR``, ``<prefix>SEED`` and
  ``<prefix>MOUNT_ERRORS=true``;
- its ``defaults`` (set unless the environment of ``wz up`` sets them: the simulator's
  warm-up), and its ``state_files`` under the run's state folder (see below), then its fixed
  ``env``.

State kept across restarts. A service that learns something at start (the LiDAR detector's
background) names the setting of its file in ``state_files``; with a state folder
(``StackOptions.state_dir``: ``wz up`` makes a temporary one per run and removes it at the
end) it gets ``<state_dir>/<service>/<file>``, so that a restarted child loads what the crashed
one saved instead of learning it again, as the containers and systemd units do with their
volumes. A value set in the environment of ``wz up`` wins.

With a topology (``wz up --topology``, :mod:`wz_cli.topology`) a service gets
``WZ_BUS_CONFIG_FILE=<its zenoh config>`` and ``WZ_BUS_CONNECT_ENDPOINTS=<the router>`` instead:
its mode and listen endpoints are the file's.
"""

from __future__ import annotations

import importlib.util
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path


@dataclass(frozen=True)
class StackOptions:
    """What ``wz up`` passes to every service."""

    router_endpoint: str
    site_file: Path
    realtime_factor: float | None = None
    seed: int | None = None
    #: The router's zenoh config (``wz router --config``); None: the built-in local one.
    router_config: Path | None = None
    #: What the router connects to (``wz router --connect``); None: what its config says.
    router_connect: tuple[str, ...] | None = None
    #: Service name -> the zenoh config its session opens with (a topology); the others are
    #: loopback peers.
    service_configs: Mapping[str, Path] = field(default_factory=dict)
    #: Where services keep their ``state_files`` for this run (None: they keep none).
    state_dir: Path | None = None
    #: The site's credentials folder (``wz credentials``: ``DIR/<site>``): each process gets
    #: its own identity's (``WZ_BUS_TLS_DIR=<credentials>/<name>``), the router
    #: ``--tls-dir <credentials>/router``. None: no TLS (the open loopback stack).
    credentials: Path | None = None
    #: The simulator renders its sensors as a real mast's (``WZ_SIM_MOUNT_ERRORS``:
    #: wz_simulator.sensors.mast); False: the environment of ``wz up`` decides.
    mount_errors: bool = False


@dataclass(frozen=True)
class ServiceSpec:
    """One process of the local stack.

    ``name`` prefixes its output lines and should be the service name it reports its status
    under (``wz/<site>/status/<name>``).
    """

    name: str
    #: Run as ``python -m <module>`` with the supervisor's interpreter.
    module: str
    summary: str
    #: Prefix of the service's settings in the environment (``WZ_SIM_`` ...).
    env_prefix: str
    args: tuple[str, ...] = ()
    #: Which ``wz up`` options the service takes: a subset of {"realtime_factor", "seed",
    #: "mount_errors"}.
    takes: frozenset[str] = frozenset()
    #: Environment set unless the supervisor's own environment sets it.
    defaults: Mapping[str, str] = field(default_factory=dict)
    #: Setting (environment variable) -> file name: a file the service keeps across its
    #: restarts, under ``<state_dir>/<name>/`` (see the module).
    state_files: Mapping[str, str] = field(default_factory=dict)
    #: Fixed extra environment.
    env: Mapping[str, str] = field(default_factory=dict)
    #: Keep a warm standby (imports done) to restart it from (see :mod:`wz_cli.supervisor`).
    standby: bool = False
    #: Its Prometheus metrics' port on loopback (``WZ_METRICS_PORT``); None: it serves none of
    #: its own (the gateway's are on its API, ``/metrics``). deploy/monitoring/ scrapes these.
    metrics_port: int | None = None
    #: Started only when named (``wz up --only drivers,...``): the field sensors' drivers,
    #: which need a manifest of devices (``WZ_DRIVERS_SOURCES``) and replace the simulator.
    optional: bool = False

    def argv(self, python: str = sys.executable) -> list[str]:
        return [python, "-m", self.module, *self.args]

    def installed(self) -> bool:
        """Whether the service's module can be imported by this interpreter."""
        try:
            return importlib.util.find_spec(self.module) is not None
        except ModuleNotFoundError:  # its parent package is missing
            return False

    def child_env(self, base: Mapping[str, str], options: StackOptions) -> dict[str, str]:
        """The environment of this service's process: ``base`` plus the stack's settings."""
        env = dict(base)
        site_file = str(options.site_file.resolve())
        zenoh_config = options.service_configs.get(self.name)
        if zenoh_config is None:
            env.update({"WZ_BUS_MODE": "peer", "WZ_BUS_LISTEN_ENDPOINTS": "tcp/127.0.0.1:0"})
        else:
            # The file says the mode and what to listen on; only the router's address is local.
            env["WZ_BUS_CONFIG_FILE"] = str(zenoh_config)
            env.pop("WZ_BUS_MODE", None)
            env.pop("WZ_BUS_LISTEN_ENDPOINTS", None)
        env.update(
            {
                "WZ_BUS_CONNECT_ENDPOINTS": options.router_endpoint,
                "WZ_BUS_MULTICAST_SCOUTING": "false",
                "WZ_SITE_FILE": site_file,
                f"{self.env_prefix}SITE_FILE": site_file,
                "WZ_LOG_FORMAT": "json",
                "PYTHONUNBUFFERED": "1",
            }
        )
        if options.credentials is not None:
            env["WZ_BUS_TLS_DIR"] = str(options.credentials.resolve() / self.name)
        if options.realtime_factor is not None and "realtime_factor" in self.takes:
            env[f"{self.env_prefix}REALTIME_FACTOR"] = repr(options.realtime_factor)
        if options.seed is not None and "seed" in self.takes:
            env[f"{self.env_prefix}SEED"] = str(options.seed)
        if options.mount_errors and "mount_errors" in self.takes:
            env[f"{self.env_prefix}MOUNT_ERRORS"] = "true"
        for name, value in self.defaults.items():
            env.setdefault(name, value)
        if options.state_dir is not None:
            for name, file_name in self.state_files.items():
                env.setdefault(name, str(options.state_dir.resolve() / self.name / file_name))
            # Its loop's last round, for the supervisor's stall check (wz_cli.supervisor).
            env.setdefault(
                "WZ_HEALTH_FILE", str(options.state_dir.resolve() / self.name / "health")
            )
        if self.metrics_port is not None:
            env["WZ_METRICS_PORT"] = str(self.metrics_port)
        else:
            env.pop("WZ_METRICS_PORT", None)
        env.update(self.env)
        return env


#: The router, started first; ``wz up`` appends ``--listen <endpoint>`` (and ``--config``,
#: ``--connect`` from a topology).
ROUTER = ServiceSpec(
    name="router",
    module="wz_cli.main",
    summary="the local Zenoh router every service connects to",
    env_prefix="WZ_ROUTER_",
    args=("router",),
)

#: The services, in start order.
STACK: tuple[ServiceSpec, ...] = (
    ServiceSpec(
        name="simulator",
        metrics_port=9471,
        module="wz_simulator.node",
        summary="SUMO work zone with LiDAR, camera and radar models; raw frames and truth",
        env_prefix="WZ_SIM_",
        standby=True,
        takes=frozenset({"realtime_factor", "seed", "mount_errors"}),
        # It starts, and restarts after a crash, on a road in steady traffic: a restarted
        # simulation is a new run from 0, and on an empty road the first vehicle would reach
        # the sensors half a minute later.
        defaults={"WZ_SIM_WARMUP_S": "60"},
    ),
    ServiceSpec(
        name="lidar-detector",
        metrics_port=9472,
        module="wz_lidar_detector.node",
        summary="LiDAR frames to vehicle detections (background-model fast path or the paper's)",
        env_prefix="WZ_LIDAR_",
        standby=True,
        # Learned once per run; a restart loads it.
        state_files={"WZ_LIDAR_BACKGROUND_FILE": "background.npz"},
    ),
    ServiceSpec(
        name="camera-detector",
        metrics_port=9473,
        module="wz_camera_detector.node",
        summary="camera frames (+ radar) to vehicle detections (YOLO on ONNX Runtime, radar "
        "fusion)",
        env_prefix="WZ_CAMERA_",
        standby=True,
    ),
    ServiceSpec(
        name="fusion-tracker",
        metrics_port=9474,
        module="wz_fusion_tracker.node",
        summary="every sensor's detections to fused tracks (Kalman, GNN, life cycle)",
        env_prefix="WZ_FUSION_",
        standby=True,
    ),
    ServiceSpec(
        name="alert-service",
        metrics_port=9475,
        module="wz_alert_service.node",
        summary="fused tracks to alerts (speeding, hard braking, late merge, TTC, queue, "
        "intrusion) and the beacon and sign",
        env_prefix="WZ_ALERT_",
        standby=True,
        # Its open episodes, continued or cleared by the next process (not started twice).
        state_files={"WZ_ALERT_STATE_FILE": "open-episodes.json"},
    ),
    ServiceSpec(
        name="drivers",
        metrics_port=9476,
        module="wz_drivers.node",
        summary="the field sensors (Ouster, RTSP camera, radar-camera unit over UDP) or a field "
        "log onto the bus, in place of the simulator (WZ_DRIVERS_SOURCES: their manifest)",
        env_prefix="WZ_DRIVERS_",
        optional=True,
    ),
    ServiceSpec(
        name="device-driver",
        metrics_port=9477,
        module="wz_drivers.device_driver",
        summary="the portable message sign over NTCIP 1203 (SNMP at WZ_SIGN_HOST:WZ_SIGN_PORT) "
        "showing the alert service's message, and the flashing beacon's relay over Modbus TCP "
        "(coil WZ_BEACON_COIL at WZ_BEACON_HOST, if set); `python -m wz_drivers.sign_sim` and "
        "`python -m wz_drivers.beacon_sim` are a bench sign and relay module",
        env_prefix="WZ_SIGN_",
        optional=True,
    ),
    ServiceSpec(
        name="gateway",
        module="wz_gateway.node",
        summary="trajectories, alerts and devices into SQLite; REST API and WZDx device feed on "
        "http://127.0.0.1:8000 (dev mode: reads need no key, an admin key is logged)",
        env_prefix="WZ_GATEWAY_",
        standby=True,
        # The local stack is a development machine: loopback only, reads open.
        env={"WZ_GATEWAY_DEV_MODE": "true"},
    ),
)


def select(only: Sequence[str] | None, stack: Sequence[ServiceSpec] = STACK) -> list[ServiceSpec]:
    """The services named in ``only`` (when None: all but the optional ones), in stack order.

    Raises
    ------
    ValueError
        For a name that is not in the stack, listing the names that are.
    """
    if not only:
        return [spec for spec in stack if not spec.optional]
    known = {spec.name for spec in stack}
    unknown = [name for name in only if name not in known]
    if unknown:
        raise ValueError(
            f"no service named {', '.join(unknown)} in the stack; known: {', '.join(sorted(known))}"
        )
    return [spec for spec in stack if spec.name in only]
