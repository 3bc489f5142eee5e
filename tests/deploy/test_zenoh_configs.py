"""deploy/zenoh/: every config loads in the zenoh package, says what its role needs, and the
router mesh relays samples (real routers as `wz router` processes, real sessions, loopback).

The mesh: services (clients, edge-service.json5) -> trailer router (trailer-router.json5) ->
regional router (regional-router.json5). The deployed endpoints (tcp/router:7447, the
placeholder regional host, 0.0.0.0) are replaced by free loopback ports with the overrides the
deployment has too: ``wz router --listen/--connect`` and ``WZ_BUS_CONNECT_ENDPOINTS``.
"""

from __future__ import annotations

import json
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import zenoh

from tests.cli.procs import ROOT, free_port, port_open, stop_process, wait_for, wz_argv, wz_env
from wz_shared.bus import zenoh_config
from wz_shared.settings import BusSettings
from wz_shared.trust import deny_all, edge_access_control, regional_access_control

ZENOH_DIR = ROOT / "deploy" / "zenoh"
EDGE_SERVICE = ZENOH_DIR / "edge-service.json5"
TRAILER_ROUTER = ZENOH_DIR / "trailer-router.json5"
REGIONAL_ROUTER = ZENOH_DIR / "regional-router.json5"
CONFIGS = sorted(ZENOH_DIR.glob("*.json5"))
#: How many samples each relay test publishes, and must receive exactly.
N_SAMPLES = 5


def get(config: zenoh.Config, path: str) -> Any:
    return json.loads(config.get_json(path))


# --- the files --------------------------------------------------------------------------------


def test_the_configs_are_there() -> None:
    names = {path.name for path in CONFIGS}
    assert {
        "router-local.json5",
        "edge-service.json5",
        "trailer-router.json5",
        "regional-router.json5",
    } <= names


@pytest.mark.parametrize("path", CONFIGS, ids=[path.name for path in CONFIGS])
def test_config_loads_in_zenoh_without_multicast(path: Path) -> None:
    config = zenoh.Config.from_file(str(path))  # refuses unknown fields and bad types
    assert get(config, "scouting/multicast/enabled") is False
    assert get(config, "mode") in {"client", "router"}


def test_edge_service_is_a_tls_client_of_the_trailer_router() -> None:
    config = zenoh.Config.from_file(str(EDGE_SERVICE))
    assert get(config, "mode") == "client"
    assert get(config, "connect/endpoints") == ["tls/router:7447"]
    assert get(config, "listen/endpoints") == []
    tls = get(config, "transport/link/tls")
    assert tls["enable_mtls"] is True and tls["verify_name_on_connect"] is True
    assert tls["connect_certificate"] == "/etc/wz/tls/cert.pem"
    assert tls["connect_private_key"] == "/etc/wz/tls/key.pem"
    assert tls["root_ca_certificate"] == "/etc/wz/tls/ca.pem"


def test_trailer_router_listens_for_the_box_over_tls_and_connects_up() -> None:
    config = zenoh.Config.from_file(str(TRAILER_ROUTER))
    assert get(config, "mode") == "router"
    assert get(config, "listen/endpoints") == ["tls/0.0.0.0:7447"]
    # A placeholder that never resolves, replaced at install (or by --connect).
    assert get(config, "connect/endpoints") == ["tls/regional.wz.invalid:7447"]
    tls = get(config, "transport/link/tls")
    assert tls["enable_mtls"] is True and tls["verify_name_on_connect"] is True
    assert tls["listen_certificate"] == tls["connect_certificate"] == "/etc/wz/tls/cert.pem"


def test_trailer_router_as_shipped_denies_everything_until_its_site_is_given() -> None:
    """The shipped file names no identity (fail closed); the site's own access control comes
    with its credentials (`wz router --tls-dir`)."""
    config = zenoh.Config.from_file(str(TRAILER_ROUTER))
    expected = zenoh.Config()
    expected.insert_json5("access_control", json.dumps(deny_all()))
    assert get(config, "access_control") == get(expected, "access_control")


def test_regional_router_listens_over_tls_and_denies_all_without_its_sites() -> None:
    config = zenoh.Config.from_file(str(REGIONAL_ROUTER))
    assert get(config, "mode") == "router"
    assert get(config, "listen/endpoints") == ["tls/0.0.0.0:7447"]
    assert get(config, "connect/endpoints") == []
    assert get(config, "transport/link/tls/enable_mtls") is True
    acl = get(config, "access_control")
    assert acl["enabled"] is True and acl["default_permission"] == "deny"
    assert acl["policies"] == []


