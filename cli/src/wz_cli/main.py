"""The ``wz`` command: run the local stack, watch it, record and replay the bus.

Subcommands: ``router``, ``up``, ``demo``, ``status``, ``tap``, ``alerts``, ``record``, ``replay``, ``recording``, ``calibrate``, and the
services' tools ``dataset``, ``pictures``, ``detect-lidar``, ``detect-camera``, ``eval`` and ``eval-camera`` (``wz <command> --help`` for each).
The command's own logs go to stderr (structured, see :mod:`wz_shared.logs`); stdout carries only
its output (tables, tapped messages, children's lines), so it can be piped.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import logging
import os
import subprocess
import sys
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path

import zenoh

from wz_cli.common import (
    DEFAULT_CONNECT_HELP,
    CliError,
    default_site_id,
    emit,
    open_bus,
    site_file_from_env,
)
from wz_shared.logs import configure_logging
from wz_shared.settings import DEFAULT_ROUTER_ENDPOINT
from wz_shared.signals import stop_on_signals
from wz_shared.site import Site, SiteFileError, load_site

log = logging.getLogger("wz_cli")

#: The site label of commands that work across sites (tap, record, replay).
ANY_SITE = "any-site"

Handler = Callable[[argparse.Namespace], int]


def _positive_float(text: str) -> float:
    value = float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return value


def _non_negative_float(text: str) -> float:
    value = float(text)
    if not value >= 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return value


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {text}")
    return value


def _add_connect(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--connect", action="append", metavar="ENDPOINT", help=DEFAULT_CONNECT_HELP)


def _key_expr_arg(text: str) -> str:
    try:
        zenoh.KeyExpr(text)
    except zenoh.ZError as exc:
        raise argparse.ArgumentTypeError(f"{text!r} is not a valid key expression: {exc}") from exc
    return text


# --- subcommands ----------------------------------------------------------------------------


def cmd_router(args: argparse.Namespace) -> int:
    from wz_cli.router import router_config, run_router

    connect = None
    if args.connect is not None:  # `--connect ''`: connect to nothing
        connect = [
            part.strip() for item in args.connect for part in item.split(",") if part.strip()
        ]
    if args.config is not None:
        log.info("router config %s", args.config)
    stop = stop_on_signals()
    return run_router(router_config(args.listen, args.config, connect, args.tls_dir), stop)


def cmd_credentials(args: argparse.Namespace) -> int:
    from wz_cli import credentials

    folder: Path = args.folder
    if args.action == "make":
        if not args.site:
            raise CliError("wz credentials make needs --site SITE")
        written = credentials.make_site(
            folder, args.site, router_names=args.name or [], days=args.days, uid=args.uid
        )
    elif args.action == "revoke":
        if not args.site:
            raise CliError("wz credentials revoke needs --site SITE")
        for path in credentials.revoke_site(folder, args.site):
            emit(f"revoked {path}")
        written = []
    elif args.action == "regional":
        written = credentials.make_regional(
            folder, names=args.name or [], days=args.days, uid=args.uid
        )
    else:
        written = []
    if not folder.is_dir():
        raise CliError(f"no credentials in {folder}", 1)
    for path in written:
        emit(f"wrote {path}")
    for line in credentials.describe(folder):
        emit(line)
    return 0


def cmd_up(args: argparse.Namespace) -> int:
    from wz_cli.stack import StackOptions, select
    from wz_cli.supervisor import Supervisor

    site_file: Path = args.site or site_file_from_env()
    try:
        site = load_site(site_file)
    except SiteFileError as exc:
        raise CliError(str(exc)) from exc
    configure_logging(service=f"wz-{args.command}", site=site.site_id, level=args.log_level)
    only = [name.strip() for item in args.only or [] for name in item.split(",") if name.strip()]
    try:
        services = select(only or None)
    except ValueError as exc:
        raise CliError(str(exc)) from exc
    missing = [spec for spec in services if not spec.installed()]
    if missing:
        raise CliError(
            "not installed here: "
            + ", ".join(f"{spec.name} (module {spec.module})" for spec in missing)
            + "; run `uv sync` in the workspace root, or leave them out with --only"
        )
    topology = None
    if args.topology is not None:
        from wz_cli.stack import STACK
        from wz_cli.topology import load_topology

        topology = load_topology(args.topology, (spec.name for spec in STACK))
    endpoint: str = args.listen or (topology.router.listen if topology else DEFAULT_ROUTER_ENDPOINT)
    stop = stop_on_signals()
    if args.command == "demo":
        _demo_banner(site.site_id, endpoint)
    # What the services keep across their restarts in this run (the LiDAR background).
    with tempfile.TemporaryDirectory(prefix="wz-up-") as state_dir:
        options = StackOptions(
            router_endpoint=endpoint,
            site_file=site_file,
            realtime_factor=args.realtime_factor,
            seed=args.seed,
            state_dir=Path(state_dir),
            mount_errors=args.mount_errors,
        )
        # `wz status --health-dir` reads each service's health file there (<service>/health).
        log.info("state and health files of this run under %s", state_dir)
        if topology is not None:
            options = topology.configure(options)
        if args.credentials is not None:
            options = dataclasses.replace(
                options, credentials=_site_credentials(args.credentials, site.site_id)
            )
        elif endpoint.startswith("tls/"):
            raise CliError(
                f"the router listens on {endpoint} (mutual TLS): give the site's credentials "
                f"with --credentials DIR (make them with `wz credentials make DIR --site "
                f"{site.site_id}`)"
            )
        return Supervisor(services, options, stop).run()


def _site_credentials(folder: Path, site_id: str) -> Path:
    """``folder/<site>``, checked: a router and every service of the stack have theirs."""
    from wz_cli.stack import ROUTER, STACK

    site_dir = folder / site_id
    missing = [
        name for name in (ROUTER.name, *(s.name for s in STACK)) if not (site_dir / name).is_dir()
    ]
    if missing:
        raise CliError(
            f"{site_dir} has no credentials for {', '.join(missing)}: run "
            f"`wz credentials make {folder} --site {site_id}`"
        )
    return site_dir


def _demo_banner(site_id: str, endpoint: str) -> None:
    connect = "" if endpoint == DEFAULT_ROUTER_ENDPOINT else f" --connect {endpoint}"
    for line in (
        f"wz demo: starting the simulated work zone at site {site_id} (router {endpoint}).",
        "Where to look, in another terminal:",
        f"  wz status{connect}                  services alive, rates, drops",
        f"  wz tap{connect} 'wz/*/truth/**'     the simulated vehicles, live",
        f"  wz tap{connect} 'wz/*/detections/**' the LiDAR detector's vehicles (site frame)",
        f"  wz alerts{connect}                  open alerts, then each alert as it comes",
        "  http://127.0.0.1:8000/              the live page: vehicles and alerts as they happen",
        "  http://127.0.0.1:8000/docs          the gateway's API: trajectories, alerts, WZDx feed",
        f"  wz tap{connect} 'wz/*/raw/**'       the sensors' frames (LiDAR, camera, radar)",
        f"  wz record{connect} demo.mcap        record the bus (opens in Foxglove); "
        "then wz replay demo.mcap",
        "Ctrl-C stops everything.",
    ):
        emit(line)


def cmd_status(args: argparse.Namespace) -> int:
    from wz_cli.stack import select
    from wz_cli.status import health_notes, problems, render_json, render_table, survey

    site = args.site or default_site_id()
    sensors = _site_sensors(site)
    if args.expect is None:
        expected = [spec.name for spec in select(None)]  # what `wz up` runs
    else:
        expected = [name.strip() for name in args.expect.split(",") if name.strip()]
    notes = health_notes(args.health_dir) if args.health_dir is not None else {}
    try:
        bus = open_bus(args.connect, site=site, service="wz-status")
    except CliError as error:
        if not notes:
            raise
        # No bus to ask: what the services' own health files say is all there is.
        emit(str(error))
        for name, note in sorted(notes.items()):
            emit(f"{name}: {note}")
        return 1
    with bus:
        found = survey(bus, site, args.timeout, expected, notes, sensors)
    views = found.services
    if args.json:
        emit(render_json(site, views, found.sensors, found.listened_s))
    else:
        for line in render_table(site, views, found.sensors, found.listened_s):
            emit(line)
    if not expected:
        return 0 if any(view.alive for view in views) else 1
    return 1 if problems(views) else 0


def _site_sensors(site_id: str) -> list[tuple[str, str]]:
    """``(sensor_id, kind)`` of the site file of :func:`site_file_from_env` when it is
    ``site_id``'s (the sensors `wz status` expects a calibration from); else none."""
    try:
        site = load_site(site_file_from_env())
    except SiteFileError:
        return []
    if site.site_id != site_id:
        return []
    return [(sensor.sensor_id, sensor.kind) for sensor in site.sensors]


