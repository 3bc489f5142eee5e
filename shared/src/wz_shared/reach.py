"""Why a process cannot join the bus: each router endpoint probed, the reason in words.

A Zenoh client told to wait for its router (``connect/timeout_ms: {client: -1}``, as every
deployed service is: ``deploy/zenoh/edge-service.json5``) retries in silence. A technician
then sees a container "unhealthy" and an empty log. :func:`open_session` opens the session in
a worker thread and, while it waits, probes each ``connect/endpoints`` entry itself, the way
the session would reach it:

1. the host name resolved (``name not resolved``: no DNS on the container network, a typo);
2. a TCP connection (``connection refused``: nothing listens, the router is down;
   ``timed out``: a firewall, a cut cable);
3. for ``tls/``, a TLS handshake with the session's own CA, certificate and key, checking the
   router's name as Zenoh does (``TLS rejected: ...``: another site's CA, an expired
   certificate, a certificate that does not name the host);

and says what it found: logged at start (which endpoints it tries), then every
``report_every_s`` while it waits, and handed to ``on_wait`` (the node writes it into its
health file, so the container's health check and ``wz status --health-dir`` show it).
An endpoint that passes all three while the session still waits is reported as reachable:
the router took the connection but not the session (its access rules, or its own state).
"""

from __future__ import annotations

import contextlib
import json
import logging
import socket
import ssl
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import zenoh

log = logging.getLogger(__name__)

#: How long one probe may wait for a name, a connection or a handshake [s].
PROBE_TIMEOUT_S = 2.0
#: First report after this long without a session [s]: a router that is up answers in well
#: under a second, so a wait past this is worth a line (and within the 5 s a technician waits).
FIRST_REPORT_AFTER_S = 1.0
#: Later reports, while the wait goes on [s].
REPORT_EVERY_S = 5.0


class BusWaitAbortedError(RuntimeError):
    """The process was told to stop while it was still waiting for the bus."""


@dataclass(frozen=True)
class Endpoint:
    """A Zenoh locator split: ``protocol`` (tcp, tls, ...), ``host`` and ``port``."""

    protocol: str
    host: str
    port: int

    @classmethod
    def parse(cls, locator: str) -> Endpoint | None:
        """``tcp/host:port``, ``tls/[::1]:port`` (metadata after ``?`` or ``#`` dropped);
        None for what has no host and port to probe (``udp/``, ``unixsock-stream/``...)."""
        protocol, _, address = locator.partition("/")
        address = address.split("?", 1)[0].split("#", 1)[0]
        if protocol not in ("tcp", "tls", "quic") or ":" not in address:
            return None
        host, _, port = address.rpartition(":")
        host = host.removeprefix("[").removesuffix("]")
        if not host or not port.isdigit():
            return None
        return cls(protocol, host, int(port))


def _tls_context(tls: dict[str, Any], verify_name: bool) -> ssl.SSLContext:
    """The client side of the session's TLS block (its CA, its own certificate for mTLS)."""
    context = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
    context.check_hostname = verify_name
    context.verify_mode = ssl.CERT_REQUIRED
    ca = tls.get("root_ca_certificate")
    if ca:
        context.load_verify_locations(cafile=ca)
    else:
        context.load_default_certs()
    cert, key = tls.get("connect_certificate"), tls.get("connect_private_key")
    if cert and key:
        context.load_cert_chain(cert, key)
    return context