@pytest.mark.parametrize("sites", [["a"], ["us75-lincoln", "i80-omaha"]])
def test_generated_access_controls_load_and_name_what_exists(sites: list[str]) -> None:
    generations = {site: 1 for site in sites}
    for acl in (
        edge_access_control(sites[0], 1),
        edge_access_control(sites[-1], 7),
        regional_access_control(generations),
    ):
        config = zenoh.Config()
        config.insert_json5("access_control", json.dumps(acl))  # zenoh checks the block
        rules = {rule["id"] for rule in acl["rules"]}
        subjects = {subject["id"] for subject in acl["subjects"]}
        assert acl["default_permission"] == "deny" and acl["policies"]
        for policy in acl["policies"]:
            assert set(policy["rules"]) <= rules and set(policy["subjects"]) <= subjects
        for rule in acl["rules"]:
            for key_expr in rule["key_exprs"]:
                zenoh.KeyExpr(key_expr)  # raises for an invalid one


def test_a_service_session_takes_the_file_and_only_explicit_overrides(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    for name in ("WZ_BUS_MODE", "WZ_BUS_CONNECT_ENDPOINTS", "WZ_BUS_LISTEN_ENDPOINTS"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("WZ_BUS_CONFIG_FILE", str(EDGE_SERVICE))
    config = zenoh_config(BusSettings())
    assert get(config, "mode") == "client"  # the file's, not the default peer
    assert get(config, "connect/endpoints") == ["tls/router:7447"]
    monkeypatch.setenv("WZ_BUS_CONNECT_ENDPOINTS", "tcp/127.0.0.1:7999")
    config = zenoh_config(BusSettings())
    assert get(config, "mode") == "client"
    assert get(config, "connect/endpoints") == ["tcp/127.0.0.1:7999"]
    assert get(config, "listen/endpoints") == []
    # Without a file the defaults apply as before: a loopback peer.
    monkeypatch.delenv("WZ_BUS_CONFIG_FILE")
    assert get(zenoh_config(BusSettings()), "mode") == "peer"


# --- the mesh, with real routers ----------------------------------------------------------------

SITE = "test-site"


@pytest.fixture(scope="module")
def credentials(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Every identity of SITE, and the regional side's (`wz credentials`)."""
    from wz_cli.credentials import make_regional, make_site

    folder = tmp_path_factory.mktemp("credentials")
    make_site(folder, SITE)
    make_regional(folder, names=["localhost", "127.0.0.1"])
    return folder


def start_router(config: Path, tls_dir: Path, *extra: str) -> tuple[str, subprocess.Popen[bytes]]:
    """`wz router --config CONFIG --tls-dir TLS_DIR --listen <free loopback port> EXTRA`,
    accepting connections."""
    port = free_port()
    endpoint = f"tls/127.0.0.1:{port}"
    process = subprocess.Popen(
        wz_argv(
            "router",
            "--config",
            str(config),
            "--tls-dir",
            str(tls_dir),
            "--listen",
            endpoint,
            *extra,
        ),
        cwd=ROOT,
        env=wz_env(),
        stderr=subprocess.PIPE,
    )
    wait_for(lambda: port_open(port) or process.poll() is not None, 20.0, f"router {config.name}")
    if process.poll() is not None:
        err = process.stderr.read().decode() if process.stderr else ""
        pytest.fail(f"router {config.name} exited: {err}")
    return endpoint, process


@pytest.fixture
def routers() -> Iterator[list[subprocess.Popen[bytes]]]:
    """The routers a test starts; each must exit 0 on SIGTERM."""
    started: list[subprocess.Popen[bytes]] = []
    try:
        yield started
    finally:
        codes = [stop_process(process, timeout_s=20.0) for process in reversed(started)]
        for process in started:
            if process.stderr is not None:
                process.stderr.close()
        assert all(code == 0 for code in codes), codes


def service_session(router_endpoint: str, tls_dir: Path) -> zenoh.Session:
    """A session opened as a service opens it: the edge-service file, the router's address
    from WZ_BUS_CONNECT_ENDPOINTS, its credentials from WZ_BUS_TLS_DIR."""
    settings = BusSettings(
        config_file=EDGE_SERVICE, connect_endpoints=[router_endpoint], tls_dir=tls_dir
    )
    return zenoh.open(zenoh_config(settings))


def client_session(router_endpoint: str, tls_dir: Path) -> zenoh.Session:
    settings = BusSettings(
        mode="client", connect_endpoints=[router_endpoint], listen_endpoints=[], tls_dir=tls_dir
    )
    return zenoh.open(zenoh_config(settings))


def relay(
    publisher_session: zenoh.Session,
    subscriber_session: zenoh.Session,
    key: str,
    subscribed: str | None = None,
) -> None:
    """Once a probe has crossed the mesh, N_SAMPLES published on ``key`` all arrive, in order.

    The publisher's matching status alone is not enough: under load in CI it turned true while
    a router on the path had no route yet, and all five samples put at once were lost. So the
    probe is put every 50 ms until one arrives; probes come before the samples from one
    publisher, and are left out of the comparison. ``subscribed``: the subscriber's key
    expression, when not ``key`` itself (a central gateway's ``wz/*/alerts/*``).
    """
    subscriber = subscriber_session.declare_subscriber(subscribed or key)
    publisher = publisher_session.declare_publisher(key)
    wait_for(lambda: publisher.matching_status.matching, 15.0, f"a subscriber of {key}")
    received: list[str] = []

    def drain() -> list[str]:
        while (sample := subscriber.try_recv()) is not None:
            received.append(sample.payload.to_string())
        return [text for text in received if text != "probe"]

    def probe_arrived() -> bool:
        publisher.put("probe")
        drain()
        return "probe" in received

    wait_for(probe_arrived, 15.0, f"a probe on {key} across the mesh")
    for index in range(N_SAMPLES):
        publisher.put(f"sample {index}")
    wait_for(lambda: len(drain()) >= N_SAMPLES, 10.0, f"{N_SAMPLES} samples on {key}")
    assert drain() == [f"sample {index}" for index in range(N_SAMPLES)]
    publisher.undeclare()
    subscriber.undeclare()


def refused(publisher_session: zenoh.Session, subscriber_session: zenoh.Session, key: str) -> None:
    """Nothing ``publisher_session`` puts on ``key`` reaches ``subscriber_session`` (2 s of
    puts, with a subscriber that does receive others' samples on the same router)."""
    subscriber = subscriber_session.declare_subscriber(key)
    deadline = time.monotonic() + 2.0
    while time.monotonic() < deadline:
        publisher_session.put(key, "forged")
        time.sleep(0.05)
    assert subscriber.try_recv() is None
    subscriber.undeclare()


def test_trailer_router_relays_on_the_box_while_its_regional_router_is_unreachable(
    routers: list[subprocess.Popen[bytes]], credentials: Path
) -> None:
    # The config's own uplink (the placeholder host) stays: it must not keep the router down.
    trailer, process = start_router(TRAILER_ROUTER, credentials / SITE / "router")
    routers.append(process)
    site = credentials / SITE
    with (
        service_session(trailer, site / "lidar-detector") as detector,
        service_session(trailer, site / "fusion-tracker") as tracker,
    ):
        relay(detector, tracker, f"wz/{SITE}/detections/lidar")


def test_trailer_router_relays_up_to_the_regional_router(
    routers: list[subprocess.Popen[bytes]], credentials: Path
) -> None:
    regional, process = start_router(REGIONAL_ROUTER, credentials / "regional" / "router")
    routers.append(process)
    trailer, process = start_router(
        TRAILER_ROUTER, credentials / SITE / "router", "--connect", regional
    )
    routers.append(process)
    central_tls = credentials / "regional" / "central-gateway"
    alert_tls = credentials / SITE / "alert-service"
    with (
        service_session(trailer, alert_tls) as alert_service,
        client_session(regional, central_tls) as central,
    ):
        # As the central gateway subscribes: every site's alerts at once.
        relay(alert_service, central, f"wz/{SITE}/alerts/speeding", "wz/*/alerts/*")
        # Not down: the region only reads; a sample it puts never reaches the trailer.
        refused(central, alert_service, f"wz/{SITE}/config/sign")
        # Nor another site's keys up: the trailer gives only its own site's.
        refused(alert_service, central, "wz/other-site/alerts/speeding")


def test_router_overrides_replace_the_config_endpoints_and_credentials(
    credentials: Path,
) -> None:
    from wz_cli.router import router_config

    config = router_config(["tls/127.0.0.1:7999"], TRAILER_ROUTER, ["tls/127.0.0.1:7998"])
    assert get(config, "listen/endpoints") == ["tls/127.0.0.1:7999"]
    assert get(config, "connect/endpoints") == ["tls/127.0.0.1:7998"]
    assert get(router_config(None, TRAILER_ROUTER, []), "connect/endpoints") == []
    kept = router_config(None, TRAILER_ROUTER)
    assert get(kept, "connect/endpoints") == ["tls/regional.wz.invalid:7447"]
    regional = credentials / "regional" / "router"
    config = router_config(None, REGIONAL_ROUTER, None, regional)
    assert get(config, "transport/link/tls/listen_certificate") == str(regional / "cert.pem")
    expected = zenoh.Config()
    expected.insert_json5("access_control", json.dumps(regional_access_control({SITE: 1})))
    assert get(config, "access_control") == get(expected, "access_control")
