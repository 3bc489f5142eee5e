"""deploy/systemd/: one unit per process of the stack, checked as INI files against the code.

Every service of ``wz up`` (cli/src/wz_cli/stack.py) has ``wz-<name>.service`` whose ExecStart
runs its module from the venv; each runs as ``wz`` with the shared environment file, restarts on
failure, starts after the router, and is sandboxed. ``systemd-analyze verify`` runs too where
it is installed.
"""

from __future__ import annotations

import configparser
import shlex
import shutil
import subprocess
from pathlib import Path

import pytest

from wz_cli.stack import ROUTER, STACK, ServiceSpec

ROOT = Path(__file__).resolve().parents[2]
SYSTEMD_DIR = ROOT / "deploy" / "systemd"
UNITS = sorted(SYSTEMD_DIR.glob("*.service"))
VENV_PYTHON = "/opt/wz/venv/bin/python"
#: Installed copies of repository files the units name (docs/deployment.md).
INSTALLED = {"/etc/wz/zenoh/": ROOT / "deploy" / "zenoh"}

Unit = dict[str, dict[str, list[str]]]


def read_unit(path: Path) -> Unit:
    """A unit file as {section: {key: [values, in order]}}: systemd allows repeated keys."""
    # First as INI (no interpolation: systemd's % specifiers are not Python's) ...
    parser = configparser.ConfigParser(interpolation=None, strict=False)
    parser.optionxform = str  # type: ignore[assignment,method-assign]  # keys are case-sensitive
    parser.read(path, encoding="utf-8")
    # ... then keeping repeated keys, which configparser would merge.
    unit: Unit = {}
    section: dict[str, list[str]] = {}
    for line in path.read_text(encoding="utf-8").splitlines():
        line = line.strip()
        if not line or line.startswith(("#", ";")):
            continue
        if line.startswith("[") and line.endswith("]"):
            section = unit.setdefault(line[1:-1], {})
            continue
        key, sep, value = line.partition("=")
        assert sep, f"{path.name}: not key=value: {line!r}"
        section.setdefault(key.strip(), []).append(value.strip())
    assert set(unit) == set(parser.sections()), path.name
    return unit


def one(unit: Unit, section: str, key: str) -> str:
    values = unit[section].get(key, [])
    assert len(values) == 1, f"{section}/{key}: {values}"
    return values[0]


def environment(unit: Unit) -> dict[str, str]:
    pairs = [item.split("=", 1) for item in unit["Service"].get("Environment", [])]
    return dict(pairs)


def unit_name(name: str) -> str:
    return f"wz-{name}.service"


def test_one_unit_per_process_of_the_stack() -> None:
    expected = {unit_name(spec.name) for spec in (ROUTER, *STACK)}
    assert {path.name for path in UNITS} == expected


@pytest.mark.parametrize("path", UNITS, ids=[path.name for path in UNITS])
def test_unit_runs_sandboxed_as_wz_and_restarts(path: Path) -> None:
    unit = read_unit(path)
    assert set(unit) == {"Unit", "Service", "Install"}
    assert one(unit, "Unit", "Description")
    # Each service its own user (its bus key readable by it alone), the group wz for the
    # shared settings (/etc/wz/wz.env, the site file).
    assert one(unit, "Service", "User") == path.stem
    assert one(unit, "Service", "Group") == "wz"
    assert one(unit, "Service", "EnvironmentFile") == "/etc/wz/wz.env"
    assert one(unit, "Service", "Restart") == "on-failure"
    assert one(unit, "Service", "NoNewPrivileges") == "yes"
    assert one(unit, "Service", "ProtectSystem") == "strict"
    # ProtectSystem=strict makes everything read-only: the state directory is the way out.
    writable = one(unit, "Service", "ReadWritePaths").split()
    assert writable and all(p.startswith("/var/lib/wz/") for p in writable)
    state = one(unit, "Service", "StateDirectory").split()
    assert {f"/var/lib/{s}" for s in state} == set(writable)
    assert one(unit, "Install", "WantedBy") == "multi-user.target"


@pytest.mark.parametrize("spec", STACK, ids=[spec.name for spec in STACK])
def test_service_unit_runs_its_module_on_the_router(spec: ServiceSpec) -> None:
    unit = read_unit(SYSTEMD_DIR / unit_name(spec.name))
    argv = shlex.split(one(unit, "Service", "ExecStart"))
    assert argv == [VENV_PYTHON, "-m", spec.module, *spec.args]
    assert one(unit, "Unit", "Requires") == unit_name(ROUTER.name)
    assert one(unit, "Unit", "After") == unit_name(ROUTER.name)
    env = environment(unit)
    # The session config of the edge box, pointed at the router on this host.
    assert env["WZ_BUS_CONNECT_ENDPOINTS"] == "tls/127.0.0.1:7447"
    # Its own certificate, as `wz credentials make` names the folder.
    assert env["WZ_BUS_TLS_DIR"] == f"/etc/wz/credentials/{spec.name}"
    config_file = env["WZ_BUS_CONFIG_FILE"]
    assert config_file == "/etc/wz/zenoh/edge-service.json5"
    assert (INSTALLED["/etc/wz/zenoh/"] / Path(config_file).name).is_file()
    # Every path it writes to is in its state directory.
    for key, value in env.items():
        if value.startswith("/var/"):
            assert value.startswith(f"/var/lib/wz/{spec.name}"), key


def test_router_unit_runs_the_trailer_router_config() -> None:
    unit = read_unit(SYSTEMD_DIR / unit_name(ROUTER.name))
    argv = shlex.split(one(unit, "Service", "ExecStart"))
    assert argv[:3] == [VENV_PYTHON, "-m", ROUTER.module]
    assert argv[3] == "router"
    config = argv[argv.index("--config") + 1]
    assert config == "/etc/wz/zenoh/trailer-router.json5"
    assert (INSTALLED["/etc/wz/zenoh/"] / Path(config).name).is_file()
    assert argv[argv.index("--tls-dir") + 1] == "/etc/wz/credentials/router"
    # The regional endpoint comes from wz.env; empty means none (`--connect ''`).
    assert argv[argv.index("--connect") + 1] == "${WZ_REGIONAL_ENDPOINT}"
    env_example = (SYSTEMD_DIR / "wz.env.example").read_text()
    assert "\nWZ_REGIONAL_ENDPOINT=" in env_example
    assert "\nWZ_GATEWAY_API_KEYS=" in env_example


def test_systemd_analyze_finds_nothing_but_the_missing_venv() -> None:
    analyze = shutil.which("systemd-analyze")
    assert analyze is not None, (
        "systemd-analyze is missing (deploy/host/bootstrap.sh installs systemd)"
    )
    result = subprocess.run(
        [analyze, "verify", *map(str, UNITS)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    problems = [
        line
        for line in (result.stdout + result.stderr).splitlines()
        if line.strip() and f"Command {VENV_PYTHON} is not executable" not in line
    ]
    assert problems == []
