"""The sight line from a sensor to a point and the vehicles in its way (wz_shared.occlusion)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wz_shared.occlusion import CLASS_HEIGHT_M, Boxes, hidden


def _boxes(*rows: tuple[float, float, float, float, float, str]) -> Boxes:
    if not rows:
        return Boxes.of([], [], [], [], [], [])
    x, y, heading, length, width, kind = zip(*rows, strict=True)
    return Boxes.of(x, y, heading, length, width, kind)


MAST = (0.0, 0.0, 8.0)  # a LiDAR 8 m up


def test_a_truck_near_the_target_hides_it_and_a_high_mast_sees_over_one_far_from_it() -> None:
    car_roof = [[40.0, 0.0, CLASS_HEIGHT_M["car"]]]
    # The sight line is 1.95 m up where it leaves a truck 3-5 m before the car: under its top.
    assert hidden(MAST, car_roof, _boxes((35.0, 0.0, 0.0, 4.5, 2.5, "truck")))[0]
    # Half-way the line is 4.4 m up where it leaves the truck: over its 4.1 m.
    assert not hidden(MAST, car_roof, _boxes((20.0, 0.0, 0.0, 4.5, 2.5, "truck")))[0]
    # A car there (1.5 m) hides nothing.
    assert not hidden(MAST, car_roof, _boxes((35.0, 0.0, 0.0, 4.5, 1.8, "car")))[0]


def test_boxes_beside_the_line_or_behind_the_target_do_not_hide_it() -> None:
    target = [[40.0, 0.0, 1.5]]
    beside = _boxes((35.0, 3.5, 0.0, 12.0, 2.5, "truck"))  # the next lane over
    behind = _boxes((48.0, 0.0, 0.0, 12.0, 2.5, "truck"))
    assert not hidden(MAST, target, beside)[0]
    assert not hidden(MAST, target, behind)[0]


def test_the_vehicle_at_the_target_does_not_hide_itself() -> None:
    assert not hidden(MAST, [[40.0, 0.0, 1.5]], _boxes((40.2, 0.1, 0.0, 16.0, 2.5, "truck")))[0]


def test_a_low_sensor_is_hidden_by_a_car_and_headings_turn_the_footprint() -> None:
    radar = (0.0, 0.0, 1.0)
    target = [[40.0, 0.0, 0.75]]
    assert hidden(radar, target, _boxes((20.0, 0.0, 0.0, 4.5, 1.8, "car")))[0]
    # A long truck 3 m to the side, along the road: clear; turned across the road: in the way.
    assert not hidden(radar, target, _boxes((20.0, 3.0, 0.0, 16.0, 2.5, "truck")))[0]
    assert hidden(radar, target, _boxes((20.0, 3.0, math.pi / 2, 16.0, 2.5, "truck")))[0]


def test_no_boxes_no_targets_and_unknown_sizes() -> None:
    assert hidden(MAST, [[40.0, 0.0, 1.5]], _boxes()).tolist() == [False]
    none = np.zeros((0, 3))
    assert hidden(MAST, none, _boxes((35.0, 0.0, 0.0, 4.5, 2.5, "truck"))).shape == (0,)
    box = _boxes((35.0, 0.0, 0.0, math.nan, math.nan, "tractor"))
    assert box.length_m[0] == 4.5 and box.width_m[0] == 1.8
    assert box.height_m[0] == CLASS_HEIGHT_M["unknown"]


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_agrees_with_points_sampled_along_the_sight_line(seed: int) -> None:
    """Against brute force: a sight line is hidden when one of 4000 points along it lies in a
    box below its top (boxes holding the target left out, as the module does)."""
    rng = np.random.default_rng(seed)
    n = 12
    boxes = Boxes.of(
        rng.uniform(5.0, 60.0, n),
        rng.uniform(-8.0, 8.0, n),
        rng.uniform(-0.3, 0.3, n),
        rng.uniform(4.0, 18.0, n),
        rng.uniform(1.7, 2.6, n),
        rng.choice(["car", "truck", "bus"], n),
    )
    sensor = np.array([0.0, -6.0, rng.uniform(1.0, 9.0)])
    targets = np.column_stack(
        [rng.uniform(10.0, 70.0, 300), rng.uniform(-8.0, 8.0, 300), rng.uniform(0.5, 2.0, 300)]
    )
    got = hidden(sensor, targets, boxes)
    u = np.linspace(0.0, 1.0, 4000)
    agree = 0
    for target, answer in zip(targets, got, strict=True):
        points = sensor + u[:, None] * (target - sensor)
        blocked = False
        for k in range(n):
            c, s = math.cos(boxes.heading_rad[k]), math.sin(boxes.heading_rad[k])
            dx, dy = points[:, 0] - boxes.x_m[k], points[:, 1] - boxes.y_m[k]
            along, across = c * dx + s * dy, -s * dx + c * dy
            inside = (np.abs(along) <= boxes.length_m[k] / 2) & (
                np.abs(across) <= boxes.width_m[k] / 2
            )
            tx, ty = target[0] - boxes.x_m[k], target[1] - boxes.y_m[k]
            holds = (abs(c * tx + s * ty) <= boxes.length_m[k] / 2 + 0.3) and (
                abs(-s * tx + c * ty) <= boxes.width_m[k] / 2 + 0.3
            )
            if not holds and np.any(inside & (points[:, 2] < boxes.height_m[k])):
                blocked = True
        agree += blocked == answer
    # Sampling misses lines that graze a corner by less than a step (1.5 cm): allow a couple.
    assert agree >= len(targets) - 2
    assert 10 < got.sum() < len(targets) - 10  # both answers are exercised
