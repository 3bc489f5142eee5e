"""``wz eval`` and ``wz eval-camera`` end to end on a short simulated run (real SUMO, sensors,
detectors with the shipped camera model, tracker), through the ``wz`` command."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from wz_eval.fusion import Dropout, EvalOptions, pipeline_options
from wz_eval.scores import SOURCES
from wz_fusion_tracker.calibration import load_bias_map
from wz_gateway.conflicts import SSAM_COLUMNS
from wz_shared.capacity import closure_capacity_vph
from wz_shared.site import DEFAULT_SITE_PATH, load_site

ROOT = Path(__file__).resolve().parents[2]
BIAS_MAP = ROOT / "deploy" / "sites" / "us75-lincoln.bias-map.json"


def wz(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "wz_cli.main", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=900,
        check=False,
    )


def test_wz_eval_writes_the_report_json_markdown_and_plots(tmp_path: Path) -> None:
    out = tmp_path / "eval"
    result = wz(
        "eval",
        "--duration-s",
        "25",
        "--warmup-s",
        "45",
        "--seed",
        "3",
        "--max-range-m",
        "150",
        "--drop",
        "lidar-mast@10+2",
        "--json",
        str(tmp_path / "report.json"),
        "--out",
        str(out),
        "--bias-map",
        str(BIAS_MAP),
        "--write-bias-map",
        str(tmp_path / "measured.json"),
    )
    assert result.returncode == 0, result.stderr[-3000:]
    report = json.loads((tmp_path / "report.json").read_text())
    # The shipped map (seed 11) was applied; this run's own map written, both sensors in it.
    assert report["bias_map"] == load_bias_map(BIAS_MAP).source
    measured = load_bias_map(tmp_path / "measured.json")
    assert measured.source == "wz eval seed 3, 25 s"
    assert set(measured.sensors) == {"lidar-mast", "camera-mast"}
    assert all(cell.samples >= 30 for cells in measured.sensors.values() for cell in cells)
    for axis in ("rmse_longitudinal_m", "rmse_lateral_m", "rmse_speed_mps"):
        assert set(report[axis]) == set(SOURCES)
    assert report["vehicles"] >= 5
    capacity_vph = closure_capacity_vph(load_site(DEFAULT_SITE_PATH), 0.15)
    assert report["conditions"] == {
        "weather": "day",
        "vehicles_per_hour": 1400.0,
        "demand_ratio": None,
        "share_of_capacity": round(1400.0 / capacity_vph, 3),
        "capacity_vph": round(capacity_vph, 1),
        "demand_profile": "steady",
        "work_zone_headways": False,
        "truck_share": 0.15,
        "aggressive_share": 0.2,
    }
    assert 0.0 < report["mota"] <= 1.0 and 0.0 < report["idf1"] <= 1.0
    # Scored where a sensor sees a car; the whole circle alongside, with the coverage.
    assert report["scored_region"] == "covered"
    assert 0.0 < report["circle"]["mota"] <= 1.0
    circle, covered = report["circle"]["mot_detail"], report["mot_detail"]
    assert circle["vehicles_scored"] >= covered["vehicles_scored"]
    coverage = report["coverage"]
    assert coverage["covered_share_upstream"] > 0.95 > coverage["covered_share_downstream"]
    assert coverage["per_sensor_reach_m"]["camera-mast"][1] < 0.0  # it faces the approach
    assert report["id_switches"] >= 0
    # SSAM's conflicts on the tracks and the truth, by type, each table beside the report
    conflicts = report["conflicts"]
    for side in ("tracks", "truth"):
        assert set(conflicts[side]["by_type"]) == {"rear end", "lane change", "crossing"}
        assert sum(conflicts[side]["by_type"].values()) == conflicts[side]["count"]
        table = (out / conflicts["ssam_csv"][side]).read_text().splitlines()
        assert tuple(table[0].split(",")) == SSAM_COLUMNS
        assert len(table) == 1 + conflicts[side]["count"]
    fused = report["sources"]["fused"]
    assert fused["rmse_longitudinal_m"] < 1.5 and fused["rmse_lateral_m"] < 1.0
    assert report["rmse_speed_mps"]["fused"] < 2.0
    (dropout,) = report["dropouts"]
    assert (dropout["sensor_id"], dropout["start_s"], dropout["duration_s"]) == (
        "lidar-mast",
        10.0,
        2.0,
    )
    assert dropout["fused_samples"] > 0 and dropout["fused_rmse_longitudinal_m"] < 3.0
    assert dropout["id_switches_from_start_to_2s_after"] >= 0
    for row in report["paper_table"]:
        assert {
            "camera",
            "lidar",
            "average",
            "paper_kf",
            "fused",
            "fused_smoothed",
            "fused_stored",
        } <= set(row)
    # The two hindsight versions (RTS over each track's updates; the published states as the
    # gateway smooths them) are scored on the same vehicles as the live tracks, and hindsight
    # does not make them worse. (Before session 10 a track still lost when the run stopped was
    # not smoothed, and a resumed track was smoothed across its hand-over: 738 of 859 samples,
    # 0.36 / 0.38 m, on this run.)
    for hindsight in ("fused_smoothed", "fused_stored"):
        smoothed = report["sources"][hindsight]
        assert smoothed["matched"] >= 0.95 * fused["matched"], hindsight
        for axis in ("rmse_longitudinal_m", "rmse_lateral_m"):
            assert smoothed[axis] <= fused[axis] * 1.05, (hindsight, axis)
    # The same alerts, scored on the vehicles a sensor saw and on every vehicle in range.
    for key in ("alerts", "alerts_all_in_range"):
        assert {"speeding", "late_merge"} <= set(report[key])
    for alert_type, seen in report["alerts"].items():
        assert seen["alerts"] == report["alerts_all_in_range"][alert_type]["alerts"]
    # issue 6's targets, checked on the run: every one has a row, the dropout's included
    checks = {row["check"]: row for row in report["must_show"]}
    assert checks["MOTA"]["value"] == report["mota"]
    assert (
        checks["lidar-mast silent 2 s: identity switches to 2 s after"]["value"]
        == (dropout["id_switches_from_start_to_2s_after"])
    )
    assert sum(1 for check in checks if check.startswith("paper table")) == 3
    markdown = (out / "eval.md").read_text()
    assert "MOTA" in markdown and "| fused |" in markdown and "hidden ones included" in markdown
    assert "Issue 6's targets on this run" in markdown
    assert "Weather day, 1400 vehicles/h, 15 % trucks, 20 % aggressive." in markdown
    assert all((out / name).stat().st_size > 10_000 for name in report.get("plots", []))
    assert "simulating" in result.stderr  # the progress lines


def test_wz_eval_refuses_a_bad_bias_map_before_it_simulates(tmp_path: Path) -> None:
    bad = tmp_path / "bias.json"
    bad.write_text(BIAS_MAP.read_text().replace('"us75-lincoln"', '"elsewhere"'))
    result = wz("eval", "--bias-map", str(bad), "--out", str(tmp_path / "eval"))
    assert result.returncode == 2
    assert "for site 'elsewhere'" in result.stderr and "simulating" not in result.stderr


@pytest.mark.parametrize(
    ("arguments", "said"),
    [
        (["--duration-s", "-5"], "argument --duration-s: -5 is not above 0"),
        (["--duration-s", "nan"], "argument --duration-s: 'nan' is not a finite number"),
        (["--warmup-s", "-1"], "argument --warmup-s: -1 is below 0"),
        (["--max-range-m", "0"], "argument --max-range-m: 0 is not above 0"),
        (["--vehicles-per-hour", "lots"], "argument --vehicles-per-hour: 'lots' is not a number"),
        (["--truck-share", "1.5"], "argument --truck-share: 1.5 is not a share from 0 to 1"),
        (["--demand-ratio", "4"], "argument --demand-ratio: 4 is not a demand ratio above 0"),
        (["--demand-profile", "wave"], "argument --demand-profile: invalid choice"),
        (["--aggressive-share", "-0.1"], "-0.1 is not a share from 0 to 1"),
        (["--weather", "snow"], "argument --weather: invalid choice: 'snow'"),
        (["--site", "/nonexistent/site.yaml"], "cannot read site file /nonexistent/site.yaml"),
    ],
)
def test_wz_eval_refuses_bad_arguments_before_it_simulates(
    tmp_path: Path, arguments: list[str], said: str
) -> None:
    result = wz("eval", *arguments, "--out", str(tmp_path / "eval"))
    assert result.returncode == 2
    assert said in result.stderr and "Traceback" not in result.stderr
    assert "simulating" not in result.stderr and not (tmp_path / "eval").exists()


def test_the_conditions_asked_for_are_the_ones_simulated() -> None:
    options = EvalOptions(
        seed=5,
        duration_s=30.0,
        warmup_s=10.0,
        vehicles_per_hour=1800.0,
        weather="fog",
        truck_share=0.3,
        aggressive_share=0.1,
    )
    simulated = pipeline_options(options)
    assert (simulated.seed, simulated.duration_s, simulated.warmup_s) == (5, 30.0, 10.0)
    assert (simulated.weather, simulated.vehicles_per_hour) == ("fog", 1800.0)
    assert (simulated.truck_share, simulated.aggressive_share) == (0.3, 0.1)


def test_dropout_parsing() -> None:
    assert Dropout.parse("camera-mast@300+2.5") == Dropout("camera-mast", 300.0, 2.5)
    with pytest.raises(ValueError, match="SENSOR@START"):
        Dropout.parse("camera-mast:300")


def test_wz_eval_camera_gives_errors_by_distance_for_the_three_methods(tmp_path: Path) -> None:
    result = wz(
        "eval-camera",
        "--duration-s",
        "20",
        "--warmup-s",
        "45",
        "--seed",
        "4",
        "--out",
        str(tmp_path),
    )
    assert result.returncode == 0, result.stderr[-3000:]
    report = json.loads((tmp_path / "camera-eval.json").read_text())
    table = report["errors_by_range_m"]
    assert set(table) == {"paper_eq12", "calibrated", "camera_radar"}
    assert report["tracks_scored"] > 50
    assert table["calibrated"]["all"]["n"] == report["tracks_scored"]
    # The paper's ranging of the bottom edge puts approaching vehicles at their front face,
    # downstream of their centre (towards the camera).
    assert table["paper_eq12"]["all"]["bias_longitudinal_m"] > 0.5
    assert "| all |" in (tmp_path / "camera-eval.md").read_text()
    # The published image tracks against the rendered vehicles: the 10 fps camera has its
    # detector on every frame.
    images = report["image_tracks"]
    assert report["camera_fps"] == 10.0 and not report["every_frame"]
    assert images["vehicles"] > 50 and images["recall"] > 0.85 and images["precision"] > 0.75


def test_wz_eval_camera_at_30_fps_runs_the_detector_on_every_fourth_frame(tmp_path: Path) -> None:
    result = wz(
        "eval-camera",
        "--duration-s",
        "4",
        "--warmup-s",
        "45",
        "--seed",
        "4",
        "--camera-fps",
        "30",
        "--out",
        str(tmp_path),
    )
    assert result.returncode == 0, result.stderr[-3000:]
    report = json.loads((tmp_path / "camera-eval.json").read_text())
    # From 3 s before the scored 4 s, the detector on one frame in four.
    assert report["camera_fps"] == 30.0 and report["frames_processed"] > 190
    assert report["detector_runs"] / report["frames_processed"] == pytest.approx(0.25, abs=0.03)
    images = report["image_tracks"]
    assert images["vehicles"] > 60 and images["recall"] > 0.85 and images["precision"] > 0.75
    assert "Published image tracks (30 fps" in (tmp_path / "camera-eval.md").read_text()


def test_the_approach_is_upstream_of_the_mast_and_a_track_goes_where_its_vehicle_is() -> None:
    from types import SimpleNamespace

    from tests.eval.test_alerts_scoring import truth_at
    from wz_eval.fusion import approach_region
    from wz_shared.site import DEFAULT_SITE_PATH, load_site

    site = load_site(DEFAULT_SITE_PATH)  # straight road: station = y; the mast at 980 m
    vehicles = truth_at(0.0)  # at stations 400, 300 and 600 m
    vehicles[2] = vehicles[2].model_copy(update={"y_m": 980.5, "station_m": 980.5})
    states = [
        SimpleNamespace(x_m=1.83, y_m=401.0),  # A's track
        SimpleNamespace(x_m=1.83, y_m=978.5),  # C's track (C just downstream): C's side
        SimpleNamespace(x_m=1.83, y_m=1100.0),  # a false track downstream
        SimpleNamespace(x_m=1.83, y_m=700.0),  # a false track upstream
    ]
    kept_vehicles, kept_states = approach_region(site, vehicles, states, 980.0)  # type: ignore[arg-type]
    assert [v.vehicle_id for v in kept_vehicles] == ["A", "B"]
    assert [s.y_m for s in kept_states] == [401.0, 700.0]


def test_the_covered_region_leaves_out_what_no_sensor_sees_and_the_tracks_that_go_with_it() -> None:
    from types import SimpleNamespace

    from tests.eval.test_alerts_scoring import truth_at
    from wz_eval.fusion import scored_region
    from wz_shared.coverage import SiteCoverage, lidar_car_ranges_m
    from wz_shared.site import DEFAULT_SITE_PATH, load_site

    site = load_site(DEFAULT_SITE_PATH)  # straight road: station = y; the mast at 980 m
    mast = next(m for m in site.sensors if m.kind == "lidar")
    reach = lidar_car_ranges_m(mast)
    assert reach is not None and reach[1] < 140.0  # a 64-beam LiDAR 6 m up: about 131 m
    far = mast.pose.y_m + 145.0  # inside the 150 m circle, beyond where a car is sure to be hit
    vehicles = truth_at(0.0)[:2]  # at stations 400 and 300 m: moved into the circle
    vehicles[0] = vehicles[0].model_copy(update={"y_m": 900.0, "station_m": 900.0})
    vehicles[1] = vehicles[1].model_copy(update={"y_m": far, "station_m": far})
    states = [
        SimpleNamespace(x_m=vehicles[0].x_m, y_m=901.0),  # the covered vehicle's track
        SimpleNamespace(x_m=vehicles[1].x_m, y_m=far - 1.0),  # the unseen vehicle's track
        SimpleNamespace(x_m=vehicles[1].x_m, y_m=far + 3.5),  # a false track where none sees
        SimpleNamespace(x_m=vehicles[1].x_m, y_m=1000.0),  # a false track where the LiDAR sees
    ]
    centre = (mast.pose.x_m, mast.pose.y_m)
    circle = scored_region(vehicles, states, centre, 150.0)  # type: ignore[arg-type]
    assert len(circle[0]) == 2 and len(circle[1]) == 4
    kept_vehicles, kept_states = scored_region(
        vehicles,
        states,
        centre,
        150.0,
        SiteCoverage(site),  # type: ignore[arg-type]
    )
    assert [v.vehicle_id for v in kept_vehicles] == [vehicles[0].vehicle_id]
    assert [s.y_m for s in kept_states] == [901.0, 1000.0]
