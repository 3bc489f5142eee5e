"""``wz eval --mast-check``: a real mast's run held to the surveyed run's figures (issue 39)."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import pytest

from wz_eval.mast_check import check_pair, main


def _report(**changes: Any) -> dict[str, Any]:
    report: dict[str, Any] = {
        "site": "site-a",
        "mota": 0.97,
        "id_switches_per_100_vehicles": 0.5,
        "must_show": [
            {"check": "fused RMSE longitudinal within 150 m", "value": 0.20},
            {"check": "fused RMSE lateral within 150 m", "value": 0.08},
            {"check": "fused RMSE speed within 150 m", "value": 0.40},
        ],
        "alerts": {
            "speeding": {"precision": 1.0, "recall": 0.9},
            "intrusion": {"precision": None, "recall": None},
        },
        "mount_errors": None,
        "calibration": {},
    }
    report.update(changes)
    return report


def _displaced(**changes: Any) -> dict[str, Any]:
    report = _report(
        mount_errors={
            "sensors": {
                "cam": {"yaw_deg": 1.0, "pitch_deg": -0.5, "clock_offset_s": 0.08},
                "lidar": {"yaw_deg": -2.0, "pitch_deg": 0.3, "clock_offset_s": 0.0},
            }
        },
        calibration={
            "cam": {
                "sensor_kind": "camera",
                "correction": {"yaw_deg": 1.1, "pitch_deg": -0.45},
                "clock_offset_s": 0.07,
            },
            "lidar": {
                "sensor_kind": "lidar",
                "correction": {"yaw_deg": -1.95, "pitch_deg": 0.31},
                "clock_offset_s": 0.0,
            },
        },
    )
    report.update(changes)
    return report


def _failed(checks: list[dict[str, Any]]) -> set[str]:
    return {c["name"] for c in checks if c["holds"] is False}


def test_a_displaced_run_within_every_margin_holds() -> None:
    checks = check_pair(_report(), _displaced())
    assert _failed(checks) == set()
    names = {c["name"] for c in checks}
    assert "cam clock learned - drawn [s]" in names
    assert "lidar clock learned - drawn [s]" not in names  # the reference clock
    assert not any(name.startswith("intrusion") for name in names)  # undefined in both


def test_each_margin_fails_just_past_it() -> None:
    worse = _displaced(mota=0.94, id_switches_per_100_vehicles=1.6)
    worse["must_show"] = copy.deepcopy(worse["must_show"])
    worse["must_show"][0]["value"] = 0.23  # 0.20 * 1.1 = 0.22
    worse["alerts"] = {"speeding": {"precision": 0.94, "recall": 0.9}}
    worse["calibration"]["cam"]["correction"]["yaw_deg"] = 1.25
    worse["calibration"]["cam"]["clock_offset_s"] = 0.105
    assert _failed(check_pair(_report(), worse)) == {
        "fused RMSE longitudinal",
        "MOTA",
        "identity switches per 100 vehicles",
        "speeding precision",
        "cam yaw learned - drawn [deg]",
        "cam clock learned - drawn [s]",
    }


def test_the_command_line_exit_status(tmp_path: Path) -> None:
    surveyed, displaced = tmp_path / "s.json", tmp_path / "d.json"
    surveyed.write_text(json.dumps(_report()))
    displaced.write_text(json.dumps(_displaced()))
    out = tmp_path / "check.json"
    assert main(["--mast-check", str(surveyed), str(displaced), "--json", str(out)]) == 0
    assert json.loads(out.read_text())["site-a"]
    bad = _displaced(mota=0.5)
    displaced.write_text(json.dumps(bad))
    assert main(["--mast-check", str(surveyed), str(displaced)]) == 1
    # the second is not a real mast's run; a missing file
    assert main(["--mast-check", str(displaced), str(surveyed)]) == 2
    assert main(["--mast-check", str(tmp_path / "none.json"), str(displaced)]) == 2
    with pytest.raises(SystemExit):
        main(["--mast-check", str(surveyed)])
