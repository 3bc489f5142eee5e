"""`wz up --topology`: the topology file, the children's configs, and a real stack on it.

Contract used (services/alert_service, the cheapest service to start): ``python -m
wz_alert_service.node`` reports itself alive under ``wz/<site>/status/alert-service``.
"""

from __future__ import annotations

import json
import signal
import subprocess
import threading
from pathlib import Path

import pytest
import zenoh

from tests.cli.procs import ROOT, free_port, run_wz, running, wait_for, wz_argv, wz_env
from wz_cli.common import CliError
from wz_cli.stack import STACK, StackOptions
from wz_cli.supervisor import Supervisor
from wz_cli.topology import load_topology
from wz_shared.bus import zenoh_config
from wz_shared.settings import BusSettings
from wz_shared.site import DEFAULT_SITE_PATH

EDGE_BOX = ROOT / "deploy" / "topologies" / "edge-box.yaml"
ZENOH_DIR = ROOT / "deploy" / "zenoh"
NAMES = [spec.name for spec in STACK]


def test_edge_box_topology_names_every_service_with_the_deployed_configs() -> None:
    topology = load_topology(EDGE_BOX, NAMES)
    assert topology.router.zenoh_config == ZENOH_DIR / "trailer-router.json5"
    assert topology.router.listen == "tls/127.0.0.1:7447"
    assert topology.router.connect == []
    assert topology.services == {name: ZENOH_DIR / "edge-service.json5" for name in NAMES}


def test_children_get_the_topology_configs() -> None:
    topology = load_topology(EDGE_BOX, NAMES)
    options = topology.configure(StackOptions("tcp/127.0.0.1:7500", DEFAULT_SITE_PATH))
    # A WZ_BUS_MODE in the shell of `wz up` must not override the file's.
    supervisor = Supervisor(STACK, options, threading.Event(), base_env={"WZ_BUS_MODE": "peer"})
    assert supervisor.router.argv[-6:] == [
        "--listen",
        "tcp/127.0.0.1:7500",
        "--config",
        str(ZENOH_DIR / "trailer-router.json5"),
        "--connect",
        "",
    ]
    for child in supervisor.services:
        assert child.env["WZ_BUS_CONFIG_FILE"] == str(ZENOH_DIR / "edge-service.json5")
        assert child.env["WZ_BUS_CONNECT_ENDPOINTS"] == "tcp/127.0.0.1:7500"
        # The file says the mode (client) and what to listen on (nothing).
        assert "WZ_BUS_MODE" not in child.env and "WZ_BUS_LISTEN_ENDPOINTS" not in child.env
    plain_options = StackOptions("tcp/127.0.0.1:7500", DEFAULT_SITE_PATH)
    plain = Supervisor(STACK, plain_options, threading.Event(), base_env={})
    assert plain.router.argv[-2:] == ["--listen", "tcp/127.0.0.1:7500"]
    assert plain.services[0].env["WZ_BUS_MODE"] == "peer"


def _write_topology(tmp_path: Path, router: str, services: dict[str, str]) -> Path:
    path = tmp_path / "topology.yaml"
    path.write_text(
        f"router: {router}\nservices:\n"
        + "".join(f"  {name}: {config}\n" for name, config in services.items())
    )
    return path


def test_bad_topologies_are_refused_with_what_is_wrong(tmp_path: Path) -> None:
    (tmp_path / "good.json5").write_text('{ mode: "router" }')
    (tmp_path / "bad.json5").write_text('{ mode: "router", colour: "red" }')
    every = {name: "good.json5" for name in NAMES}
    cases = [
        ("{zenoh_config: good.json5}", {"simulator": "good.json5"}, "missing alert-service"),
        ("{zenoh_config: good.json5}", {**every, "radar": "good.json5"}, "unknown radar"),
        ("{zenoh_config: good.json5, colour: red}", every, "colour"),
        ("{zenoh_config: nope.json5}", every, "nope.json5, which does not exist"),
        ("{zenoh_config: bad.json5}", every, "bad.json5 is not a zenoh config"),
        ("[", every, "is not valid"),
    ]
    for router, services, message in cases:
        path = _write_topology(tmp_path, router, services)
        with pytest.raises(CliError, match=message):
            load_topology(path, NAMES)


