"""The monitoring profile: Prometheus' configs and alert rules checked and unit-tested with the
real ``promtool`` (Debian's ``prometheus`` package, installed by deploy/host/bootstrap.sh), the
local scrape config in step with `wz up`'s ports, the Grafana dashboard's queries on series
the services export; and, during a real `wz up`, every service's ``/metrics`` scraped, by the
test and by a real Prometheus running the shipped rules on the local config."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import time
import urllib.parse
from pathlib import Path
from typing import Any

import httpx
import pytest
import yaml
from prometheus_client import generate_latest

from tests.cli.procs import ROOT, free_port, running, start_wz_up, wait_for
from wz_cli.stack import STACK, select
from wz_shared.messages import DeviceLink, ServiceState
from wz_shared.metrics import RuntimeView, ServiceMetrics

MONITORING = ROOT / "deploy" / "monitoring"
PROMTOOL = shutil.which("promtool")
PROMETHEUS = shutil.which("prometheus")
COMPOSE = yaml.safe_load((ROOT / "docker-compose.yml").read_text(encoding="utf-8"))
#: The gateway's port in prometheus-local.yml: `wz up`'s default (WZ_GATEWAY_PORT).
GATEWAY_PORT = 8000


def promtool(*args: str) -> subprocess.CompletedProcess[str]:
    assert PROMTOOL, "promtool is missing: run deploy/host/bootstrap.sh (apt: prometheus)"
    return subprocess.run(
        [PROMTOOL, *args], cwd=MONITORING, capture_output=True, text=True, timeout=60, check=False
    )


@pytest.mark.parametrize("config", ["prometheus.yml", "prometheus-local.yml"])
def test_promtool_accepts_the_scrape_configs(config: str) -> None:
    result = promtool("check", "config", config)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "SUCCESS: 6 rules found" in result.stdout


def test_the_alert_rules_fire_on_what_they_should_in_promtools_unit_tests() -> None:
    """rules_test.yml: a stalled loop, a failed scrape, a silent LiDAR, growing drops and a
    sign not answering each set off their alert, with the labels and summaries expected."""
    result = promtool("test", "rules", "rules_test.yml")
    assert result.returncode == 0, result.stdout + result.stderr
    rules = yaml.safe_load((MONITORING / "rules.yml").read_text())["groups"]
    names = {rule["alert"] for group in rules for rule in group["rules"]}
    tested = set(re.findall(r"alertname: (\w+)", (MONITORING / "rules_test.yml").read_text()))
    assert {"WzServiceStalled", "WzSensorSilent", "WzDropsGrowing"} <= names
    assert names - tested == {"WzProcessingSlow"}  # its histogram input is left to the stack


def local_targets() -> list[str]:
    config = yaml.safe_load((MONITORING / "prometheus-local.yml").read_text())
    (job,) = config["scrape_configs"]
    return [t for group in job["static_configs"] for t in group["targets"]]


def test_the_local_config_scrapes_every_port_wz_up_gives() -> None:
    expected = [f"127.0.0.1:{s.metrics_port}" for s in STACK if s.metrics_port is not None]
    assert local_targets() == [*expected, f"127.0.0.1:{GATEWAY_PORT}"]
    ports = [s.metrics_port for s in STACK if s.metrics_port is not None]
    assert len(set(ports)) == len(ports)


def exported_series() -> set[str]:
    """The series names a node's registry exposes, with one of every kind of sample."""
    view = RuntimeView(
        service="lidar-detector",
        site="s",
        bus_snapshot=lambda: (
            {kind: {"wz/s/raw/lidar/a": 1} for kind in ("published", "received", "dropped", "gaps")}
            | {"invalid": {"wz/s/raw/lidar/a|invalid": 1}}
        ),
        queue_depths=lambda: {"wz/s/raw/lidar/a": (0, 1)},
        loop_age_s=lambda: 0.1,
        input_age_s=lambda: 0.1,
        state=lambda: ServiceState.RUNNING,
        uptime_s=lambda: 1.0,
        devices=lambda: {"dynamic-message-sign": DeviceLink(address="udp x:161", reachable=True)},
    )
    metrics = ServiceMetrics(view)
    metrics.processing.observe(0.01)
    text = generate_latest(metrics.registry).decode()
    return set(re.findall(r"^(wz_[a-z_]+)\{", text, re.MULTILINE))


def test_the_dashboard_queries_series_the_services_export() -> None:
    dashboard = json.loads((MONITORING / "grafana" / "dashboard.json").read_text())
    exprs = [t["expr"] for panel in dashboard["panels"] for t in panel["targets"]]
    names = set(re.findall(r"\b(wz_[a-z_]+)", " ".join(exprs)))
    groups = yaml.safe_load((MONITORING / "rules.yml").read_text())["groups"]
    rule_exprs = " ".join(rule["expr"] for group in groups for rule in group["rules"])
    names |= set(re.findall(r"\b(wz_[a-z_]*[a-z])(?![a-z_(])", rule_exprs))
    exported = exported_series()
    assert names and names <= exported, names - exported
    assert len({panel["id"] for panel in dashboard["panels"]}) == len(dashboard["panels"])