def endpoint_problem(
    locator: str, tls: dict[str, Any] | None = None, timeout_s: float = PROBE_TIMEOUT_S
) -> str | None:
    """Why ``locator`` cannot be reached now, in words; None when it can.

    ``tls``: the session's ``transport/link/tls`` block (paths to its CA, certificate and
    key; ``verify_name_on_connect``), used for a ``tls/`` locator.
    """
    endpoint = Endpoint.parse(locator)
    if endpoint is None:
        return None  # nothing this probe knows how to try
    try:
        addresses = socket.getaddrinfo(
            endpoint.host, endpoint.port, type=socket.SOCK_STREAM, proto=socket.IPPROTO_TCP
        )
    except socket.gaierror as error:
        return f"name not resolved ({endpoint.host}: {error.strerror})"
    if endpoint.protocol == "quic":
        return None  # UDP: no connection to try without speaking QUIC
    family, kind, proto, _, address = addresses[0]
    ip = address[0] if isinstance(address[0], str) else endpoint.host
    where = f"{ip}:{endpoint.port}"
    with socket.socket(family, kind, proto) as sock:
        sock.settimeout(timeout_s)
        try:
            sock.connect(address)
        except ConnectionRefusedError:
            return f"connection refused ({where}: nothing listens there)"
        except TimeoutError:
            return f"timed out after {timeout_s:g} s ({where})"
        except OSError as error:
            return f"cannot connect ({where}: {error.strerror or error})"
        if endpoint.protocol != "tls":
            return None
        tls = tls or {}
        try:
            context = _tls_context(tls, bool(tls.get("verify_name_on_connect", True)))
        except (OSError, ssl.SSLError) as error:
            return f"TLS credentials unusable ({error})"
        try:
            with context.wrap_socket(sock, server_hostname=endpoint.host) as wrapped:
                # TLS 1.3 sends the server's verdict on our certificate after the handshake:
                # a short read shows a refused client certificate as an alert.
                wrapped.settimeout(0.3)
                with contextlib.suppress(TimeoutError, ssl.SSLWantReadError):
                    wrapped.recv(1)
        except ssl.SSLCertVerificationError as error:
            return f"TLS rejected: the router's certificate: {error.verify_message}"
        except ssl.SSLError as error:
            return f"TLS rejected ({error.reason or error})"
        except (OSError, TimeoutError) as error:
            return f"TLS handshake failed ({error})"
    return None


def session_endpoints(config: zenoh.Config) -> tuple[str, list[str], dict[str, Any] | None]:
    """The session's mode, its connect endpoints and its TLS block, read off ``config``."""
    mode = json.loads(config.get_json("mode") or '"peer"')
    raw = json.loads(config.get_json("connect/endpoints") or "[]")
    if isinstance(raw, dict):  # per mode: {router: [...], peer: [...], client: [...]}
        raw = raw.get(mode, [])
    tls = json.loads(config.get_json("transport/link/tls") or "null")
    return mode, [str(e) for e in raw], tls if isinstance(tls, dict) else None


def describe_wait(endpoints: list[str], tls: dict[str, Any] | None) -> str:
    """One line: each endpoint and why it cannot be reached (or that it can)."""
    if not endpoints:
        return "waiting for the bus: no router endpoint configured (connect/endpoints is empty)"
    parts = []
    for locator in endpoints:
        problem = endpoint_problem(locator, tls)
        parts.append(
            f"{locator}: "
            + (problem or "reachable, but the router has not accepted the session yet")
        )
    return "waiting for the bus: " + "; ".join(parts)


def open_session(
    config: zenoh.Config,
    *,
    on_wait: Callable[[str], None] | None = None,
    stop: threading.Event | None = None,
    first_report_after_s: float = FIRST_REPORT_AFTER_S,
    report_every_s: float = REPORT_EVERY_S,
) -> zenoh.Session:
    """``zenoh.open(config)``, saying why while it waits (see the module).

    Raises
    ------
    zenoh.ZError
        What ``zenoh.open`` raised (a client that gives up: ``timeout_ms`` not -1).
    BusWaitAbortedError
        ``stop`` was set while waiting (SIGTERM during start-up).
    """
    mode, endpoints, tls = session_endpoints(config)
    outcome: dict[str, Any] = {}
    done = threading.Event()

    def run() -> None:
        try:
            outcome["session"] = zenoh.open(config)
        except BaseException as error:  # handed to the caller's thread
            outcome["error"] = error
        finally:
            done.set()

    log.info("joining the bus as a %s of %s", mode, ", ".join(endpoints) or "no router")
    worker = threading.Thread(target=run, name="zenoh-open", daemon=True)
    started = time.monotonic()
    worker.start()
    next_report = started + first_report_after_s
    while not done.wait(0.2):
        if stop is not None and stop.is_set():
            raise BusWaitAbortedError("stopped while waiting for the bus")
        if time.monotonic() < next_report:
            continue
        reason = describe_wait(endpoints, tls)
        if done.is_set():
            break  # joined while probing: nothing to report
        log.warning("%s (%.0f s so far)", reason, time.monotonic() - started)
        if on_wait is not None:
            on_wait(reason)
        next_report = time.monotonic() + report_every_s
    if "error" in outcome:
        raise outcome["error"]
    session: zenoh.Session = outcome["session"]
    if time.monotonic() - started > first_report_after_s:
        log.info("joined the bus after %.1f s", time.monotonic() - started)
    return session
