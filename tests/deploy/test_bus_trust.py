"""The deployed bus refuses forged messages at the router: one test per role, on network hosts.

Two hosts (network namespaces) on one cable, as the trailer's box and a device plugged into
its switch:

- the *box* runs the trailer's router from the deployed config as shipped
  (``deploy/zenoh/trailer-router.json5``: mutual TLS, access control by role) with the site's
  credentials (``wz credentials make``), and the authorised pipeline downstream of the
  tracker: a stand-in tracker (:mod:`tests.deploy.track_source`, with the tracker's
  certificate), the real alert service and the real gateway, each with its own certificate
  and the deployed service config (``edge-service.json5``);
- the *yard* runs :mod:`tests.deploy.bus_probe`, once per role's certificate (and with none,
  and with one from another CA): it puts a forged alert, detection batch, track batch,
  devices' state, LiDAR frame and the alert service's status, and answers the open-alerts
  query with a forged reply.

The box also runs the regional router (``regional-router.json5``, on another port), which the
trailer's router links up to, as a centre does over the cellular link.

This test's own sessions (over a third cable) are raw subscribers of every key of the site:
one with the site operator's certificate at the trailer's router, one with the central
gateway's at the regional router; what they see is what the routers let through, before any
consumer's own checks. Each role must get through exactly what its row of the issue's table
says, nothing more; a session without the CA's certificate must not connect at all; every
identity of *another site from the same CA* (its services', its operator's, its trailer
router's) connects but gets nothing of this site's through either router (a key taken from
one trailer on a roadside forges nothing at another); neither does this site's own previous
generation of certificates, rotated away by making the site again; and the authorised pipeline, running
all along, stores the alert service's alerts in the gateway and reaches the centre.
"""

from __future__ import annotations

import os
import shutil
import sqlite3
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest
import zenoh

from tests.deploy.bus_probe import KINDS, PUT_S
from tests.deploy.netns import Host, Network, require_namespaces
from wz_cli.credentials import make_regional, make_site
from wz_shared.bus import zenoh_config
from wz_shared.settings import BusSettings
from wz_shared.site import load_site

ROOT = Path(__file__).resolve().parents[2]
ZENOH = ROOT / "deploy" / "zenoh"
SITE_FILE = ROOT / "deploy" / "sites" / "us75-lincoln.yaml"
SITE = load_site(SITE_FILE).site_id
#: Another site's credentials from the same CA.
OTHER_SITE = "i80-omaha"
PORT = 7447
#: The regional router's port, on the box's host too.
REGIONAL_PORT = 7448

#: What each role's forged messages may get through the router: the issue's table (only the
#: alert service alerts, only detectors detections, only the tracker tracks, the gateway only
#: reads), plus raw data and the upstream point sensors' readings from the sensors' side, and
#: each service its own status only.
ALLOWED: dict[str, set[str]] = {
    "simulator": {"raw", "points", "config"},
    "drivers": {"raw", "points", "detection"},
    "lidar-detector": {"detection"},
    "camera-detector": {"detection"},
    "fusion-tracker": {"tracks"},
    "alert-service": {"alert", "devices", "status", "active reply"},
    "gateway": set(),
    "operator": set(),
}


@dataclass
class Box:
    network: Network
    box: Host
    yard: Host
    router_endpoint: str  # as the yard reaches it
    regional_endpoint: str  # as the yard reaches it
    credentials: Path
    stranger: Path  # another CA's credentials for the same site
    revoked: Path  # the site's credentials of the generation before (rotated away)
    data_dir: Path
    seen: list[tuple[str, bytes]] = field(default_factory=list)
    #: What the central gateway's session at the regional router received.
    central_seen: list[tuple[str, bytes]] = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def forged_seen(self, at: str = "trailer") -> set[str]:
        with self.lock:
            samples = self.seen if at == "trailer" else self.central_seen
            return {payload.decode() for _, payload in samples if payload.decode() in KINDS}


def _env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("WZ_")}
    env.update({"WZ_LOG_FORMAT": "json", "PYTHONUNBUFFERED": "1", **extra})
    return env


