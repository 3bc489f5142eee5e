"""A car that a truck hides from the sensors keeps its track (``max_occlusion_coast_s``,
``max_occlusion_memory_s``): the tracker asks whether other tracked vehicles stand in every
covering sensor's sight line to the track's predicted position (wz_shared.occlusion)."""

from __future__ import annotations

import numpy as np

from wz_fusion_tracker.settings import TrackerSettings
from wz_fusion_tracker.tracker import MultiTargetTracker
from wz_fusion_tracker.types import Measurement
from wz_shared.arrays import F64, Bool
from wz_shared.occlusion import Boxes, hidden

LIDAR = "lidar-mast"
COV = np.eye(2) * 0.01
SPEED = 5.0  # a queue creeping past the mast [m/s]
NEAR_Y, FAR_Y = 0.0, 3.6  # the truck's lane (nearer the mast) and the car's


def sensor_at(y_m: float):  # type: ignore[no-untyped-def]
    """The tracker's ``hidden_from_sensors`` for one LiDAR 5 m up at x = 0 and ``y_m``."""
    position = np.array([0.0, y_m, 5.0])

    def hidden_from_sensors(targets_m: F64, boxes: Boxes) -> Bool:
        return hidden(position, targets_m, boxes)

    return hidden_from_sensors


def run(mast_y_m: float, **changes: float) -> tuple[list[set[int]], int]:
    """A 16 m truck and a car beside it creep past a mast at 5 m/s, the car from x = -10 m;
    the car's detections stop for 1 <= t < 7.5 s (6.5 s: longer than the coast and the lost
    memory together), as the truck hides it from a mast on the truck's side. The published
    confirmed ids over time, and the car's id at the end."""
    tracker = MultiTargetTracker(
        TrackerSettings(reorder_window_s=0.0, **changes),
        heading_at=lambda x, y: 0.0,
        hidden_from_sensors=sensor_at(mast_y_m),
    )
    published: list[set[int]] = []
    for k in range(int(9.0 / 0.05)):
        t = 0.05 * k
        x = -10.0 + SPEED * t
        seen = [
            Measurement(
                x_m=x, y_m=NEAR_Y, covariance_m2=COV, object_class="truck", length_m=16.0,
                width_m=2.5,
            )
        ]  # fmt: skip
        if not 1.0 <= t < 7.5:
            seen.append(
                Measurement(
                    x_m=x, y_m=FAR_Y, covariance_m2=COV, object_class="car", length_m=4.5,
                    width_m=1.8,
                )
            )  # fmt: skip
        tracker.add(LIDAR, t, seen)
        published.append({s.track_id for s in tracker.tracks() if s.status != "tentative"})
    (car,) = [s for s in tracker.tracks() if abs(s.y_m - FAR_Y) < 1.0]
    return published, car.track_id


def test_a_car_the_truck_hides_keeps_its_id_by_coasting_then_by_memory() -> None:
    # Coasting up to 8 s: published all through, at its predicted place.
    published, car = run(-10.0, max_occlusion_coast_s=8.0)
    assert car == 2 and all(ids == {1, 2} for ids in published[20:])
    # Coasting 4 s, then remembered while hidden: unpublished for a while, the same id back.
    published, car = run(-10.0, max_occlusion_coast_s=4.0, max_occlusion_memory_s=12.0)
    assert car == 2 and {1} in published and set().union(*published) == {1, 2}


def test_without_it_or_with_the_mast_on_the_cars_side_the_car_comes_back_as_a_new_track() -> None:
    # Off: 1.5 s of coasting and 3 s of memory do not bridge 6.5 s.
    assert run(-10.0)[1] == 3
    # With the mast on the car's side the truck is behind the car and hides nothing: a missed
    # car is a car gone, and is not kept.
    assert run(13.6, max_occlusion_coast_s=8.0, max_occlusion_memory_s=12.0)[1] == 3
