"""Virtual loop detector: crossings interpolated exactly, each track once, counts against the
closed forms; and the pure cores import no I/O library."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.purity import top_level_imports
from wz_gateway import auth, export, models, traffic, wzdx
from wz_gateway.traffic import find_crossings, summarize


def test_crossing_is_interpolated_between_the_points_that_straddle_the_detector() -> None:
    # Track 7: 10 m/s from 90 m at t = 0 with points every 0.5 s; 100 m is passed at t = 1.0.
    # Track 3 accelerates: 95 m at 2.0 s (8 m/s), 105 m at 3.0 s (12 m/s): crossing at 2.5 s.
    rng = np.random.default_rng(1)
    rows = [(7, 0.5 * k, 90.0 + 5.0 * k, 0, 10.0, math.nan) for k in range(6)]
    rows += [(3, 2.0, 95.0, 1, 8.0, 4.0), (3, 3.0, 105.0, 1, 12.0, 4.0)]
    rows = [rows[i] for i in rng.permutation(len(rows))]  # order of storage is no guarantee
    ids, t, s, lane, v, length = (np.array(column) for column in zip(*rows, strict=True))
    crossings = find_crossings(ids, t, s, lane, v, length, detector_station_m=100.0)
    assert crossings.track_id.tolist() == [3, 7]
    assert crossings.stamp.tolist() == pytest.approx([2.5, 1.0])
    assert crossings.speed_mps.tolist() == pytest.approx([10.0, 10.0])
    assert crossings.lane_index.tolist() == [1, 0]
    assert crossings.length_m.tolist() == [4.0, traffic.DEFAULT_VEHICLE_LENGTH_M]


def test_a_track_counts_once_and_only_going_downstream() -> None:
    # Track 1 passes, backs up (a tracker glitch) and passes again: one crossing, the first.
    # Track 2 drives upstream (the other way): no crossing. Track 3 stops short of it.
    ids = [1, 1, 1, 1, 2, 2, 3, 3]
    t = [0.0, 1.0, 2.0, 3.0, 0.0, 1.0, 0.0, 1.0]
    s = [99.0, 101.0, 99.5, 100.5, 101.0, 99.0, 90.0, 99.9]
    crossings = find_crossings(ids, t, s, [0] * 8, [2.0] * 8, [5.0] * 8, 100.0)
    assert crossings.track_id.tolist() == [1]
    assert crossings.stamp.tolist() == pytest.approx([0.5])


def test_summary_against_the_closed_forms() -> None:
    crossings = traffic.Crossings(
        track_id=np.arange(4, dtype=np.int64),
        stamp=np.array([10.0, 20.0, 30.0, 400.0]),  # the last is after the interval
        lane_index=np.array([0, 0, 1, -1], dtype=np.int64),  # -1: on the shoulder
        speed_mps=np.array([20.0, 30.0, 25.0, 25.0]),
        length_m=np.array([4.5, 12.0, 4.5, 4.5]),
    )
    summary = summarize(crossings, 0.0, 60.0, [0, 1], detector_station_m=950.0, zone_length_m=2.0)
    right, left = summary.lanes
    assert (right.vehicles, left.vehicles, summary.vehicles) == (2, 1, 3)
    assert right.volume_vph == pytest.approx(120.0) and left.volume_vph == pytest.approx(60.0)
    assert right.average_speed_mps == pytest.approx(25.0)
    assert right.occupancy_percent == pytest.approx(100 * (6.5 / 20 + 14.0 / 30) / 60)
    assert left.occupancy_percent == pytest.approx(100 * (6.5 / 25) / 60)
    assert summary.volume_vph == pytest.approx(180.0)
    assert summary.average_speed_mps == pytest.approx(25.0)
    assert summary.occupancy_percent == pytest.approx(
        (right.occupancy_percent + left.occupancy_percent) / 2
    )
    with pytest.raises(ValueError, match="empty collection interval"):
        summarize(crossings, 5.0, 5.0, [0], 950.0)


def test_a_loop_counts_a_truck_split_in_two_tracks_once_and_close_cars_twice() -> None:
    """A trailer tracked apart from its cab crosses 0.32 s after it at 19 m/s (6 m behind its
    centre, inside the truck): the zone is still occupied, one presence. Two cars 1 s apart
    at the same speed leave the zone between them: two."""
    crossings = traffic.Crossings(
        track_id=np.arange(4, dtype=np.int64),
        stamp=np.array([10.0, 10.32, 20.0, 21.0]),
        lane_index=np.zeros(4, dtype=np.int64),
        speed_mps=np.array([19.0, 19.0, 19.0, 19.0]),
        length_m=np.full(4, traffic.DEFAULT_VEHICLE_LENGTH_M),  # lengths unknown
    )
    summary = summarize(crossings, 0.0, 60.0, [0], 950.0)
    assert summary.vehicles == 3 and summary.lanes[0].average_speed_mps == pytest.approx(19.0)
    # Occupied time: the truck's union [10 - 2.25/19, 10.32 + (2.25 + 1.83)/19], and the cars'.
    truck = (0.32 + (4.5 + 1.83) / 19) / 60
    cars = 2 * (4.5 + 1.83) / 19 / 60
    assert summary.lanes[0].occupancy_percent == pytest.approx(100 * (truck + cars))


@settings(max_examples=60, deadline=None)
@given(
    speeds=st.lists(st.floats(0.0, 60.0), min_size=0, max_size=40),
    duration_s=st.floats(1.0, 3600.0),
)
def test_summary_invariants(speeds: list[float], duration_s: float) -> None:
    n = len(speeds)
    crossings = traffic.Crossings(
        track_id=np.arange(n, dtype=np.int64),
        stamp=np.linspace(0.0, duration_s, n) if n else np.zeros(0),
        lane_index=np.zeros(n, dtype=np.int64),
        speed_mps=np.array(speeds, dtype=np.float64),
        length_m=np.full(n, 4.5),
    )
    summary = summarize(crossings, 0.0, duration_s, [0, 1], 950.0)
    # A presence holds the zone for (L + zone) / v: crossings closer than that are one vehicle.
    pace = np.maximum(np.array(speeds), traffic.MIN_OCCUPANCY_SPEED_MPS)
    apart = n < 2 or duration_s / (n - 1) > float(np.max((4.5 + 1.83) / pace))
    assert summary.vehicles <= n and (summary.vehicles == n or not apart)
    assert summary.volume_vph == pytest.approx(3600.0 * summary.vehicles / duration_s)
    for lane in summary.lanes:
        assert 0.0 <= lane.occupancy_percent <= 100.0
    assert summary.lanes[1].vehicles == 0 and summary.lanes[1].average_speed_mps is None


def test_pure_cores_import_no_io_library() -> None:
    io_libraries = {"zenoh", "fastapi", "starlette", "sqlalchemy", "uvicorn", "httpx", "requests"}
    for module in (traffic, wzdx, auth, export, models):
        assert not top_level_imports(module) & io_libraries, module.__name__