def cmd_tap(args: argparse.Namespace) -> int:
    import shutil

    from wz_cli.tap import run_tap

    stop = stop_on_signals()
    width = shutil.get_terminal_size((160, 24)).columns
    with open_bus(args.connect, site=ANY_SITE, service="wz-tap") as bus:
        return run_tap(
            bus,
            args.key_expr,
            count=args.count,
            timeout_s=args.timeout,
            full_json=args.json,
            width=width,
            stop=stop,
        )


def cmd_alerts(args: argparse.Namespace) -> int:
    from wz_cli.alerts import run_alerts

    site = args.site or default_site_id()
    stop = stop_on_signals()
    with open_bus(args.connect, site=site, service="wz-alerts") as bus:
        return run_alerts(
            bus,
            active_only=args.active,
            count=args.count,
            timeout_s=args.timeout,
            full_json=args.json,
            stop=stop,
        )


def cmd_record(args: argparse.Namespace) -> int:
    from wz_cli.record import run_record

    site = _foxglove_site(args) if args.foxglove else None  # a bad site file fails first
    stop = stop_on_signals()
    with open_bus(args.connect, site=ANY_SITE, service="wz-record") as bus:
        code = run_record(
            bus,
            args.out,
            args.key_exprs or ["wz/**"],
            duration_s=args.duration,
            max_messages=args.max_messages,
            overwrite=args.overwrite,
            stop=stop,
            connect=args.connect or [],
        )
    if not args.foxglove:
        return code
    from wz_cli.foxglove import run_convert

    # The finished recording, then the same with Foxglove channels in its place.
    converted = args.out.with_name(f".{args.out.name}.foxglove")
    code = run_convert(args.out, converted, site, overwrite=True)
    converted.replace(args.out)
    return code