def scrape(port: int) -> str:
    response = httpx.get(f"http://127.0.0.1:{port}/metrics", timeout=5.0)
    response.raise_for_status()
    return response.text


@pytest.mark.xdist_group("stack")
def test_every_service_is_scraped_during_wz_up(tmp_path: Path) -> None:
    assert PROMETHEUS, "prometheus is missing: run deploy/host/bootstrap.sh (apt: prometheus)"
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    http_port = free_port()
    services = [s for s in select(None) if s.metrics_port is not None]
    assert {s.name for s in services} == {
        "simulator",
        "lidar-detector",
        "camera-detector",
        "fusion-tracker",
        "alert-service",
    }
    up = start_wz_up(tmp_path, endpoint, http_port)
    with running(up):
        texts: dict[str, str] = {}

        def all_working() -> bool:
            for spec in services:
                try:
                    text = scrape(spec.metrics_port or 0)
                except httpx.HTTPError:
                    return False
                texts[spec.name] = text
                if not re.search(r'wz_service_state\{[^}]*state="running"\} 1\.0', text):
                    return False
            # Data through the pipeline: the tracker and the alert service processed inputs.
            return all(
                re.search(r"wz_processing_seconds_count\{[^}]*\} [1-9]", texts[name])
                for name in ("lidar-detector", "fusion-tracker", "alert-service")
            )

        wait_for(all_working, 180.0, "every service's /metrics with data through the pipeline")
        for name, text in texts.items():
            assert f'service="{name}",site="us75-lincoln"' in text
            assert "wz_bus_published_total{" in text and "wz_loop_age_seconds{" in text
        assert re.search(
            r'wz_queue_depth\{[^}]*key="wz/us75-lincoln/tracks"', texts["alert-service"]
        )
        gateway = httpx.get(f"http://127.0.0.1:{http_port}/metrics", timeout=5.0)
        assert gateway.status_code == 200 and "wz_gateway_" in gateway.text

        # A real Prometheus on the shipped local config (the gateway on the test's port) with
        # the shipped rules: every target of the running stack up, the series queryable.
        config = (MONITORING / "prometheus-local.yml").read_text()
        config = config.replace(f"127.0.0.1:{GATEWAY_PORT}", f"127.0.0.1:{http_port}")
        config = config.replace(
            "rule_files: [rules.yml]", f"rule_files: [{MONITORING / 'rules.yml'}]"
        )
        (tmp_path / "prometheus.yml").write_text(config)
        web = free_port()
        prometheus = subprocess.Popen(
            [
                PROMETHEUS,
                f"--config.file={tmp_path / 'prometheus.yml'}",
                f"--storage.tsdb.path={tmp_path / 'tsdb'}",
                f"--web.listen-address=127.0.0.1:{web}",
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        api = f"http://127.0.0.1:{web}/api/v1"
        with running(prometheus):
            health: dict[str, str] = {}

            def scraped() -> bool:
                try:
                    reply = httpx.get(f"{api}/targets", timeout=5.0).json()
                except (httpx.HTTPError, ValueError):
                    return False
                for target in reply["data"]["activeTargets"]:
                    health[target["labels"]["instance"]] = target["health"]
                return bool(health) and "unknown" not in health.values()

            wait_for(scraped, 60.0, "Prometheus' first scrape of every target")
            # The compose file's healthcheck asks this URL of the real Prometheus.
            probe = COMPOSE["services"]["prometheus"]["healthcheck"]["test"]
            url = urllib.parse.urlsplit(probe[-1])
            assert url.path == "/-/healthy"
            assert httpx.get(f"http://127.0.0.1:{web}{url.path}", timeout=5.0).status_code == 200
            running_ports = {f"127.0.0.1:{s.metrics_port}" for s in services}
            running_ports.add(f"127.0.0.1:{http_port}")
            assert {i for i, h in health.items() if h == "up"} == running_ports, health
            # The optional services (drivers, device-driver) are not running: down, as they are.
            assert {i for i, h in health.items() if h == "down"} == {
                f"127.0.0.1:{s.metrics_port}" for s in STACK if s.optional
            }
            time.sleep(1.0)
            reply = httpx.get(
                f"{api}/query", params={"query": "count by (service) (wz_service_uptime_seconds)"}
            ).json()
            reported = {r["metric"]["service"] for r in reply["data"]["result"]}
            assert reported == {s.name for s in services}
            rules: list[dict[str, Any]] = []

            def evaluated() -> bool:  # every evaluation_interval (15 s): wait for the first
                rules[:] = httpx.get(f"{api}/rules").json()["data"]["groups"][0]["rules"]
                return all(rule["health"] != "unknown" for rule in rules)

            wait_for(evaluated, 60.0, "Prometheus' first evaluation of the rules")
            assert len(rules) == 6 and all(rule["health"] == "ok" for rule in rules), rules
