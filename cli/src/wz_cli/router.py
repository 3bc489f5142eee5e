"""``wz router``: the local Zenoh router, a Python session in router mode.

No zenohd binary is needed: every service of the local stack connects to this process. It keeps
no storage; it only routes. Multicast scouting is always off (endpoints are explicit), so
nothing on the network finds it unless a listen endpoint on a public interface says so.
"""

from __future__ import annotations

import json
import logging
import os
import sys
import threading
from collections.abc import Sequence
from pathlib import Path

import zenoh

from wz_cli.common import CliError
from wz_shared.settings import DEFAULT_ROUTER_ENDPOINT
from wz_shared.trust import ACL_FILE, CERT_FILE, tls_config

log = logging.getLogger(__name__)

#: How long a stopping router waits for its session to close. Closing a session with TLS links
#: to other routers normally takes well under a second, but on a loaded box it was seen to hang
#: past a container's 10 s stop grace; a router keeps no state, so it exits without waiting.
CLOSE_TIMEOUT_S = 5.0

#: Config of the local router, shipped as a file too.
LOCAL_ROUTER_CONFIG = (
    Path(__file__).resolve().parents[3] / "deploy" / "zenoh" / "router-local.json5"
)


def router_config(
    listen: Sequence[str] | None,
    config_file: Path | None,
    connect: Sequence[str] | None = None,
    tls_dir: Path | None = None,
) -> zenoh.Config:
    """The router's Zenoh config: ``config_file`` if given, else the built-in local one.

    ``listen`` replaces the listen endpoints of either, ``connect`` the endpoints it connects
    to (an empty list: none, e.g. a trailer router without its regional router); None keeps
    them. ``tls_dir``: the router's credentials folder (``wz credentials``) in place of the
    config's TLS paths, and its ``access-control.json``, when it has one, in place of the
    config's access control (the regional router's, which names the sites). Multicast
    scouting is forced off.
    """
    if config_file is not None:
        try:
            config = zenoh.Config.from_file(str(config_file))
        except zenoh.ZError as exc:  # unreadable, or not a zenoh config
            raise CliError(f"cannot use zenoh config {config_file}: {exc}") from exc
    else:
        config = zenoh.Config()
        config.insert_json5("listen/endpoints", json.dumps([DEFAULT_ROUTER_ENDPOINT]))
        config.insert_json5("connect/endpoints", json.dumps([]))
    config.insert_json5("mode", json.dumps("router"))
    if listen:
        try:
            config.insert_json5("listen/endpoints", json.dumps(list(listen)))
        except zenoh.ZError as exc:
            raise CliError(f"bad --listen endpoint in {', '.join(listen)}: {exc}") from exc
    if connect is not None:
        try:
            config.insert_json5("connect/endpoints", json.dumps(list(connect)))
        except zenoh.ZError as exc:
            raise CliError(f"bad --connect endpoint in {', '.join(connect)}: {exc}") from exc
    if tls_dir is not None:
        if not (tls_dir / CERT_FILE).is_file():
            raise CliError(f"{tls_dir} holds no {CERT_FILE}: make it with `wz credentials`")
        config.insert_json5("transport/link/tls", json.dumps(tls_config(tls_dir)))
        acl = tls_dir / ACL_FILE
        if not acl.is_file():
            log.warning(
                "%s holds no %s: the config's own access control applies (a trailer "
                "router's denies everything: make the site's with `wz credentials make`)",
                tls_dir,
                ACL_FILE,
            )
        else:
            try:
                config.insert_json5("access_control", acl.read_text())
            except zenoh.ZError as exc:
                raise CliError(f"cannot use the access control in {acl}: {exc}") from exc
    config.insert_json5("scouting/multicast/enabled", json.dumps(False))
    return config


def run_router(config: zenoh.Config, stop: threading.Event) -> int:
    """Route until ``stop`` is set; return the exit code."""
    listen = json.loads(config.get_json("listen/endpoints"))
    try:
        session = zenoh.open(config)
    except zenoh.ZError as exc:  # e.g. the port is taken
        raise CliError(f"cannot start the router on {', '.join(listen)}: {exc}", 1) from exc
    try:
        connect = json.loads(config.get_json("connect/endpoints"))
        log.info(
            "router %s listening on %s, connecting to %s",
            session.zid(),
            ", ".join(listen),
            ", ".join(connect) or "nothing",
        )
        stop.wait()
    finally:
        closer = threading.Thread(target=session.close, name="router-close", daemon=True)
        closer.start()
        closer.join(CLOSE_TIMEOUT_S)
        if closer.is_alive():
            log.warning(
                "the router's session did not close within %.0f s; exiting without waiting "
                "(a router keeps no state)",
                CLOSE_TIMEOUT_S,
            )
            logging.shutdown()
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(0)
    log.info("router stopped")
    return 0