def _foxglove_site(args: argparse.Namespace) -> Site | None:
    """The site whose geometry a Foxglove conversion draws (None with --no-site)."""
    if args.no_site:
        return None
    path: Path = args.site or site_file_from_env()
    try:
        return load_site(path)
    except SiteFileError as exc:
        raise CliError(
            f"{exc}\n(give the recording's site file with --site, or --no-site)", 1
        ) from exc


def cmd_recording(args: argparse.Namespace) -> int:
    from wz_cli.foxglove import run_convert

    if not args.recording.is_file():
        raise CliError(f"no such recording: {args.recording}", 1)
    return run_convert(args.recording, args.out, _foxglove_site(args), overwrite=args.overwrite)


def _add_foxglove_site(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--site",
        type=Path,
        metavar="SITE.yaml",
        help="the recording's site file: road, work zone, sensor poses and geodetic origin "
        "(default: WZ_SITE_FILE or the default site)",
    )
    parser.add_argument(
        "--no-site",
        action="store_true",
        help="no site geometry: frames, tracks and truth only",
    )


def cmd_replay(args: argparse.Namespace) -> int:
    from wz_cli.replay import run_replay

    if args.recording.is_dir():  # a field log: the devices' own recordings and a log.yaml
        return _replay_field_log(args)
    if not args.recording.is_file():
        raise CliError(f"no such recording: {args.recording}", 1)
    stop = stop_on_signals()
    with open_bus(args.connect, site=ANY_SITE, service="wz-replay") as bus:
        return run_replay(
            bus,
            args.recording,
            rate=None if args.fast else args.rate,
            loop=args.loop,
            wait_subscribers_s=args.wait_subscribers,
            stop=stop,
        )


