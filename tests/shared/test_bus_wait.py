"""A service that cannot reach its router says which endpoint and why, in its log and in its
health file, within 5 s; once the router comes, it joins and its health clears.

The probes (:mod:`wz_shared.reach`) are checked against real sockets: a name that does not
resolve, a port nothing listens on, a listening port, and a real TLS server whose certificate
comes from another site's CA (what a trailer given another site's keys sees). The process test
runs the alert service as the containers do (the deployed ``edge-service.json5``: a client
that waits for its router) with no router, then starts a real ``wz router`` on the port.
"""

from __future__ import annotations

import json
import socket
import ssl
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.cli.procs import (
    ROOT,
    free_port,
    port_open,
    running,
    stop_process,
    wait_for,
    wz_argv,
    wz_env,
)
from wz_cli.credentials import make_site
from wz_shared.health import heartbeat_problem, mark_waiting, touch, waiting_reason
from wz_shared.reach import Endpoint, describe_wait, endpoint_problem
from wz_shared.trust import tls_config

EDGE_CONFIG = ROOT / "deploy" / "zenoh" / "edge-service.json5"


@pytest.mark.parametrize(
    ("locator", "parsed"),
    [
        ("tcp/127.0.0.1:7447", Endpoint("tcp", "127.0.0.1", 7447)),
        ("tls/router:7447", Endpoint("tls", "router", 7447)),
        ("tcp/[::1]:7447#iface=lo", Endpoint("tcp", "::1", 7447)),
        ("udp/127.0.0.1:7447", None),
        ("tcp/127.0.0.1", None),
        ("tcp/router:port", None),
    ],
)
def test_locators_parse(locator: str, parsed: Endpoint | None) -> None:
    assert Endpoint.parse(locator) == parsed


def test_a_name_that_does_not_resolve() -> None:
    problem = endpoint_problem("tls/wz-no-such-router.invalid:7447")
    assert problem is not None and problem.startswith("name not resolved")


def test_a_port_nothing_listens_on_and_one_that_listens() -> None:
    port = free_port()
    problem = endpoint_problem(f"tcp/127.0.0.1:{port}")
    assert problem is not None and problem.startswith("connection refused")
    with socket.create_server(("127.0.0.1", 0)) as server:
        assert endpoint_problem(f"tcp/127.0.0.1:{server.getsockname()[1]}") is None
        line = describe_wait([f"tcp/127.0.0.1:{port}"], None)
        assert line.startswith(f"waiting for the bus: tcp/127.0.0.1:{port}: connection refused")


@pytest.fixture
def two_sites(tmp_path: Path) -> tuple[Path, Path]:
    """Credentials of two sites, each from its own CA (two folders)."""
    make_site(tmp_path / "a", "site-a")
    make_site(tmp_path / "b", "site-b")
    return tmp_path / "a" / "site-a", tmp_path / "b" / "site-b"


@pytest.fixture
def tls_router(two_sites: tuple[Path, Path]) -> Iterator[int]:
    """A TLS server with site b's router certificate, asking for a client certificate of
    site b's CA (as the router's mutual TLS does); yields its port."""
    router = two_sites[1] / "router"
    context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    context.load_cert_chain(router / "cert.pem", router / "key.pem")
    context.load_verify_locations(router / "ca.pem")
    context.verify_mode = ssl.CERT_REQUIRED
    server = socket.create_server(("127.0.0.1", 0))
    server.settimeout(0.2)
    done = threading.Event()

    def serve() -> None:
        while not done.is_set():
            try:
                conn, _ = server.accept()
            except TimeoutError:
                continue
            try:
                with context.wrap_socket(conn, server_side=True) as tls:
                    tls.settimeout(1.0)
                    tls.recv(1)
            except (ssl.SSLError, OSError):
                pass

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield int(server.getsockname()[1])
    finally:
        done.set()
        thread.join(2.0)
        server.close()


