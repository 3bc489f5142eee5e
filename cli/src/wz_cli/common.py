"""What the `wz` subcommands share: endpoints, bus sessions, terminal output."""

from __future__ import annotations

import logging
import os
import re
import socket
import sys
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import zenoh

from wz_shared.bus import Bus
from wz_shared.settings import DEFAULT_ROUTER_ENDPOINT, BusSettings
from wz_shared.site import DEFAULT_SITE_PATH, SiteFileError, load_site

log = logging.getLogger(__name__)

_TCP_ENDPOINT = re.compile(r"^(?:tcp|tls)/(?P<host>\[[^\]]+\]|[^:/\[\]]+):(?P<port>\d{1,5})$")


class CliError(Exception):
    """A problem the user can fix (bad argument, unreachable router, unreadable file).

    ``main`` logs its message and exits with ``exit_code``; no traceback.
    """

    def __init__(self, message: str, exit_code: int = 2) -> None:
        super().__init__(message)
        self.exit_code = exit_code


# --- endpoints ------------------------------------------------------------------------------


def tcp_address(endpoint: str) -> tuple[str, int] | None:
    """``"tcp/127.0.0.1:7447"`` (or ``tls/...``, TLS over TCP) -> ``("127.0.0.1", 7447)``;
    None for other protocols.

    Zenoh endpoint metadata after ``#`` or ``?`` is ignored.
    """
    bare = re.split(r"[#?]", endpoint.strip(), maxsplit=1)[0]
    match = _TCP_ENDPOINT.match(bare)
    if match is None:
        return None
    host = match["host"].strip("[]")
    port = int(match["port"])
    if not 0 < port < 65536:
        return None
    return host, port


def connect_host(host: str) -> str:
    """The address to connect to for a listen host (a wildcard listen means this machine)."""
    return {"0.0.0.0": "127.0.0.1", "::": "::1"}.get(host, host)


def port_accepts(host: str, port: int, timeout_s: float = 0.2) -> bool:
    """Whether a TCP connection to ``host:port`` is accepted now."""
    try:
        with socket.create_connection((connect_host(host), port), timeout=timeout_s):
            return True
    except OSError:
        return False


def wait_for_port(
    host: str,
    port: int,
    timeout_s: float,
    *,
    still_worth_waiting: Callable[[], bool] = lambda: True,
) -> bool:
    """Poll until ``host:port`` accepts connections; False on timeout or when told to give up."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if port_accepts(host, port):
            return True
        if not still_worth_waiting():
            return False
        time.sleep(0.05)
    return False


# --- the bus --------------------------------------------------------------------------------


def bus_settings(connect: Sequence[str] | None) -> BusSettings:
    """Bus settings of a CLI session: a Zenoh client of the router.

    The endpoints are ``--connect`` if given, else ``WZ_BUS_CONNECT_ENDPOINTS``, else the local
    router ``tcp/127.0.0.1:7447``. A client (not a peer, as the services are) because a
    short-lived observer should ask the router, which knows every service: a fresh peer learns
    the tokens and subscriptions of other peers only once its own links to them are up, so a
    liveliness query made right after it opens can miss services that are alive.
    """
    settings = BusSettings()
    update: dict[str, object] = {"mode": "client", "listen_endpoints": []}
    if connect:
        update["connect_endpoints"] = [
            part.strip() for item in connect for part in item.split(",") if part.strip()
        ]
    return settings.model_copy(update=update)


def open_bus(connect: Sequence[str] | None, *, site: str, service: str) -> Bus:
    """Open a bus session for a CLI command (``service`` names it in logs only).

    Raises
    ------
    CliError
        When no endpoint can be reached, with what to check.
    """
    settings = bus_settings(connect)
    try:
        return Bus.open(settings, site=site, service=service)
    except zenoh.ZError as exc:
        tls = any(e.startswith("tls/") for e in settings.connect_endpoints)
        hint = (
            " A tls/ router takes a certificate of the site's CA: set WZ_BUS_TLS_DIR to your "
            "credentials folder (`wz credentials make`: <site>/operator)."
            if tls
            else ""
        )
        raise CliError(
            f"cannot reach the bus at {', '.join(settings.connect_endpoints)}: is the stack "
            "running (`wz up`)? Point at another router with --connect or "
            f"WZ_BUS_CONNECT_ENDPOINTS ({exc}).{hint}",
            1,
        ) from exc


def site_file_from_env() -> Path:
    """The site file the environment names (``WZ_SITE_FILE``), else the default site."""
    value = os.environ.get("WZ_SITE_FILE")
    return Path(value) if value else DEFAULT_SITE_PATH


def default_site_id() -> str:
    """The site id of :func:`site_file_from_env`."""
    path = site_file_from_env()
    try:
        return load_site(path).site_id
    except SiteFileError as exc:
        raise CliError(f"{exc}\n(give the site id with --site)") from exc


DEFAULT_CONNECT_HELP = (
    "router endpoint to connect to (repeatable, or comma-separated); default: "
    f"WZ_BUS_CONNECT_ENDPOINTS or {DEFAULT_ROUTER_ENDPOINT}"
)


# --- output ---------------------------------------------------------------------------------

_output_lock = threading.Lock()


def emit(line: str) -> None:
    """Write one line of the command's own output to stdout, flushed (pipes see it at once)."""
    with _output_lock:
        sys.stdout.write(line + "\n")
        sys.stdout.flush()


def format_duration(seconds: float) -> str:
    """``4.2s``, ``3m05s``, ``2h03m``."""
    if seconds < 60:
        return f"{seconds:.1f}s"
    minutes, secs = divmod(int(seconds), 60)
    if minutes < 60:
        return f"{minutes}m{secs:02d}s"
    hours, minutes = divmod(minutes, 60)
    return f"{hours}h{minutes:02d}m"


def format_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    """Left-aligned columns separated by two spaces."""
    widths = [len(h) for h in header]
    for row in rows:
        widths = [max(w, len(cell)) for w, cell in zip(widths, row, strict=True)]
    return [
        "  ".join(cell.ljust(w) for cell, w in zip(row, widths, strict=True)).rstrip()
        for row in (header, *rows)
    ]