def _wait(probe: object, what: str, timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if probe():  # type: ignore[operator]
            return
        time.sleep(0.2)
    pytest.fail(f"timed out after {timeout_s:.0f} s waiting for {what}")


@pytest.fixture(scope="module")
def box(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Box]:
    require_namespaces()
    tmp = tmp_path_factory.mktemp("trust")
    network = Network(f"wzt{os.getpid() % 10000}")
    processes: list[subprocess.Popen[bytes]] = []
    stop_file = tmp / "stop"
    try:
        box_host, yard = network.host("box"), network.host("yard")
        network.cable(box_host, yard)
        watch_address = network.root_cable(box_host)
        credentials, stranger = tmp / "credentials", tmp / "stranger"
        names = [*box_host.addresses, watch_address]
        make_site(credentials, SITE, router_names=names)
        # The site's first generation, kept as a thief would have it, then rotated away.
        revoked = tmp / "revoked"
        shutil.copytree(credentials / SITE, revoked)
        make_site(credentials, SITE, router_names=names)
        make_site(credentials, OTHER_SITE, router_names=names)
        make_regional(credentials, names=[*names, "127.0.0.1"])
        make_site(stranger, SITE, router_names=names)
        site = credentials / SITE
        logs = tmp / "logs"
        logs.mkdir()

        def start(name: str, argv: list[str], **env: str) -> None:
            log = logs / f"{name}.log"
            processes.append(box_host.popen(argv, env=_env(**env), cwd=ROOT, log=log))

        start(
            "regional-router",
            [sys.executable, "-m", "wz_cli.main", "router", "--config",
             str(ZENOH / "regional-router.json5"), "--tls-dir",
             str(credentials / "regional" / "router"), "--listen",
             f"tls/0.0.0.0:{REGIONAL_PORT}"],
        )  # fmt: skip
        start(
            "router",
            [sys.executable, "-m", "wz_cli.main", "router", "--config",
             str(ZENOH / "trailer-router.json5"), "--tls-dir", str(site / "router"),
             "--connect", f"tls/127.0.0.1:{REGIONAL_PORT}"],
        )  # fmt: skip
        service = {
            "WZ_BUS_CONFIG_FILE": str(ZENOH / "edge-service.json5"),
            "WZ_BUS_CONNECT_ENDPOINTS": f"tls/127.0.0.1:{PORT}",
            "WZ_SITE_FILE": str(SITE_FILE),
        }
        data_dir = tmp / "gateway"
        start(
            "gateway",
            [sys.executable, "-m", "wz_gateway.node"],
            **service,
            WZ_BUS_TLS_DIR=str(site / "gateway"),
            WZ_GATEWAY_DEV_MODE="true",
            WZ_GATEWAY_DATA_DIR=str(data_dir),
        )
        start(
            "alert-service",
            [sys.executable, "-m", "wz_alert_service.node"],
            **service,
            WZ_BUS_TLS_DIR=str(site / "alert-service"),
        )
        start(
            "tracks",
            [sys.executable, "-m", "tests.deploy.track_source", str(SITE_FILE), str(stop_file)],
            **service,
            WZ_BUS_TLS_DIR=str(site / "fusion-tracker"),
        )
        result = Box(
            network, box_host, yard, f"tls/{box_host.addresses[0]}:{PORT}",
            f"tls/{box_host.addresses[0]}:{REGIONAL_PORT}", credentials, stranger, revoked,
            data_dir,
        )  # fmt: skip
        settings = BusSettings(
            mode="client",
            connect_endpoints=[f"tls/{watch_address}:{PORT}"],
            listen_endpoints=[],
            tls_dir=site / "operator",
        )
        central = BusSettings(
            mode="client",
            connect_endpoints=[f"tls/{watch_address}:{REGIONAL_PORT}"],
            listen_endpoints=[],
            tls_dir=credentials / "regional" / "central-gateway",
        )
        _wait(lambda: _opens(settings), "the router, for the operator", 30.0)
        _wait(lambda: _opens(central), "the regional router, for the centre", 30.0)
        with (
            zenoh.open(zenoh_config(settings)) as session,
            zenoh.open(zenoh_config(central)) as central_session,
        ):

            def on_sample(sample: zenoh.Sample) -> None:
                with result.lock:
                    result.seen.append((str(sample.key_expr), sample.payload.to_bytes()))

            def on_central(sample: zenoh.Sample) -> None:
                with result.lock:
                    result.central_seen.append((str(sample.key_expr), sample.payload.to_bytes()))

            session.declare_subscriber(f"wz/{SITE}/**", on_sample)
            central_session.declare_subscriber(f"wz/{SITE}/**", on_central)
            result.session = session  # type: ignore[attr-defined]
            yield result
    finally:
        stop_file.touch()
        for process in processes:
            process.terminate()
        for process in processes:
            try:
                process.wait(10)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
        network.close()


def _opens(settings: BusSettings) -> bool:
    try:
        zenoh.open(zenoh_config(settings)).close()  # type: ignore[no-untyped-call]
    except zenoh.ZError:
        return False
    return True


def _probe(box: Box, tls_dir: Path, *extra: str, at: str = "trailer") -> tuple[str, set[str]]:
    """Run the probe in the yard against the trailer's router (or the regional one); its first
    line, and the forged kinds the routers let by (to the operator at the trailer's router,
    or to the centre at the regional router)."""
    with box.lock:
        box.seen.clear()
        box.central_seen.clear()
    endpoint = box.router_endpoint if at == "trailer" else box.regional_endpoint
    argv = [sys.executable, "-m", "tests.deploy.bus_probe", endpoint, SITE,
            str(tls_dir), *extra]  # fmt: skip
    process = subprocess.Popen(
        box.yard.argv(argv), env=_env(), cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )
    assert process.stdout is not None
    first = process.stdout.readline().decode().strip()
    replies: list[bytes] = []
    if first == "connected" and at == "trailer":
        # Ask until its queryable answers through the router or it stops serving (a loaded
        # machine routed the declaration after more than 1 s).
        session: zenoh.Session = box.session  # type: ignore[attr-defined]
        serving_until = time.monotonic() + PUT_S - 0.5
        while b"forged" not in replies and time.monotonic() < serving_until:
            for reply in session.get(f"wz/{SITE}/alerts/active", timeout=0.5):
                if reply.ok is not None:
                    replies.append(reply.ok.payload.to_bytes())
    _, err = process.communicate(timeout=30)
    time.sleep(0.5)  # the last samples in flight
    seen = box.forged_seen(at) | (box.forged_seen("regional") if at == "trailer" else set())
    if b"forged" in replies:
        seen.add("active reply")
    assert process.returncode in (0, 3), err.decode()[-2000:]
    return first, seen


@pytest.mark.parametrize("role", list(ALLOWED))
def test_a_role_gets_through_the_router_only_what_it_may_give(box: Box, role: str) -> None:
    first, seen = _probe(box, box.credentials / SITE / role)
    assert first == "connected"
    # What the trailer's router lets by also reaches the centre (the trailer's uplink), and
    # nothing else does.
    assert seen == ALLOWED[role]


#: Every identity of the other site: its services', its operator's and its trailer router's.
OTHER_IDENTITIES = [*ALLOWED, "router"]


@pytest.mark.parametrize("at", ["trailer", "regional"])
@pytest.mark.parametrize("role", OTHER_IDENTITIES)
def test_another_sites_certificate_gives_nothing_of_this_site(box: Box, role: str, at: str) -> None:
    """Same CA, so the TLS handshake succeeds; the common name names the other site, so no
    rule of this site's router, and no rule of the regional router for this site's keys,
    lets anything by: alerts, detections, tracks, devices, raw data, status, config."""
    first, seen = _probe(box, box.credentials / OTHER_SITE / role, at=at)
    assert first == "connected"
    assert seen == set(), f"{OTHER_SITE}'s {role} certificate got {seen} through at {at}"


def test_the_router_lets_the_authorised_pipeline_run(box: Box) -> None:
    """Tracks from the tracker's certificate, alerts from the alert service's, stored by the
    gateway: all along the probes' forgeries, none of which is among them."""
    database = box.data_dir / "gateway.sqlite3"

    def stored() -> list[tuple[str, str]]:
        if not database.exists():
            return []
        with sqlite3.connect(f"file:{database}?mode=ro", uri=True) as db:
            return db.execute("SELECT source_id, alert_type FROM alerts").fetchall()

    _wait(lambda: len(stored()) >= 3, "alerts stored by the gateway", 60.0)
    assert {source for source, _ in stored()} == {"alert-service"}
    with box.lock:
        keys = {key for key, _ in box.seen}
    assert f"wz/{SITE}/tracks" in keys and f"wz/{SITE}/status/gateway" in keys

    def central_keys() -> set[str]:
        with box.lock:
            return {key for key, _ in box.central_seen}

    # Up the trailer's link to the regional router: the site's alerts and tracks.
    _wait(
        lambda: {f"wz/{SITE}/tracks", f"wz/{SITE}/alerts/speeding"} <= central_keys(),
        "the site's tracks and alerts at the centre",
        30.0,
    )


@pytest.mark.parametrize(
    ("role", "at"),
    [("alert-service", "trailer"), ("fusion-tracker", "trailer"), ("router", "regional")],
)
def test_the_sites_rotated_away_generation_gives_nothing(box: Box, role: str, at: str) -> None:
    """Certificates of this very site, of the generation before `wz credentials make` made it
    again (a stolen box's): the same CA and the same role, but named by no rule any more."""
    first, seen = _probe(box, box.revoked / role, at=at)
    assert first == "connected"
    assert seen == set(), f"the old {role} certificate got {seen} through at {at}"


@pytest.mark.parametrize("how", ["no certificate", "another CA's certificate"])
def test_a_session_without_the_sites_certificate_cannot_connect(box: Box, how: str) -> None:
    if how == "no certificate":
        first, seen = _probe(box, box.credentials / SITE / "alert-service", "--no-cert")
    else:
        first, seen = _probe(box, box.stranger / SITE / "alert-service")
    assert first.startswith("refused"), first
    assert seen == set()
