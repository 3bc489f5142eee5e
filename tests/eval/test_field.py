"""Field validation on a synthetic drive: a van on a straight northbound road, GPS at 10 Hz, and
sources with a known clock offset, bias, noise, clutter and a known gap."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import wz_eval.field as field_module
from tests.purity import top_level_imports
from wz_drivers.gps import GpsTrack
from wz_eval.field import (
    FieldResult,
    FieldSettings,
    SourceObservations,
    associate,
    estimate_clock_offset,
    evaluate_field,
    markdown_table,
    plot_field,
)
from wz_shared.geometry import RoadFrame

T0 = 1_750_680_000.0
SPEED_MPS = 25.0
#: Station of the van at T0 [m]; the road runs north along x = 0, so station = y and
#: offset = -x; the van keeps to the right lane, x = 1.75 m.
START_M = 50.0
VAN_X_M = 1.75
ROAD = RoadFrame([(0.0, 0.0), (0.0, 2000.0)])


def van_y(t_rel_s: np.ndarray) -> np.ndarray:
    return START_M + SPEED_MPS * t_rel_s


def gps_truth(duration_s: float = 40.0, speed_mps: float = SPEED_MPS) -> GpsTrack:
    t_rel = np.arange(0.0, duration_s, 0.1)
    y = START_M + speed_mps * t_rel
    x = np.full_like(y, VAN_X_M)
    return GpsTrack(
        t=T0 + t_rel,
        x_m=x,
        y_m=y,
        station_m=y,
        offset_m=-x,
        speed_mps=np.full_like(y, speed_mps),
        heading_rad=np.full_like(y, np.pi / 2),
    )


def radar_camera(rng: np.random.Generator) -> SourceObservations:
    """Stamps 0.3 s ahead of GPS time; the van 0.2 m to the left of the truth; noise 0.3 m
    along and 0.1 m across the road; a car in the other lane and one pulling away ahead."""
    stamps_rel = 5.03 + 0.1 * np.arange(300)
    true_rel = stamps_rel - 0.3
    n = stamps_rel.size
    van_x = VAN_X_M - 0.2 + rng.normal(0.0, 0.1, n)  # offset + 0.2 m: to the left (west)
    van_yy = van_y(true_rel) + rng.normal(0.0, 0.3, n)
    other_lane_x = np.full(n, -1.75)
    other_lane_y = van_y(true_rel) + 2.0
    ahead_y = START_M + 30.0 + 30.0 * true_rel  # 30 m/s, from 30 m ahead
    times = np.concatenate([stamps_rel, stamps_rel, stamps_rel]) + T0
    return SourceObservations(
        times_s=times,
        x_m=np.concatenate([van_x, other_lane_x, np.full(n, VAN_X_M)]),
        y_m=np.concatenate([van_yy, other_lane_y, ahead_y]),
    )


def lidar(rng: np.random.Generator) -> SourceObservations:
    """On GPS time; no bias; noise 0.1 m; nothing strictly between 10 s and 12 s; the van's
    track id 7 before the gap and 9 after; a car in the other lane (id 3)."""
    stamps_rel = np.round(5.0 + 0.1 * np.arange(301), 10)
    stamps_rel = stamps_rel[(stamps_rel <= 10.0) | (stamps_rel >= 12.0)]
    n = stamps_rel.size
    ids = np.where(stamps_rel <= 10.0, 7, 9)
    return SourceObservations(
        times_s=np.concatenate([stamps_rel, stamps_rel]) + T0,
        x_m=np.concatenate([VAN_X_M + rng.normal(0.0, 0.1, n), np.full(n, -1.75)]),
        y_m=np.concatenate([van_y(stamps_rel) + rng.normal(0.0, 0.1, n), van_y(stamps_rel) - 1.0]),
        ids=np.concatenate([ids, np.full(n, 3)]),
    )


@pytest.fixture(scope="module")
def result() -> FieldResult:
    rng = np.random.default_rng(7)
    settings = FieldSettings(
        station_window_m=(START_M + 5.0 * SPEED_MPS, START_M + 35.0 * SPEED_MPS)
    )
    return evaluate_field(
        gps_truth(),
        {"radar-camera": radar_camera(rng), "lidar": lidar(rng)},
        ROAD,
        settings,
        clock_offsets_s={"lidar": 0.0},
    )


def test_clock_offset_recovered_and_errors_as_expected(result: FieldResult) -> None:
    radar = result.sources["radar-camera"]
    assert radar.clock.estimated
    assert radar.clock.offset_s == pytest.approx(0.3, abs=0.02)
    assert radar.clock.speed_mps == pytest.approx(SPEED_MPS)
    # The van's observations with true GPS times in [5, 35] s: 5.03 ... 34.63 s, 297 of 300.
    assert radar.longitudinal.count == radar.lateral.count == 297
    assert radar.lateral.mean_m == pytest.approx(0.2, abs=0.03)
    assert radar.lateral.rmse_m == pytest.approx(np.hypot(0.2, 0.1), abs=0.03)
    assert radar.longitudinal.mean_m == pytest.approx(0.0, abs=0.08)
    assert radar.longitudinal.rmse_m == pytest.approx(0.3, abs=0.05)
    assert radar.longitudinal.max_abs_m is not None and radar.longitudinal.p95_abs_m is not None
    assert radar.longitudinal.p95_abs_m == pytest.approx(1.96 * 0.3, rel=0.25)
    assert radar.longitudinal.max_abs_m < 3.0
    # Without the offset the van is 7.5 m from where the GPS puts it: outside the gate.
    assert radar.rmse_longitudinal_at_zero_offset_m is None


def test_association_takes_the_van_not_its_neighbours(result: FieldResult) -> None:
    lidar_result = result.sources["lidar"]
    assert lidar_result.clock.offset_s == 0.0 and not lidar_result.clock.estimated
    assert lidar_result.clock.note == "given"
    assert np.all(np.abs(lidar_result.association.lateral_error_m) < 0.6)
    assert lidar_result.lateral.rmse_m == pytest.approx(0.1, abs=0.02)
    assert lidar_result.distinct_ids == 2 and lidar_result.id_changes == 1
    assert np.all(np.diff(lidar_result.association.t_s) > 0.0)  # one per stamp, in order


def test_availability_and_longest_gap_exact(result: FieldResult) -> None:
    ((start, end),) = result.window_s
    assert (start, end) == pytest.approx((T0 + 5.0, T0 + 35.0), abs=1e-6)
    lidar_result = result.sources["lidar"]
    # Covered: [4.75, 10.25] and [11.75, 35.25] s, inside the 30 s window: 28.5 s.
    assert lidar_result.availability == pytest.approx(28.5 / 30.0, abs=1e-6)
    assert lidar_result.longest_gap_s == pytest.approx(2.0, abs=1e-6)
    radar = result.sources["radar-camera"]
    assert radar.availability is not None and radar.availability > 0.99


def test_default_window_spans_the_associations() -> None:
    rng = np.random.default_rng(3)
    outcome = evaluate_field(
        gps_truth(), {"lidar": lidar(rng)}, ROAD, clock_offsets_s={"lidar": 0.0}
    )
    assert outcome.station_window_m is not None
    low, high = outcome.station_window_m
    assert low == pytest.approx(START_M + 5.0 * SPEED_MPS)
    assert high == pytest.approx(START_M + 35.0 * SPEED_MPS)
    assert outcome.sources["lidar"].availability == pytest.approx(28.5 / 30.0, abs=1e-6)


def test_table_and_dict_render(result: FieldResult) -> None:
    table = markdown_table(result)
    assert table.startswith(
        "| source | samples | RMSE distance [m] | RMSE longitudinal [m] | RMSE lateral [m]"
    )
    rows = [line for line in table.splitlines() if line.startswith("| radar-camera |")]
    assert len(rows) == 1 and "+0.3" in rows[0]
    assert "| lidar | " in table and "(given)" in table and "95.0" in table
    assert "t - offset" in table
    summary = json.loads(json.dumps(result.to_dict(), allow_nan=False))
    radar = summary["sources"]["radar-camera"]
    assert radar["clock_offset_estimated"] is True
    assert {
        "rmse_longitudinal_m",
        "rmse_lateral_m",
        "bias_lateral_m",
        "p95_abs_lateral_m",
        "availability",
        "longest_gap_s",
        "clock_offset_s",
    } <= set(radar)
    assert summary["window_s"] == pytest.approx(30.0)


def test_a_source_that_never_sees_the_van(result: FieldResult) -> None:
    rng = np.random.default_rng(5)
    blind = SourceObservations(
        times_s=T0 + np.arange(5.0, 35.0, 0.1),
        x_m=np.full(300, -30.0),
        y_m=rng.uniform(0, 1000, 300),
    )
    outcome = evaluate_field(
        gps_truth(), {"lidar": lidar(rng), "blind": blind}, ROAD, clock_offsets_s={"lidar": 0.0}
    )
    row = outcome.sources["blind"]
    assert row.longitudinal.count == 0 and row.longitudinal.rmse_m is None
    assert not row.clock.estimated and "too few" in row.clock.note
    assert row.availability == 0.0 and row.longest_gap_s == pytest.approx(30.0)
    assert "| blind | 0 | - |" in markdown_table(outcome)


def test_offset_not_estimated_for_a_stopped_van() -> None:
    rng = np.random.default_rng(11)
    truth = gps_truth(duration_s=10.0, speed_mps=0.0)
    seen = SourceObservations(
        times_s=T0 + np.arange(1.0, 9.0, 0.1),
        x_m=VAN_X_M + rng.normal(0, 0.1, 80),
        y_m=START_M + rng.normal(0, 0.1, 80),
    )
    clock = estimate_clock_offset(truth, seen, ROAD)
    assert clock.offset_s == 0.0 and not clock.estimated and "speed" in clock.note
    assert len(associate(truth, seen, ROAD)) == 80


def test_plot_is_written(result: FieldResult, tmp_path: Path) -> None:
    path = plot_field(result, tmp_path / "field" / "field.png")
    assert path.stat().st_size > 10_000


def test_core_is_independent_of_drivers_and_middleware() -> None:
    assert not top_level_imports(field_module) & {"wz_drivers", "wz_simulator", "zenoh", "fastapi"}
