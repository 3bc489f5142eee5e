"""`wz up` with the real simulator: status, tap, restart after kill -9, clean stop, no orphans.

Contract used (services/simulator): ``python -m wz_simulator.node`` publishes GroundTruth on
``wz/<site>/truth/vehicles`` and, through ServiceRuntime, a liveliness token and ServiceStatus
(with its pid) on ``wz/<site>/status/simulator``.
"""

from __future__ import annotations

import json
import logging
import os
import re
import signal
import socket
import subprocess
import threading
from pathlib import Path
from typing import Any

import pytest

from tests.cli.procs import ROOT, free_port, run_wz, running, wait_for, wz_argv, wz_env
from wz_cli import supervisor as supervisor_module
from wz_cli.stack import ServiceSpec, StackOptions
from wz_cli.supervisor import Supervisor
from wz_shared.site import DEFAULT_SITE_PATH

#: Runs `wz up`, whose services serve metrics on fixed ports: one such test at a time (pytest-xdist
#: group; the Makefile runs -n auto --dist loadgroup).
pytestmark = pytest.mark.xdist_group("stack")


def _state(pid: int) -> str | None:
    """The process state letter (R, S, Z ...) or None when there is no such process."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except (FileNotFoundError, ProcessLookupError):
        return None
    return stat.rsplit(")", 1)[1].split()[0]


def _gone(pid: int) -> bool:
    return _state(pid) in (None, "Z", "X")  # a zombie has exited; only its parent must reap it


def _is_standby(pid: int) -> bool:
    """Whether ``pid`` runs ``python -m wz_cli.standby ...`` (waiting, or woken as a service)."""
    try:
        return b"wz_cli.standby" in Path(f"/proc/{pid}/cmdline").read_bytes()
    except (FileNotFoundError, ProcessLookupError):
        return False


def _waiting_standbys(log: str) -> set[int]:
    """The warm standbys the supervisor's log shows started and not (yet) woken."""
    started = re.findall(r"standby of \S+ \(pid (\d+)\) importing", log)
    woken = re.findall(r"started \S+ \(pid (\d+)\) from its warm standby", log)
    return {int(pid) for pid in started} - {int(pid) for pid in woken}


