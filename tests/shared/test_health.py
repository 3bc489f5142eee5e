"""The heartbeat a container healthcheck reads: touched by a real service runtime on a real
bus, checked by the probe run as the healthcheck runs it."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from wz_shared.health import heartbeat_problem, main, touch
from wz_shared.service import ServiceRuntime
from wz_shared.settings import BusSettings, ServiceSettings


def probe(path: Path, max_age_s: float = 10.0) -> subprocess.CompletedProcess[str]:
    """The probe exactly as docker-compose.yml runs it."""
    return subprocess.run(
        [sys.executable, "-m", "wz_shared.health", str(path), "--max-age-s", str(max_age_s)],
        capture_output=True,
        text=True,
        timeout=30,
        check=False,
    )


def test_fresh_stale_and_missing(tmp_path: Path) -> None:
    beat = tmp_path / "run" / "health"
    assert "no heartbeat file" in (heartbeat_problem(beat, 10.0) or "")
    touch(beat)
    modified_s = beat.stat().st_mtime
    assert heartbeat_problem(beat, 10.0, now_s=modified_s + 9.9) is None
    problem = heartbeat_problem(beat, 10.0, now_s=modified_s + 12.0)
    assert problem is not None and "12.0 s old (limit 10 s)" in problem
    assert main([str(beat)]) == 0
    os.utime(beat, (modified_s - 60.0, modified_s - 60.0))
    assert main([str(beat), "--max-age-s", "30"]) == 1
    assert main([str(beat), "--max-age-s", "90"]) == 0


def test_runtime_touches_the_file_while_it_runs_and_removes_it_on_stop(tmp_path: Path) -> None:
    beat = tmp_path / "health"
    bus_settings = BusSettings(mode="peer", listen_endpoints=[], connect_endpoints=[])
    with ServiceRuntime(
        "health-test", "test-site", bus_settings, status_period_s=0.05, health_file=beat
    ):
        deadline = time.monotonic() + 10.0
        while not beat.exists() and time.monotonic() < deadline:
            time.sleep(0.01)
        assert beat.exists(), "no heartbeat within 10 s"
        first_s = beat.stat().st_mtime_ns
        deadline = time.monotonic() + 10.0
        while beat.stat().st_mtime_ns == first_s and time.monotonic() < deadline:
            time.sleep(0.01)
        assert beat.stat().st_mtime_ns > first_s, "the heartbeat is not renewed"
        healthy = probe(beat)
        assert healthy.returncode == 0, healthy.stderr
    assert not beat.exists()
    stopped = probe(beat)
    assert stopped.returncode == 1
    assert "unhealthy: no heartbeat file" in stopped.stderr


def test_without_a_health_file_nothing_is_written(tmp_path: Path) -> None:
    bus_settings = BusSettings(mode="peer", listen_endpoints=[], connect_endpoints=[])
    with ServiceRuntime("health-test", "test-site", bus_settings, status_period_s=0.05) as runtime:
        assert runtime.health_file is None
        assert not runtime.stop.wait(0.2)
    assert list(tmp_path.iterdir()) == []


def test_health_file_is_a_stack_wide_setting(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("WZ_HEALTH_FILE", "/tmp/wz-health")
    assert ServiceSettings().health_file == Path("/tmp/wz-health")
    monkeypatch.delenv("WZ_HEALTH_FILE")
    assert ServiceSettings().health_file is None