def _router_sessions(endpoint: str, tls_dir: Path) -> list[dict[str, object]]:
    """The sessions the router reports in its admin space (the trailer config enables it, for
    the operator's certificate)."""
    settings = BusSettings(
        mode="client", connect_endpoints=[endpoint], listen_endpoints=[], tls_dir=tls_dir
    )
    with zenoh.open(zenoh_config(settings)) as session:
        me = str(session.zid())
        sessions: list[dict[str, object]] = []
        for reply in session.get("@/*/router", timeout=3.0):
            if reply.ok is not None:
                sessions += json.loads(reply.ok.payload.to_string())["sessions"]
    return [s for s in sessions if s["peer"] != me]


def test_up_with_the_edge_box_topology_needs_credentials(tmp_path: Path) -> None:
    result = run_wz("up", "--topology", str(EDGE_BOX), "--only", "alert-service")
    assert result.returncode == 2
    assert "--credentials" in result.stderr and "wz credentials make" in result.stderr
    result = run_wz(
        "up",
        "--topology",
        str(EDGE_BOX),
        "--only",
        "alert-service",
        "--credentials",
        str(tmp_path),
    )
    assert result.returncode == 2 and "has no credentials for router" in result.stderr


@pytest.mark.xdist_group("stack")
def test_up_with_the_edge_box_topology(tmp_path: Path) -> None:
    from wz_cli.credentials import make_site
    from wz_shared.site import load_site

    credentials = tmp_path / "credentials"
    site_id = load_site(DEFAULT_SITE_PATH).site_id
    make_site(credentials, site_id)
    operator = {"WZ_BUS_TLS_DIR": str(credentials / site_id / "operator")}
    endpoint = f"tls/127.0.0.1:{free_port()}"
    log_path = tmp_path / "up.log"
    with log_path.open("wb") as log:
        up = subprocess.Popen(
            wz_argv(
                "up",
                "--topology",
                str(EDGE_BOX),
                "--only",
                "alert-service",
                "--listen",
                endpoint,
                "--credentials",
                str(credentials),
            ),
            cwd=ROOT,
            env=wz_env(WZ_ALERT_STATUS_PERIOD_S="0.5"),
            stdout=log,
            stderr=subprocess.STDOUT,
        )
        with running(up):

            def alert_service_alive() -> bool:
                result = run_wz(
                    "status",
                    "--json",
                    "--timeout",
                    "2",
                    "--connect",
                    endpoint,
                    "--expect",
                    "alert-service",
                    **operator,
                )
                if result.returncode != 0:
                    return False
                services = json.loads(result.stdout)["services"]
                return any(s["service"] == "alert-service" and s["alive"] for s in services)

            wait_for(alert_service_alive, 45.0, "the alert service alive in `wz status`")
            # The service joined as the edge-service config says: a client of the router.
            sessions = _router_sessions(endpoint, credentials / site_id / "operator")
            assert [s["whatami"] for s in sessions] == ["client"], sessions
            up.send_signal(signal.SIGINT)
            assert up.wait(30) == 0
    log_text = log_path.read_text()
    assert "trailer-router.json5" in log_text
    assert f"listening on {endpoint}, connecting to nothing" in log_text


def test_up_help_says_credentials_takes_the_folder_make_wrote() -> None:
    """The folder given to `wz credentials make`, not its <site>/ subfolder (which the help
    once said, and which fails)."""
    result = run_wz("up", "--help")
    text = " ".join(result.stdout.split())
    assert result.returncode == 0
    assert "DIR itself, not its <site>/ subfolder" in text