def _children(pid: int) -> list[int]:
    """Every live child of ``pid`` (services and their warm standbys)."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except (FileNotFoundError, ProcessLookupError):
                continue
            if int(fields[1]) == pid and fields[0] != "Z":
                found.append(int(entry.name))
    return found


def _status(endpoint: str) -> dict[str, Any]:
    """`wz status --json`; no service at all while the router is not up yet."""
    result = run_wz(
        "status", "--json", "--timeout", "3", "--connect", endpoint, "--expect", "simulator"
    )
    if result.returncode == 1 and "cannot reach the bus" in result.stderr:
        return {"alive": 0, "services": []}
    report: dict[str, Any] = json.loads(result.stdout)
    assert result.returncode == (0 if report["ok"] else 1), result.stderr
    return report


def _simulator_pid(endpoint: str) -> int | None:
    """The pid of the simulator if it is alive and has reported its status."""
    for service in _status(endpoint)["services"]:
        if service["service"] == "simulator" and service["alive"] and service["status"]:
            return int(service["status"]["pid"])
    return None


def _start_up(command: str, endpoint: str, tmp_path: Path) -> subprocess.Popen[bytes]:
    log = (tmp_path / f"{command}.log").open("wb")
    return subprocess.Popen(
        wz_argv(command, "--only", "simulator", "--listen", endpoint, "--realtime-factor", "5"),
        cwd=ROOT,
        env=wz_env(WZ_SIM_WORK_DIR=str(tmp_path / "sim"), WZ_SIM_STATUS_PERIOD_S="0.5"),
        stdout=log,
        stderr=subprocess.STDOUT,
    )


def test_up_status_tap_restart_and_stop(tmp_path: Path) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    up = _start_up("up", endpoint, tmp_path)
    with running(up):
        pids: list[int | None] = [None]

        def simulator_alive() -> bool:
            pids[0] = _simulator_pid(endpoint)
            return pids[0] is not None

        wait_for(simulator_alive, 90.0, "the simulator alive in `wz status`")
        first_pid = pids[0]
        assert first_pid is not None

        tables: list[str] = []

        def truth_rate_shown() -> bool:
            # The first status may come before the first truth message (a loaded machine).
            table = run_wz("status", "--connect", endpoint, "--expect", "simulator")
            assert table.returncode == 0, table.stderr
            tables[:] = [table.stdout]
            return "wz/us75-lincoln/truth/vehicles" in table.stdout

        wait_for(truth_rate_shown, 60.0, "the truth key in `wz status`")
        assert re.search(rf"\nsimulator +up +[\d.]+ s +running +{first_pid} ", tables[0]), tables[0]

        lines: list[str] = []

        def vehicles_seen() -> bool:
            tap = run_wz(
                "tap", "wz/*/truth/**", "--count", "3", "--timeout", "20", "--connect", endpoint
            )
            assert tap.returncode == 0, tap.stderr
            lines[:] = tap.stdout.splitlines()
            assert len(lines) == 3 and all(" ground_truth  stamp=" in line for line in lines)
            return all(re.search(r"vehicles=[1-9]\d* first=\S+ [\d.]+ m/s", x) for x in lines)

        wait_for(vehicles_seen, 90.0, "vehicles in `wz tap`")
        assert all(line.startswith("wz/us75-lincoln/truth/vehicles  ") for line in lines)

        # A crash is followed by a restart: a new pid alive.
        os.kill(first_pid, signal.SIGKILL)

        def restarted() -> bool:
            return simulator_alive() and pids[0] != first_pid

        wait_for(restarted, 90.0, "a restarted simulator")
        second_pid = pids[0]
        assert second_pid is not None
        children = _children(up.pid)
        waiting = _waiting_standbys((tmp_path / "up.log").read_text())
        services = [pid for pid in children if pid not in waiting]
        assert second_pid in services and len(services) == 2  # the router and the simulator

        up.send_signal(signal.SIGINT)
        assert up.wait(30) == 0
    wait_for(lambda: all(map(_gone, children)), 10.0, "every child of `wz up` to exit")
    assert _gone(first_pid)
    log = (tmp_path / "up.log").read_text()
    assert re.search(rf"simulator \(pid {first_pid}\) killed by SIGKILL \(signal 9\)", log), log
    assert "restarting in 0.5 s" in log
    assert re.search(r"^simulator \| \{", log, re.MULTILINE)  # children's lines, prefixed
    assert re.search(r"^router    \| \{", log, re.MULTILINE)


def test_no_child_outlives_a_killed_supervisor(tmp_path: Path) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    demo = _start_up("demo", endpoint, tmp_path)
    with running(demo):
        wait_for(lambda: _simulator_pid(endpoint) is not None, 90.0, "the simulator alive")
        # The simulator's warm standby too: one, and gone with the rest.
        log = tmp_path / "demo.log"
        wait_for(lambda: bool(_waiting_standbys(log.read_text())), 60.0, "the standby")
        children = _children(demo.pid)
        (standby,) = _waiting_standbys(log.read_text())
        assert standby in children and _is_standby(standby) and len(children) == 3
        demo.kill()  # SIGKILL: no chance to stop its children itself
        demo.wait()
    wait_for(lambda: all(map(_gone, children)), 15.0, "the orphans to exit")
    banner = (tmp_path / "demo.log").read_text()
    assert f"wz tap --connect {endpoint} 'wz/*/truth/**'" in banner
    assert f"wz status --connect {endpoint}" in banner


def test_up_refuses_a_taken_port_and_unknown_services() -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = run_wz("up", "--listen", f"tcp/127.0.0.1:{port}", timeout_s=30)
    assert result.returncode == 1
    assert "already listens" in result.stderr
    result = run_wz("up", "--only", "simulator,nope", "--listen", "tcp/127.0.0.1:1")
    assert result.returncode == 2
    assert "no service named nope" in result.stderr


@pytest.mark.parametrize("endpoint", ["udp/127.0.0.1:7447", "tcp/127.0.0.1"])
def test_up_needs_a_tcp_router_endpoint(endpoint: str) -> None:
    result = run_wz("up", "--listen", endpoint)
    assert result.returncode == 2
    assert "tcp/ or tls/<host>:<port>" in result.stderr


def test_supervisor_backs_off_and_kills_what_ignores_sigterm(
    caplog: pytest.LogCaptureFixture, capsys: pytest.CaptureFixture[str]
) -> None:
    """Stand-in services: one exits at once (restarted, 0.5 s then 1 s then 2 s later), one
    ignores SIGTERM (killed after the grace period)."""
    stub = ServiceSpec("crasher", "tests.cli.stub_service", "exits 3", "X_", args=("crash",))
    stubborn = ServiceSpec("stubborn", "tests.cli.stub_service", "no", "X_", args=("stubborn",))
    options = StackOptions(f"tcp/127.0.0.1:{free_port()}", DEFAULT_SITE_PATH)
    stop = threading.Event()
    supervisor = Supervisor(
        [stub, stubborn],
        options,
        stop,
        base_env=wz_env(PYTHONPATH=str(ROOT)),
        stop_grace_s=1.0,
    )
    codes: list[int] = []
    caplog.set_level(logging.INFO, logger="wz_cli.supervisor")
    thread = threading.Thread(target=lambda: codes.append(supervisor.run()))
    thread.start()
    try:
        wait_for(lambda: supervisor.services[0].restarts >= 3, 30.0, "three restarts")
        stubborn_process = supervisor.services[1].process
        assert stubborn_process is not None
    finally:
        stop.set()
        thread.join(30.0)
    assert codes == [0]
    assert stubborn_process.returncode == -signal.SIGKILL
    messages = [record.getMessage() for record in caplog.records]
    delays = [
        float(m.split("restarting in ")[1].split(" s")[0])
        for m in messages
        if m.startswith("crasher") and "exited with code 3" in m
    ]
    assert delays[:3] == [0.5, 1.0, 2.0]
    assert any("did not stop within 1 s of SIGTERM: killing it" in m for m in messages)
    out = capsys.readouterr().out
    assert "crasher  | crashing now\n" in out and "crasher  | a line on stderr\n" in out
    assert "stubborn | ignoring SIGTERM\n" in out


def test_a_crashed_service_restarts_from_its_warm_standby(
    monkeypatch: pytest.MonkeyPatch,
    caplog: pytest.LogCaptureFixture,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """Once the child has run STANDBY_AFTER_S, a standby imports its module and waits; a kill
    -9 of the child wakes the standby: a new process that runs the module as `python -m`
    would, arguments included. Stopping the stack ends the standby started after it."""
    monkeypatch.setattr(supervisor_module, "STANDBY_AFTER_S", 0.5)
    spec = ServiceSpec(
        "server", "tests.cli.stub_service", "serves", "X_", args=("serve", "--flag"), standby=True
    )
    options = StackOptions(f"tcp/127.0.0.1:{free_port()}", DEFAULT_SITE_PATH)
    stop = threading.Event()
    supervisor = Supervisor([spec], options, stop, base_env=wz_env(PYTHONPATH=str(ROOT)))
    (child,) = supervisor.services
    codes: list[int] = []
    caplog.set_level(logging.INFO, logger="wz_cli.supervisor")
    thread = threading.Thread(target=lambda: codes.append(supervisor.run()))
    thread.start()
    spares: list[int] = []
    try:
        wait_for(child.spare_ready.is_set, 60.0, "the standby ready")
        assert child.process is not None and child.spare is not None
        first, standby = child.process.pid, child.spare.pid
        assert _is_standby(standby) and not _is_standby(first)
        os.kill(first, signal.SIGKILL)
        wait_for(lambda: child.restarts == 1 and child.running, 10.0, "the restart")
        assert child.process is not None and child.process.pid == standby
        wait_for(lambda: child.spare is not None, 10.0, "the next standby")
        assert child.spare is not None
        spares.append(child.spare.pid)
    finally:
        stop.set()
        thread.join(30.0)
    assert codes == [0]
    assert child.process is not None and child.process.returncode == 0  # SIGTERM: clean stop
    wait_for(lambda: all(map(_gone, spares)), 10.0, "the new standby to end")
    out = capsys.readouterr().out
    assert f"server | serving: pid {first}, args ['serve', '--flag']\n" in out
    assert f"server | serving: pid {standby}, args ['serve', '--flag']\n" in out
    assert "wz-standby-ready" not in out  # the supervisor takes that line
    messages = [record.getMessage() for record in caplog.records]
    assert f"started server (pid {standby}) from its warm standby, restart #1" in messages
    assert any(
        m.startswith(f"standby of server (pid {standby}) ready: its imports took ")
        for m in messages
    )