def test_tls_with_another_sites_ca_is_rejected_and_the_sites_own_is_not(
    two_sites: tuple[Path, Path], tls_router: int
) -> None:
    site_a, site_b = two_sites
    locator = f"tls/localhost:{tls_router}"
    problem = endpoint_problem(locator, tls_config(site_a / "alert-service"))
    assert problem is not None and problem.startswith("TLS rejected"), problem
    assert "certificate" in problem
    assert endpoint_problem(locator, tls_config(site_b / "alert-service")) is None
    unusable = endpoint_problem(locator, tls_config(site_a / "no-such-role"))
    assert unusable is not None and unusable.startswith("TLS credentials unusable")


def test_the_health_file_says_why_until_touched(tmp_path: Path) -> None:
    path = tmp_path / "health"
    mark_waiting(path, "waiting for the bus: tls/router:7447: name not resolved")
    assert waiting_reason(path) == "waiting for the bus: tls/router:7447: name not resolved"
    assert heartbeat_problem(path, 6.0) == "waiting for the bus: tls/router:7447: name not resolved"
    touch(path)
    assert waiting_reason(path) is None
    assert heartbeat_problem(path, 6.0) is None


def _log_lines(path: Path) -> list[dict[str, object]]:
    lines = []
    for raw in path.read_text(encoding="utf-8", errors="replace").splitlines():
        try:
            lines.append(json.loads(raw))
        except json.JSONDecodeError:
            continue
    return lines


def test_a_service_with_no_router_says_why_then_joins_when_it_comes(tmp_path: Path) -> None:
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    health = tmp_path / "state" / "alert-service" / "health"
    log_path = tmp_path / "alert-service.log"
    env = wz_env(
        WZ_BUS_CONFIG_FILE=str(EDGE_CONFIG),  # a client that waits for its router, as deployed
        WZ_BUS_CONNECT_ENDPOINTS=endpoint,
        WZ_HEALTH_FILE=str(health),
        WZ_STATUS_PERIOD_S="0.5",
    )
    with log_path.open("wb") as log:
        node = subprocess.Popen(
            [sys.executable, "-m", "wz_alert_service.node"],
            cwd=ROOT,
            env=env,
            stdout=log,
            stderr=subprocess.STDOUT,
        )
    with running(node):
        started = time.monotonic()

        def said_why() -> bool:
            return any(
                "connection refused" in str(line.get("msg", "")) for line in _log_lines(log_path)
            )

        wait_for(lambda: said_why() or node.poll() is not None, 10.0, "the waiting line")
        said_s = time.monotonic() - started
        assert node.poll() is None, log_path.read_text()
        # From the process's start, Python's imports included (about 1 s here).
        assert said_s < 5.0, f"the reason came {said_s:.1f} s after start"
        messages = [str(line.get("msg", "")) for line in _log_lines(log_path)]
        assert any(f"joining the bus as a client of {endpoint}" in m for m in messages)
        waiting = [m for m in messages if m.startswith("waiting for the bus")]
        assert waiting[0].startswith(f"waiting for the bus: {endpoint}: connection refused")

        # The container's health check says it, and so does `wz status --health-dir`.
        wait_for(lambda: waiting_reason(health) is not None, 10.0, "the health file's reason")
        check = subprocess.run(
            [sys.executable, "-m", "wz_shared.health", str(health)],
            capture_output=True,
            text=True,
            check=False,
        )
        assert check.returncode == 1
        assert "waiting for the bus" in check.stderr and "connection refused" in check.stderr
        status = subprocess.run(
            wz_argv("status", "--connect", endpoint, "--health-dir", str(health.parent.parent)),
            cwd=ROOT,
            env=wz_env(),
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
        assert status.returncode == 1
        assert "alert-service: waiting for the bus" in status.stdout, status.stdout

        # The router comes: the service joins, says so, and its health clears.
        router = subprocess.Popen(
            wz_argv("router", "--listen", endpoint), cwd=ROOT, env=wz_env(), stderr=subprocess.PIPE
        )
        with running(router):
            wait_for(lambda: port_open(port), 20.0, "the router")
            wait_for(
                lambda: any(
                    "joined the bus" in str(line.get("msg", "")) for line in _log_lines(log_path)
                ),
                20.0,
                "the service to join",
            )
            wait_for(lambda: heartbeat_problem(health, 6.0) is None, 10.0, "a healthy file")
            assert node.poll() is None
            assert stop_process(node) == 0
            stop_process(router)
