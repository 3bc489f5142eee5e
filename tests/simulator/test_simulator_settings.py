"""Simulator settings: env prefix WZ_SIM_, stack-wide site file, bounds."""

from __future__ import annotations

from pathlib import Path

import pytest
from pydantic import ValidationError

from wz_shared.site import DEFAULT_SITE_PATH
from wz_simulator.settings import SimulatorSettings


def test_defaults() -> None:
    settings = SimulatorSettings()
    assert settings.site_file == DEFAULT_SITE_PATH
    assert settings.step_s == 0.05
    assert settings.vehicles_per_hour == 1400.0
    assert (settings.truck_share, settings.aggressive_share) == (0.15, 0.15)
    assert settings.realtime_factor == 1.0 and settings.duration_s == 0.0


def test_environment(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("WZ_SIM_SEED", "7")
    monkeypatch.setenv("WZ_SIM_VEHICLES_PER_HOUR", "900")
    monkeypatch.setenv("WZ_SIM_REALTIME_FACTOR", "0")
    monkeypatch.setenv("WZ_SIM_WORK_DIR", str(tmp_path))
    monkeypatch.setenv("WZ_SITE_FILE", str(tmp_path / "site.yaml"))
    settings = SimulatorSettings()
    assert settings.seed == 7 and settings.vehicles_per_hour == 900.0
    assert settings.realtime_factor == 0.0
    assert settings.work_dir == tmp_path
    assert settings.site_file == tmp_path / "site.yaml"


def test_out_of_range_values_are_refused() -> None:
    with pytest.raises(ValidationError):
        SimulatorSettings(truck_share=1.5)
    with pytest.raises(ValidationError):
        SimulatorSettings(step_s=0.0)
