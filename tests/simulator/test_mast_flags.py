"""The real mast's flags (issue 39): the simulator's settings, ``wz up --mount-errors``,
``wz eval --mount-errors --bump``, the sites sweep and the report that states the draw."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from pydantic import ValidationError

from wz_cli.main import build_parser
from wz_cli.stack import StackOptions, select
from wz_eval import cli as eval_cli
from wz_eval.fusion import EvalOptions, _undisturbed_minutes, pipeline_options
from wz_eval.fusion_report import bump_lines, calibration_lines, mount_error_lines
from wz_eval.pipeline import PipelineOptions, run_pipeline
from wz_eval.sites import finished_report, plan_jobs
from wz_shared.site import Site
from wz_simulator.sensors.mast import Bump, MastModel
from wz_simulator.settings import SimulatorSettings


def test_settings_from_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("WZ_SIM_MOUNT_ERRORS", "true")
    monkeypatch.setenv("WZ_SIM_BUMP_SENSOR", "camera-mast")
    monkeypatch.setenv("WZ_SIM_BUMP_AT_S", "300")
    monkeypatch.setenv("WZ_SIM_BUMP_YAW_DEG", "-3")
    settings = SimulatorSettings()
    assert settings.mount_errors and settings.bump_sensor == "camera-mast"
    assert (settings.bump_at_s, settings.bump_yaw_deg) == (300.0, -3.0)


def test_a_bump_needs_the_mast_and_its_time() -> None:
    with pytest.raises(ValidationError, match="needs WZ_SIM_MOUNT_ERRORS"):
        SimulatorSettings(bump_sensor="camera-mast", bump_at_s=10.0)
    with pytest.raises(ValidationError, match="together"):
        SimulatorSettings(mount_errors=True, bump_sensor="camera-mast")
    with pytest.raises(ValidationError):
        SimulatorSettings(mount_errors=True, bump_sensor="camera-mast", bump_at_s=-1.0)


def test_wz_up_passes_the_flag_to_the_simulator_only(tmp_path: Path) -> None:
    assert build_parser().parse_args(["up", "--mount-errors"]).mount_errors is True
    assert build_parser().parse_args(["up"]).mount_errors is False
    assert build_parser().parse_args(["demo", "--mount-errors"]).mount_errors is True
    options = StackOptions("tcp/127.0.0.1:7999", tmp_path / "site.yaml", mount_errors=True)
    for spec in select(None):
        env = spec.child_env({}, options)
        assert ("WZ_SIM_MOUNT_ERRORS" in env) == (spec.name == "simulator")
    (simulator,) = select(["simulator"])
    assert simulator.child_env({}, options)["WZ_SIM_MOUNT_ERRORS"] == "true"
    plain = StackOptions("tcp/127.0.0.1:7999", tmp_path / "site.yaml")
    assert "WZ_SIM_MOUNT_ERRORS" not in simulator.child_env({}, plain)
    # Off by default, but the environment of wz up may still turn it on.
    assert simulator.child_env({"WZ_SIM_MOUNT_ERRORS": "true"}, plain)["WZ_SIM_MOUNT_ERRORS"]


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["--bump", "camera-mast@30"], "--bump needs --mount-errors"),
        (["--mount-errors", "--bump", "camera-mast"], "SENSOR@SECONDS"),
        (["--mount-errors", "--bump", "nowhere@30"], "has no sensor 'nowhere'"),
    ],
)
def test_wz_eval_refuses_a_bump_it_cannot_make(
    arguments: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as stopped:
        eval_cli.main([*arguments, "--out", "/nonexistent/never-written"])
    assert stopped.value.code == 2
    assert message in capsys.readouterr().err


def test_the_eval_options_reach_the_pipeline() -> None:
    assert PipelineOptions().mount_errors is False and EvalOptions().mount_errors is False
    bump = Bump.parse("radar-mast@120:1.5", after_s=60.0)
    options = pipeline_options(EvalOptions(seed=3, mount_errors=True, bump=bump))
    assert options.mount_errors and options.bump == Bump("radar-mast", 180.0, 1.5)


def test_the_pipeline_refuses_a_bump_without_the_mast(site: Site) -> None:
    with pytest.raises(ValueError, match="needs mount_errors"):
        run_pipeline(site, PipelineOptions(bump=Bump("camera-mast", 10.0)))


def test_the_report_states_the_draw(site: Site) -> None:
    drawn = MastModel.draw(site, 7, Bump("camera-mast", 360.0, 2.0)).describe()
    lines = "\n".join(mount_error_lines({"mount_errors": json.loads(json.dumps(drawn))}))
    for mount in site.sensors:
        yaw = drawn["sensors"][mount.sensor_id]["yaw_deg"]
        assert f"| {mount.sensor_id} | {yaw:+.2f} |" in lines
    assert "Bump: camera-mast turned +2.00 deg at simulation time 360 s" in lines
    assert mount_error_lines({"mount_errors": None}) == []
    assert mount_error_lines({}) == []


def test_the_sites_sweep_carries_the_flag_and_resumes_only_its_own_runs(tmp_path: Path) -> None:
    (plain,) = plan_jobs(1, 42, 300.0, 60.0, tmp_path, resume=True)
    (real,) = plan_jobs(1, 42, 300.0, 60.0, tmp_path, resume=True, mount_errors=True)
    assert not plain.mount_errors and real.mount_errors
    site_text = "site: the same\n"
    plain.out_dir.mkdir(parents=True)
    (plain.out_dir / "site.yaml").write_text(site_text, encoding="utf-8")
    report = {
        "seed": 42,
        "duration_s": 300.0,
        "warmup_s": 60.0,
        "conditions": {
            "weather": plain.weather,
            "vehicles_per_hour": plain.vehicles_per_hour,
            "truck_share": plain.truck_share,
        },
        "mount_errors": None,
    }
    (plain.out_dir / "eval.json").write_text(json.dumps(report))
    assert finished_report(plain, site_text) == report
    assert finished_report(real, site_text) is None  # a run without the errors is not its own
    with_errors = {**report, "mount_errors": {"sensors": {}, "masts": [], "bump": None}}
    (plain.out_dir / "eval.json").write_text(json.dumps(with_errors))
    assert finished_report(real, site_text) == with_errors
    assert finished_report(plain, site_text) is None


def test_the_report_sets_what_was_learned_beside_what_was_drawn(site: Site) -> None:
    drawn = json.loads(json.dumps(MastModel.draw(site, 7).describe()))
    camera = next(m.sensor_id for m in site.sensors if m.intrinsics.kind == "camera")
    truth = drawn["sensors"][camera]
    report = {
        "mount_errors": drawn,
        "calibration": {
            camera: {
                "sensor_kind": "camera",
                "state": "calibrated",
                "correction": {
                    "yaw_deg": truth["yaw_deg"] + 0.05,
                    "pitch_deg": 0.1,
                    "roll_deg": 0.0,
                    "x_m": 0.0,
                    "y_m": 0.0,
                    "z_m": 0.0,
                },
                "clock_offset_s": 0.081,
                "samples": 412,
            }
        },
    }
    lines = "\n".join(calibration_lines(report))
    assert (
        f"| {camera} | calibrated | {truth['yaw_deg'] + 0.05:+.2f} ({truth['yaw_deg']:+.2f}) |"
        in lines
    )
    assert f"+81 ({1000 * truth['clock_offset_s']:+.0f}) | 412 |" in lines
    # Without a real mast the learned values stand alone; without calibration, nothing.
    alone = "\n".join(calibration_lines({"calibration": report["calibration"]}))
    assert f"| {camera} | calibrated | {truth['yaw_deg'] + 0.05:+.2f} |" in alone
    assert calibration_lines({}) == []


def test_the_report_tells_the_bump() -> None:
    bump = {
        "sensor_id": "camera-mast",
        "at_s": 360.0,
        "yaw_deg": 2.0,
        "flagged_after_s": 4.0,
        "calibrated_again_after_s": 31.5,
        "false_alerts_minute_after": 1,
        "false_alerts_per_minute_before": 0.5,
        "false_alerts_by_undisturbed_minute": [0, 1, 0, 1, 3],
        "before": {
            "from_s": 60.0,
            "to_s": 360.0,
            "fused_rmse_longitudinal_m": 0.2,
            "fused_rmse_lateral_m": 0.1,
            "id_switches": 0,
            "false_alerts": 2,
        },
        "from_5_min_after": None,
    }
    lines = "\n".join(bump_lines({"bump": bump}))
    assert "Flagged after 4.0 s, calibrated again after 31.5 s" in lines
    assert (
        "False alerts in the minute after: 1 (before it: 0.50 a minute; the 5 other whole "
        "minutes: 1.00 a minute, 0 to 3)" in lines
    )
    assert "- before (60-360 s): fused RMSE 0.20 / 0.10 m, 0 identity switches" in lines
    assert bump_lines({"bump": None}) == []


def test_the_knocks_minute_is_compared_with_every_whole_undisturbed_minute() -> None:
    # Scored 120-600 s, knocked at 180 s: one whole minute before, six after the knock's.
    assert _undisturbed_minutes(180.0, 120.0, 600.0) == [
        120.0,
        240.0,
        300.0,
        360.0,
        420.0,
        480.0,
        540.0,
    ]
    # A minute cut by the run's start or end is not one.
    assert _undisturbed_minutes(150.0, 100.0, 260.0) == []
