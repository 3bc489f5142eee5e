"""Conflicts and SSAM's measures (:mod:`wz_gateway.conflicts`) on scripted near misses with
hand-computed values (:mod:`tests.gateway.conflict_scenes`), the types by angle and lane, the
neighbour search against brute force, and SSAM's CSV layout."""

from __future__ import annotations

import csv
import io
import math

import numpy as np
import pytest

from tests.gateway.conflict_scenes import (
    LENGTH_M,
    WIDTH_M,
    as_trajectories,
    crossing_rows,
    rear_end_rows,
)
from wz_gateway.conflicts import (
    SSAM_COLUMNS,
    ConflictSettings,
    classify,
    clock_angle,
    count_by_type,
    find_conflicts,
    near_pairs,
    ssam_csv,
    time_to_collision,
    trajectories,
)


def _state(x: float, y: float, vx: float, vy: float, heading: float) -> tuple[np.ndarray, ...]:
    return tuple(np.array([v]) for v in (x, y, vx, vy, heading, LENGTH_M, WIDTH_M))


def test_ttc_of_a_car_closing_on_another_in_its_lane() -> None:
    # 15 m bumper to bumper (centres 19.5 m apart), closing at 10 m/s: 1.5 s
    lead = _state(19.5, 0.0, 10.0, 0.0, 0.0)
    follower = _state(0.0, 0.0, 20.0, 0.0, 0.0)
    assert time_to_collision(follower, lead)[0] == pytest.approx(1.5, abs=1e-12)
    assert time_to_collision(lead, follower)[0] == pytest.approx(1.5, abs=1e-12)
    # the same speeds: never; side by side in the next lane (3.6 m): never
    assert math.isinf(time_to_collision(_state(0.0, 0.0, 10.0, 0.0, 0.0), lead)[0])
    assert math.isinf(time_to_collision(_state(19.5, 3.6, 20.0, 0.0, 0.0), lead)[0])
    # overlapping now: 0
    assert time_to_collision(_state(17.0, 0.5, 10.0, 0.0, 0.0), lead)[0] == 0.0


def test_ttc_uses_the_rectangles_corners() -> None:
    # crossing scene at t = 0: A's front reaches B's path (x = -0.9) at (17.75 - 2.25 - 0.9)/10
    a = _state(-17.75, 0.0, 10.0, 0.0, 0.0)
    b = _state(0.0, -17.25, 0.0, 10.0, math.pi / 2)
    assert time_to_collision(a, b)[0] == pytest.approx(1.46, abs=1e-12)
    # a car rotated 90 degrees is 1.8 m long along x: its side, not its 4.5 m, is hit
    side_on = _state(10.0, 0.0, 0.0, 0.0, math.pi / 2)
    car = _state(0.0, 0.0, 10.0, 0.0, 0.0)
    assert time_to_collision(car, side_on)[0] == pytest.approx((10.0 - 2.25 - 0.9) / 10.0)


def test_rear_end_near_miss_matches_the_hand_values() -> None:
    [conflict] = find_conflicts(as_trajectories(rear_end_rows()))
    assert (conflict.first_id, conflict.second_id) == ("lead", "follow")
    assert conflict.conflict_type == "rear end"
    # TTC(t) = (2 - t)/2 + 1/(2 - t): least sqrt(2) at 2 - sqrt(2) (the 0.05 s grid: 0.6 s)
    assert conflict.ttc_s == pytest.approx(math.sqrt(2.0), abs=2e-4)
    assert conflict.min_ttc_stamp == pytest.approx(2.0 - math.sqrt(2.0), abs=0.05)
    assert conflict.start_stamp == 0.0 and conflict.end_stamp == pytest.approx(1.0)
    assert conflict.pet_s == pytest.approx(0.5, abs=1e-6)  # 5 m at 10 m/s
    assert conflict.drac_mps2 == pytest.approx(10.0 / 3.0)  # 10^2 / (2 * 15) at t = 0
    assert conflict.max_speed_mps == pytest.approx(20.0)
    assert conflict.dr_mps2 == pytest.approx(-5.0) and conflict.max_d_mps2 == pytest.approx(-5.0)
    # at 0.6 s: 17 and 10 m/s; equal masses: post-crash 13.5 m/s, each changes by 3.5 m/s
    assert conflict.delta_speed_mps == pytest.approx(7.0)
    assert conflict.max_delta_v_mps == pytest.approx(3.5)
    assert conflict.conflict_angle_deg == 0.0 and conflict.clock_angle == "6:00"