def _replay_field_log(args: argparse.Namespace) -> int:
    try:
        from wz_drivers.records import FieldDataError
        from wz_drivers.replay import run_field_replay
    except ModuleNotFoundError as exc:  # the drivers are not installed with this CLI
        raise CliError(f"replaying a field log needs the drivers package: {exc}", 1) from exc
    stop = stop_on_signals()
    try:
        with open_bus(args.connect, site=ANY_SITE, service="wz-replay") as bus:
            return run_field_replay(
                bus,
                args.recording,
                rate=None if args.fast else args.rate,
                loop=args.loop,
                wait_subscribers_s=args.wait_subscribers,
                stop=stop,
                emit=emit,
            )
    except FieldDataError as exc:
        raise CliError(str(exc), 1) from exc


def _ground_range(text: str) -> tuple[float, float]:
    try:
        low, high = (float(part) for part in text.split(","))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"expected MIN,MAX in metres, got {text!r}") from exc
    if not 0 <= low < high:
        raise argparse.ArgumentTypeError(f"expected 0 <= MIN < MAX, got {text!r}")
    return low, high


def cmd_calibrate(args: argparse.Namespace) -> int:
    from wz_cli.calibrate import run_command

    if args.frame is None and args.height is not None:
        raise CliError("--height goes with --frame")
    if args.frame is not None:
        for flag, given in (
            ("--write-site", args.write_site is not None),
            ("--pictures", args.pictures is not None),
            ("--no-camera", args.no_camera),
        ):
            if given:
                raise CliError(f"{flag} does not go with --frame (the ground of one frame)")
    if args.pictures is not None and args.recording is None:
        raise CliError("--pictures needs --recording (the frames to draw)")
    if args.include_learning and args.write_site is None:
        raise CliError("--include-learning goes with --write-site")
    site_path: Path = args.site or site_file_from_env()
    site: Site | None = None
    if args.frame is None or args.site is not None:
        try:
            site = load_site(site_path)
        except SiteFileError as exc:
            raise CliError(str(exc)) from exc
    stop = stop_on_signals()
    site_id = site.site_id if site is not None else ANY_SITE
    return run_command(
        args,
        site,
        site_path,
        stop,
        lambda: open_bus(args.connect, site=site_id, service="wz-calibrate"),
    )


#: Commands that run a tool of a service in its own process: the CLI stays light (no SUMO,
#: open3d or OpenCV imports) and works where that service is not installed.
SERVICE_TOOLS = {
    "dataset": ("wz_simulator.dataset", "export camera frames (YOLO) and LiDAR frames (3D boxes)"),
    "pictures": ("wz_simulator.pictures", "write pictures of the simulated sensors with truth"),
    "detect-lidar": (
        "wz_lidar_detector.cli",
        "detect vehicles in PCD/PLY/NPZ LiDAR files, one JSON line per file",
    ),
    "detect-camera": (
        "wz_camera_detector.cli",
        "detect vehicles in image or video files, one JSON line per frame",
    ),
    "eval": (
        "wz_eval.cli",
        "run the pipeline on the simulated work zone and score it against truth (tracks, MOT)",
    ),
    "site": (
        "wz_eval.site_tool",
        "generate a seeded work-zone site file, or draw a site file's plan",
    ),
    "field-log": (
        "wz_eval.field_log",
        "write a field log (Ouster pcap, radar-camera objects, RTK-GPS NMEA) from simulation",
    ),
    "eval-camera": (
        "wz_eval.camera",
        "camera ranging error against simulation truth by distance (Eq. 1-2, calibrated, +radar)",
    ),
}


def cmd_service_tool(args: argparse.Namespace) -> int:
    module = SERVICE_TOOLS[args.command][0]
    package = module.split(".")[0]
    if importlib.util.find_spec(package) is None:
        raise CliError(f"wz {args.command} needs the {package.replace('_', '-')} package", 1)
    return subprocess.call([sys.executable, "-m", module, *args.tool_args])