def test_crossing_near_miss_matches_the_hand_pet() -> None:
    [conflict] = find_conflicts(as_trajectories(crossing_rows()))
    assert (conflict.first_id, conflict.second_id) == ("a", "b")
    assert conflict.conflict_type == "crossing"
    assert conflict.pet_s == pytest.approx(1.2, abs=1e-6)
    assert (conflict.min_pet_x_m, conflict.min_pet_y_m) == pytest.approx((0.0, 0.0), abs=1e-9)
    assert conflict.min_pet_stamp == pytest.approx(3.2, abs=1e-6)
    assert conflict.ttc_s <= 1.46 + 1e-9 and conflict.start_stamp == 0.0
    assert conflict.conflict_angle_deg == pytest.approx(90.0)
    assert conflict.clock_angle == "3:00"


def test_thresholds_are_parameters() -> None:
    data = as_trajectories(crossing_rows())
    assert find_conflicts(data, ConflictSettings(max_pet_s=1.0)) == []  # PET 1.2 s
    assert find_conflicts(data, ConflictSettings(max_ttc_s=0.5)) == []
    assert (
        len(find_conflicts(as_trajectories(rear_end_rows()), ConflictSettings(max_ttc_s=1.0))) == 0
    )


def _straight(
    name: str, x0: float, y: float, speed: float, heading: float, lane: int, n: int = 80
) -> list[tuple[str, float, float, float, float, float, float, int]]:
    c, s = math.cos(heading), math.sin(heading)
    return [
        (name, k * 0.05, x0 + speed * c * k * 0.05, y + speed * s * k * 0.05, speed * c,
         speed * s, heading, lane)
        for k in range(n)
    ]  # fmt: skip


@pytest.mark.parametrize(
    ("heading_deg", "expected"),
    [(10.0, "rear end"), (45.0, "lane change"), (80.0, "lane change"), (120.0, "crossing")],
)
def test_types_by_angle(heading_deg: float, expected: str) -> None:
    # B converges on A's path from its side at the given angle, lanes unknown; apart at the
    # start (a pair that overlaps when first seen together is one vehicle tracked twice)
    heading = math.radians(heading_deg)
    meet_s = 2.0
    a = _straight("a", -10.0 * meet_s, 0.0, 10.0, 0.0, -1)
    bx, by = -8.0 * meet_s * math.cos(heading), -8.0 * meet_s * math.sin(heading)
    b = _straight("b", bx, by, 8.0, heading, -1)
    [conflict] = find_conflicts(as_trajectories(a + b))
    assert conflict.conflict_type == expected
    assert abs(conflict.conflict_angle_deg) == pytest.approx(heading_deg, abs=1e-6)


def test_types_by_lane_come_first() -> None:
    settings = ConflictSettings()
    assert classify(10.0, (1, 1, 1, 1), settings) == "rear end"
    assert classify(10.0, (1, 0, 1, 1), settings) == "lane change"  # merged into its lane
    assert classify(10.0, (1, 1, 1, 2), settings) == "lane change"  # left it
    assert classify(10.0, (1, -1, 1, 1), settings) == "rear end"  # unknown: by angle
    assert classify(50.0, (1, 0, 1, 0), settings) == "lane change"
    assert classify(10.0, (1, 1, 1, 1), ConflictSettings(use_lanes=False)) == "rear end"
    assert classify(100.0, (0, 1, 0, 1), settings) == "crossing"


def test_pairs_that_never_conflict_give_nothing() -> None:
    rows = (
        _straight("ahead", 30.0, 0.0, 20.0, 0.0, 0)  # 25.5 m gap, the same speed
        + _straight("behind", 0.0, 0.0, 20.0, 0.0, 0)
        + _straight("beside", 0.0, 3.6, 25.0, 0.0, 1)  # the next lane, faster
        + _straight("away", -20.0, 0.0, 20.0, math.pi, 0)  # driving off the other way
    )
    assert find_conflicts(as_trajectories(rows)) == []
    assert find_conflicts(trajectories([], [], [], [], [], [], [])) == []
    # One vehicle alone: no pair to examine (this raised an IndexError).
    assert find_conflicts(as_trajectories(_straight("alone", 0.0, 0.0, 20.0, 0.0, 0))) == []
    # Vehicles never near each other at the same time: no pair either.
    far_apart = _straight("here", 0.0, 0.0, 20.0, 0.0, 0) + _straight(
        "there", 5000.0, 0.0, 20.0, 0.0, 0
    )
    assert find_conflicts(as_trajectories(far_apart)) == []


def test_near_pairs_match_brute_force() -> None:
    rng = np.random.default_rng(7)
    n = 600
    step = rng.integers(0, 5, n).astype(np.int64)
    x, y = rng.uniform(-400.0, 400.0, n), rng.uniform(-60.0, 60.0, n)
    vehicle = rng.permutation(n).astype(np.int64)
    i, j = near_pairs(step, x, y, vehicle, 40.0)
    found = {(int(a), int(b)) for a, b in zip(i, j, strict=True)}
    assert len(found) == len(i)  # each pair once
    expected = {
        (a, b)
        for a in range(n)
        for b in range(n)
        if step[a] == step[b]
        and vehicle[a] < vehicle[b]
        and math.hypot(x[a] - x[b], y[a] - y[b]) <= 40.0
    }
    assert found == expected and len(expected) > 100


def test_csv_is_ssams_table() -> None:
    conflicts = find_conflicts(as_trajectories(rear_end_rows() + crossing_rows()))
    assert count_by_type(conflicts) == {"rear end": 1, "lane change": 0, "crossing": 1}
    rows = list(csv.reader(io.StringIO(ssam_csv(conflicts, "scene"))))
    assert tuple(rows[0]) == SSAM_COLUMNS and len(SSAM_COLUMNS) == 44
    table = [dict(zip(rows[0], row, strict=True)) for row in rows[1:]]
    assert [row["FirstVID"] for row in table] == ["lead", "a"]  # by tMinTTC
    assert float(table[0]["TTC"]) == pytest.approx(math.sqrt(2.0), abs=1e-3)
    assert float(table[1]["PET"]) == pytest.approx(1.2, abs=1e-3)
    assert table[1]["ConflictType"] == "crossing" and table[0]["ConflictType"] == "rear end"
    assert table[0]["FirstLink"] == "1" and table[1]["FirstLink"] == "0"  # lanes unknown
    assert table[0]["zMinPET"] == "0" and table[0]["trjFile"] == "scene"


def test_many_vehicles_stay_fast_and_find_the_scripted_conflict() -> None:
    # 300 cars 40 m apart in three lanes at one speed, plus the rear-end scene off to the side
    rows = []
    for k in range(300):
        rows += _straight(f"car{k}", 40.0 * (k // 3), 3.6 * (k % 3) + 50.0, 25.0, 0.0, k % 3, 40)
    data = as_trajectories(rows + rear_end_rows(2.0))
    [conflict] = find_conflicts(data)
    assert conflict.second_id == "follow"


def test_sizes_default_and_speeds_give_the_acceleration() -> None:
    data = trajectories(["v", "v"], [0.0, 1.0], [0.0, 9.0], [0.0, 0.0], [8.0, 10.0], [0.0, 0.0],
                        [0.0, 0.0])  # fmt: skip
    assert np.isnan(data.length_m).all() and (data.lane_index == -1).all()
    assert clock_angle(-90.0) == "9:00" and clock_angle(180.0) == "12:00"


def test_a_track_born_overlapping_another_is_one_vehicle_not_a_conflict() -> None:
    # A semitrailer's trailer tracked apart from its cab: a second track 3 m behind the cab's
    # centre from its first point on, at the same speed, the two boxes (4.5 m cars' where the
    # length is unknown) overlapping: TTC 0 throughout.
    cab = _straight("cab", 0.0, 0.0, 20.0, 0.0, 0)
    trailer = _straight("trailer", -3.0, 0.0, 20.0, 0.0, 0)[10:]
    assert find_conflicts(as_trajectories(cab + trailer)) == []
    kept = find_conflicts(as_trajectories(cab + trailer), ConflictSettings(drop_twins=False))
    assert len(kept) == 1 and kept[0].ttc_s == 0.0
    # Born apart, then overlapping at the same speed (the trailer's track drifting onto the
    # cab's): one vehicle too.
    drifting = [
        (n, t, x + min(t, 1.0) * 2.0, y, vx, vy, h, lane)
        for n, t, x, y, vx, vy, h, lane in _straight("trailer", -9.0, 0.0, 20.0, 0.0, 0)
    ]
    assert find_conflicts(as_trajectories(cab + drifting)) == []
    # A car that comes up from apart into the cab's rear is a conflict.
    car = _straight("car", -30.0, 0.0, 30.0, 0.0, 0)
    [conflict] = find_conflicts(as_trajectories(cab + car))
    assert conflict.ttc_s < 1.5