# --- the parser -----------------------------------------------------------------------------


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="wz",
        description="Work-zone edge sensing: run the local stack, watch it, record and replay.",
        epilog="Exit codes: 0 success, 1 failure (see each command), 2 usage error.",
    )
    parser.add_argument(
        "--log-level",
        default=os.environ.get("WZ_LOG_LEVEL", "INFO"),
        choices=["DEBUG", "INFO", "WARNING", "ERROR"],
        help="level of the command's own logs on stderr (default INFO or WZ_LOG_LEVEL)",
    )
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    router = commands.add_parser(
        "router",
        help="run the local Zenoh router until SIGINT/SIGTERM",
        description="A Zenoh session in router mode (no zenohd needed); multicast scouting off.",
    )
    router.add_argument(
        "--listen",
        action="append",
        metavar="ENDPOINT",
        help=f"endpoint to listen on (repeatable; default {DEFAULT_ROUTER_ENDPOINT}, or the "
        "config file's)",
    )
    router.add_argument(
        "--config", type=Path, help="a zenoh JSON5 config, e.g. deploy/zenoh/router-local.json5"
    )
    router.add_argument(
        "--connect",
        action="append",
        metavar="ENDPOINT",
        help="endpoint of another router to connect to, e.g. the regional router (repeatable or "
        "comma-separated; replaces the config file's; '' for none)",
    )
    router.add_argument(
        "--tls-dir",
        type=Path,
        metavar="DIR",
        help="the router's credentials folder (`wz credentials`): its certificate and the CA in "
        "place of the config's TLS paths, and its access-control.json if any",
    )
    router.set_defaults(handler=cmd_router)

    creds = commands.add_parser(
        "credentials",
        help="make a site's bus certificates (mutual TLS, one per service)",
        description="make: the CA (first time) and every identity of --site (its router with "
        "the site's access control, each service, the operator), each certificate naming the "
        "site; on a site that exists, a new generation (rotation: the old one is refused "
        "once the routers restart); revoke: every identity of --site deleted and refused (a "
        "stolen trailer), the regional access control rewritten without it; regional: the "
        "regional router (--name its host names), the central gateway and its access control "
        "for every site in FOLDER; list: what is there.",
    )
    creds.add_argument("action", choices=["make", "revoke", "regional", "list"])
    creds.add_argument("folder", type=Path, metavar="FOLDER", help="e.g. /etc/wz/credentials")
    creds.add_argument("--site", help="the site id (make, revoke)")
    creds.add_argument(
        "--name",
        action="append",
        metavar="HOST",
        help="another name or address the router is reached by (repeatable)",
    )
    creds.add_argument(
        "--days", type=_positive_int, default=400, help="validity of the certificates (400)"
    )
    creds.add_argument(
        "--uid", type=int, help="owner of the files written (the images' user: 65534)"
    )
    creds.set_defaults(handler=cmd_credentials)

    for name, summary in (
        ("up", "run the local stack: the router, then one process per service"),
        ("demo", "the README's demo: `wz up` on the default site, with where to look"),
    ):
        up = commands.add_parser(
            name,
            help=summary,
            description=summary + ". Children are restarted when they crash (backoff 0.5 s "
            "doubling to 30 s); Ctrl-C or SIGTERM stops them all (exit 0).",
        )
        up.add_argument(
            "--site", type=Path, help="site file (default: WZ_SITE_FILE or the default site)"
        )
        up.add_argument(
            "--only",
            action="append",
            metavar="NAME[,NAME...]",
            help="run only these services (comma-separated or repeated), e.g. simulator",
        )
        up.add_argument(
            "--realtime-factor",
            type=_non_negative_float,
            metavar="X",
            help="simulated seconds per wall-clock second (0 = as fast as possible)",
        )
        up.add_argument("--seed", type=int, help="seed of the simulation")
        up.add_argument(
            "--mount-errors",
            action="store_true",
            help="the simulator renders its sensors as a real mast's: set-up errors, late "
            "clocks, sway and settling drawn from the seed (WZ_SIM_MOUNT_ERRORS; a bump with "
            "WZ_SIM_BUMP_SENSOR, WZ_SIM_BUMP_AT_S, WZ_SIM_BUMP_YAW_DEG); the services keep the "
            "site file's poses",
        )
        up.add_argument(
            "--listen",
            metavar="ENDPOINT",
            help=f"the router's endpoint, tcp/<host>:<port> (default {DEFAULT_ROUTER_ENDPOINT}, "
            "or the topology's)",
        )
        up.add_argument(
            "--topology",
            type=Path,
            metavar="FILE",
            help="which zenoh config the router and each service use, e.g. "
            "deploy/topologies/edge-box.yaml (the edge box of docker-compose.yml, without "
            "containers); default: the router and loopback peers",
        )
        up.add_argument(
            "--credentials",
            type=Path,
            metavar="DIR",
            help="the folder `wz credentials make DIR --site SITE` wrote (DIR itself, not its "
            "<site>/ subfolder: the site's is taken from it): every process joins the bus "
            "with its own certificate; needed by a topology whose router listens on tls/",
        )
        up.set_defaults(handler=cmd_up)

    status = commands.add_parser(
        "status",
        help="which services are alive, with their rates and drops",
        description="Query the services' liveliness tokens under wz/<site>/status/* and listen "
        "to their status messages, and to the sensors' self-calibration under "
        "wz/<site>/calibration/* (a CALIBRATION table: state, learned yaw, pitch and roll "
        "corrections, clock offset, samples, time in that state).",
        epilog="Exit code: 0 when every expected service is up (its loop goes round), 1 when "
        "one is down, silent or stalled; with --expect '': 0 if any service is alive.",
    )
    status.add_argument("--site", help="site id (default: the site of WZ_SITE_FILE / default)")
    status.add_argument(
        "--timeout",
        type=_positive_float,
        default=6.0,
        metavar="S",
        help="how long to wait for status and calibration messages [s] (default 6: the "
        "detectors send each sensor's calibration every 5 s; it returns as soon as every "
        "service and sensor has reported)",
    )
    status.add_argument("--json", action="store_true", help="one JSON object instead of a table")
    status.add_argument(
        "--health-dir",
        type=Path,
        metavar="DIR",
        help="a folder of the services' health files (<service>/health: the state folder "
        "`wz up` logs at start): a service not up shows what its file says, e.g. why it is "
        "still waiting for the bus",
    )
    status.add_argument(
        "--expect",
        metavar="NAME[,NAME...]",
        help="the services that must be up (default: those `wz up` runs; a field box: e.g. "
        "drivers,lidar-detector,camera-detector,fusion-tracker,alert-service,gateway)",
    )
    _add_connect(status)
    status.set_defaults(handler=cmd_status)

    tap = commands.add_parser(
        "tap",
        help="print live messages on a key expression, one line each",
        description="Print `key  kind  summary` per message; invalid payloads as <invalid: ...>.",
        epilog="Exit code: 1 if --timeout ran out before --count messages, else 0.",
    )
    tap.add_argument("key_expr", type=_key_expr_arg, metavar="KEYEXPR", help="e.g. 'wz/*/truth/**'")
    tap.add_argument("--count", type=_positive_int, metavar="N", help="stop after N messages")
    tap.add_argument("--timeout", type=_positive_float, metavar="S", help="stop after S seconds")
    tap.add_argument("--json", action="store_true", help="the full JSON of each message")
    _add_connect(tap)
    tap.set_defaults(handler=cmd_tap)

    alerts = commands.add_parser(
        "alerts",
        help="the open alerts of a site, then each alert event as it comes",
        description="Ask the alert service for the open episodes (wz/<site>/alerts/active), "
        "print them as `open`, then print `stamp  phase  type  severity  track  description` "
        "for each event on wz/<site>/alerts/*.",
        epilog="Exit code: 1 if --active got no answer, or --timeout ran out before --count "
        "events; else 0.",
    )
    alerts.add_argument("--site", help="site id (default: the site of WZ_SITE_FILE / default)")
    alerts.add_argument("--active", action="store_true", help="print the open alerts and stop")
    alerts.add_argument("--count", type=_positive_int, metavar="N", help="stop after N events")
    alerts.add_argument("--timeout", type=_positive_float, metavar="S", help="stop after S s")
    alerts.add_argument("--json", action="store_true", help="the full JSON of each alert")
    _add_connect(alerts)
    alerts.set_defaults(handler=cmd_alerts)

    record = commands.add_parser(
        "record",
        help="record bus payloads into an MCAP file (opens in Foxglove)",
        description="Record raw payloads, one MCAP channel per key, until --duration, "
        "--max-messages or Ctrl-C; then finish the file.",
    )
    record.add_argument("out", type=Path, metavar="OUT.mcap")
    record.add_argument(
        "key_exprs",
        nargs="*",
        type=_key_expr_arg,
        metavar="KEYEXPR",
        help="what to record (default wz/**)",
    )
    record.add_argument("--duration", type=_positive_float, metavar="S", help="stop after S s")
    record.add_argument(
        "--max-messages", type=_positive_int, metavar="N", help="stop after N messages"
    )
    record.add_argument("--overwrite", action="store_true", help="replace OUT.mcap if it exists")
    record.add_argument(
        "--foxglove",
        action="store_true",
        help="when done, add channels in Foxglove's schemas (as `wz recording foxglove`)",
    )
    _add_foxglove_site(record)
    _add_connect(record)
    record.set_defaults(handler=cmd_record)

    recording = commands.add_parser(
        "recording",
        help="work on a recording: `foxglove` adds channels Foxglove can show",
        description="foxglove: copy IN.mcap into OUT.mcap with, beside every recorded channel, "
        "LiDAR point clouds, camera images, tracks, alerts, the road and work zone, sensor "
        "transforms and location fixes in Foxglove's schemas (protobuf). Open OUT.mcap in "
        "Foxglove with deploy/foxglove/layout.json.",
        epilog="Exit code: 3 if IN.mcap was cut short (everything readable was converted), "
        "1 if it cannot be read, else 0.",
    )
    recording.add_argument("action", choices=["foxglove"])
    recording.add_argument("recording", type=Path, metavar="IN.mcap")
    recording.add_argument("out", type=Path, metavar="OUT.mcap")
    recording.add_argument("--overwrite", action="store_true", help="replace OUT.mcap if it exists")
    _add_foxglove_site(recording)
    recording.set_defaults(handler=cmd_recording)

    replay = commands.add_parser(
        "replay",
        help="publish a recording back on the bus",
        description="Publish each recorded payload on its key, at the recorded pace.",
        epilog="Exit code: 3 if the recording was cut short (everything readable was replayed), "
        "1 if it cannot be read, else 0.",
    )
    replay.add_argument(
        "recording",
        type=Path,
        metavar="IN.mcap|LOG_DIR",
        help="a recording of the bus (wz record), or a field log folder (the "
        "devices' recordings and their log.yaml; run the pipeline with "
        "--site LOG_DIR/site.yaml)",
    )
    pace = replay.add_mutually_exclusive_group()
    pace.add_argument(
        "--rate",
        type=_positive_float,
        default=1.0,
        metavar="X",
        help="X times the recorded pace (default 1)",
    )
    pace.add_argument("--fast", action="store_true", help="as fast as possible")
    replay.add_argument("--loop", action="store_true", help="start over at the end, until Ctrl-C")
    replay.add_argument(
        "--wait-subscribers",
        type=_non_negative_float,
        default=2.0,
        metavar="S",
        help="wait at most S seconds in all for subscribers to appear (default 2)",
    )
    _add_connect(replay)
    replay.set_defaults(handler=cmd_replay)

    calibrate = commands.add_parser(
        "calibrate",
        help="the sensors' learned poses and clocks, from a recording, the stack or a frame",
        description="Show what the sensors' self-calibration learns (issue 39; "
        "docs/calibration.md). --recording: run the LiDAR and camera detectors here on a "
        "`wz record` file's raw frames, in the order of their stamps; --minutes: listen to "
        "a running stack's calibration messages; --frame: the ground plane under a LiDAR "
        "from one frame (no lanes needed). Prints each sensor's correction with its "
        "uncertainty (yaw, pitch, roll [deg], x, y, z [m], clock [ms]; 'not observed' where "
        "the data say nothing) and its state; --write-site writes the site file with each "
        "calibrated sensor's pose corrected.",
        epilog="Exit codes: 0 every sensor with data calibrated (--frame: a plane found); 1 "
        "cannot read the input, or it holds no frame of the site's sensors (--frame: no "
        "plane; --minutes: no sensor heard); 2 usage; 3 the recording was cut short (everything readable was used); 4 a "
        "sensor is not calibrated yet (its correction is partial: a longer recording or more "
        "traffic).",
    )
    what = calibrate.add_mutually_exclusive_group(required=True)
    what.add_argument(
        "--recording",
        type=Path,
        metavar="FILE.mcap",
        help="a `wz record` file with the sensors' raw frames (wz/<site>/raw/**)",
    )
    what.add_argument(
        "--minutes",
        type=_positive_float,
        metavar="N",
        help="listen to the running stack's wz/<site>/calibration/* for at most N minutes "
        "(returns once every sensor of the site file is calibrated)",
    )
    what.add_argument(
        "--frame",
        type=Path,
        metavar="FILE",
        help="ground only: fit the ground plane under a LiDAR in one frame (PCD, PLY, NPZ in "
        "the sensor's frame): its height, pitch and roll against the road",
    )
    calibrate.add_argument(
        "--site",
        type=Path,
        metavar="SITE.yaml",
        help="the site file (default: WZ_SITE_FILE or the default site; with --frame: none, "
        "a level sensor, unless given)",
    )
    calibrate.add_argument(
        "--write-site",
        type=Path,
        metavar="OUT.yaml",
        help="write the site file with each calibrated sensor's pose = the site file's + its "
        "learned correction (everything else kept)",
    )
    calibrate.add_argument(
        "--include-learning",
        action="store_true",
        help="--write-site also corrects sensors still learning (their estimate is partial)",
    )
    calibrate.add_argument("--overwrite", action="store_true", help="replace OUT.yaml if it exists")
    calibrate.add_argument(
        "--pictures",
        type=Path,
        metavar="DIR",
        help="with --recording: before/after PNGs: the LiDAR's detections on the lanes, the "
        "LiDAR's vehicles projected into a camera frame (site file's vs learned pose)",
    )
    calibrate.add_argument(
        "--no-camera",
        action="store_true",
        help="with --recording: the LiDAR only (the camera and radar are not run: faster)",
    )
    calibrate.add_argument(
        "--height",
        type=_positive_float,
        metavar="M",
        help="with --frame: the sensor's height above the road to start from (default: "
        "the site file's, or the most common level of the returns below the sensor)",
    )
    calibrate.add_argument(
        "--ground-range",
        type=_ground_range,
        default=(4.0, 40.0),
        metavar="MIN,MAX",
        help="with --frame: returns within this horizontal range are fitted [m] (default 4,40, "
        "as the detector)",
    )
    calibrate.add_argument("--json", action="store_true", help="one JSON object instead of text")
    _add_connect(calibrate)
    calibrate.set_defaults(handler=cmd_calibrate)

    for name, (module, summary) in SERVICE_TOOLS.items():
        tool = commands.add_parser(
            name,
            help=summary,
            description=f"{summary} (runs python -m {module}; see `wz {name} --help`)",
            add_help=False,
        )
        tool.add_argument("tool_args", nargs=argparse.REMAINDER, help="the tool's options")
        tool.set_defaults(handler=cmd_service_tool)
    return parser


def run(argv: Sequence[str] | None = None) -> int:
    """Parse ``argv``, run the command, return its exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] in SERVICE_TOOLS:
        # Everything after the command is the tool's own: argparse would claim its options.
        tool = argparse.Namespace(command=argv[0], tool_args=argv[1:])
        configure_logging(service=f"wz-{argv[0]}", site="-")
        try:
            return cmd_service_tool(tool)
        except CliError as exc:
            log.error("%s", exc)
            return exc.exit_code
    args = build_parser().parse_args(argv)
    configure_logging(service=f"wz-{args.command}", site="-", level=args.log_level)
    handler: Handler = args.handler
    try:
        return handler(args)
    except CliError as exc:
        log.error("%s", exc)
        return exc.exit_code
    except BrokenPipeError:
        # stdout was closed by its reader (`wz tap ... | head`): not an error. Point stdout at
        # /dev/null so the interpreter's final flush does not fail again.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0


def main() -> None:
    sys.exit(run())


if __name__ == "__main__":
    main()
