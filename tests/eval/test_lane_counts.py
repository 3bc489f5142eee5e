"""Lane volumes at the WZDx traffic detector, tracks against truth (``wz_eval.lane_counts``):
scripted vehicles crossing the gateway's detector station, counted with the gateway's own
crossing code; a missed vehicle and a vehicle put in the wrong lane show as errors per lane
even where the station total agrees."""

from __future__ import annotations

import pytest

from tests.alert_service.helpers import SITE, batch, make_track
from wz_eval.lane_counts import VOLUME_TOLERANCE, lane_volume_report
from wz_gateway.wzdx import detector_station_m, lane_order
from wz_shared.messages import DriverProfile, TrackBatch, VehicleClass, VehicleTruth

STATION = detector_station_m(SITE)
SPEED = 25.0
RIGHT, LEFT = 0, 1  # site lane indices (0 at the right)


def truth_vehicle(name: str, station_m: float, lane_index: int) -> VehicleTruth:
    lane = next(lane for lane in SITE.lanes if lane.index == lane_index)
    return VehicleTruth(
        vehicle_id=name,
        vehicle_class=VehicleClass.CAR,
        x_m=-lane.center_offset_m,
        y_m=station_m,
        heading_rad=1.5707963267948966,
        speed_mps=SPEED,
        accel_mps2=0.0,
        length_m=4.5,
        width_m=1.8,
        height_m=1.5,
        lane_index=lane_index,
        station_m=station_m,
        offset_m=lane.center_offset_m,
        driver_profile=DriverProfile.NORMAL,
    )


def scene(lanes: dict[int, int], track_lanes: dict[int, int] | None = None, missed: int = -1):
    """Vehicle k in lane ``lanes[k]`` starts 50 m + 20 k m before the detector; 20 s at 10 Hz.
    The tracks follow the truth, with ``track_lanes`` overriding a track's lane and vehicle
    ``missed`` not tracked."""
    track_lanes = track_lanes or {}
    truth, batches = [], []
    for step in range(200):
        t = 0.1 * step
        vehicles, tracks = [], []
        for k, lane_index in lanes.items():
            station = STATION - 50.0 - 20.0 * k + SPEED * t
            vehicles.append(truth_vehicle(f"veh{k}", station, lane_index))
            if k != missed:
                lane = track_lanes.get(k, lane_index)
                offset = next(x for x in SITE.lanes if x.index == lane).center_offset_m
                tracks.append(make_track(k + 1, station, SPEED, offset_m=offset, lane_index=lane))
        truth.append((t, vehicles))
        batches.append(batch(t, tracks, step))
    return truth, batches


def rows(report: dict) -> dict[int, dict]:
    return {row["lane_order"]: row for row in report["lanes"]}


def test_tracks_that_follow_the_truth_count_the_same_per_lane() -> None:
    lanes = {k: RIGHT if k % 3 else LEFT for k in range(12)}
    truth, batches = scene(lanes)
    report = lane_volume_report(SITE, batches, truth, 0.0, 19.9)
    by_lane = rows(report)
    right, left = by_lane[lane_order(SITE, RIGHT)], by_lane[lane_order(SITE, LEFT)]
    assert (right["truth_vehicles"], left["truth_vehicles"]) == (8, 4)
    assert (right["track_vehicles"], left["track_vehicles"]) == (8, 4)
    assert right["truth_volume_vph"] == pytest.approx(3600 * 8 / 19.9, abs=0.1)
    assert report["holds"] and report["station"]["volume_error"] == 0.0
    assert right["speed_difference_mps"] == pytest.approx(0.0, abs=1e-9)


def test_a_missed_vehicle_and_a_lane_error_show_per_lane() -> None:
    lanes = {k: RIGHT if k % 2 else LEFT for k in range(10)}  # 5 and 5
    truth, batches = scene(lanes, track_lanes={1: LEFT}, missed=2)
    report = lane_volume_report(SITE, batches, truth, 0.0, 19.9)
    by_lane = rows(report)
    right, left = by_lane[lane_order(SITE, RIGHT)], by_lane[lane_order(SITE, LEFT)]
    assert (right["truth_vehicles"], right["track_vehicles"]) == (5, 4)  # vehicle 1 moved
    assert (left["truth_vehicles"], left["track_vehicles"]) == (5, 5)  # +1 moved, -1 missed
    assert right["volume_error"] == pytest.approx(-0.2) and not right["holds"]
    assert left["volume_error"] == 0.0 and left["holds"]
    assert report["station"]["volume_error"] == pytest.approx(-0.1)
    assert not report["holds"] and VOLUME_TOLERANCE == 0.05
    # Nothing hid the right lane: its error is the tracker's, not the sight's.
    assert right["reliable"] and not report["off_lanes_marked"]


def test_a_lane_a_standing_truck_hides_is_marked_unreliable_and_left_out_of_the_target() -> None:
    """A semitrailer stands in the right lane 12 m past the loop, between it and the mast: the
    left lane's loop spot is hidden, two of its five vehicles are never tracked."""
    lanes = {k: RIGHT if k % 2 else LEFT for k in range(10)}
    truth, batches = scene(lanes)
    truck = make_track(99, STATION + 12.0, 0.0, length_m=16.0).model_copy(
        update={"object_class": VehicleClass.TRUCK, "width_m": 2.5}
    )
    kept = [
        b.model_copy(update={"tracks": [t for t in b.tracks if t.track_id not in (1, 5)] + [truck]})
        for b in batches
    ]
    report = lane_volume_report(SITE, kept, truth, 0.0, 19.9)
    by_lane = rows(report)
    right, left = by_lane[lane_order(SITE, RIGHT)], by_lane[lane_order(SITE, LEFT)]
    assert (left["truth_vehicles"], left["track_vehicles"]) == (5, 3)
    assert left["hidden_share"] == pytest.approx(1.0) and left["reliable"] is False
    assert right["hidden_share"] == 0.0 and right["reliable"] and right["holds"]
    assert report["holds"] and report["off_lanes_marked"]


def test_vehicles_outside_the_interval_are_not_counted() -> None:
    truth, batches = scene({0: RIGHT, 1: RIGHT})  # cross at 2.0 s and 2.8 s
    report = lane_volume_report(SITE, batches, truth, 2.5, 19.9)
    assert report["station"]["truth_vehicles"] == report["station"]["track_vehicles"] == 1
    empty: list[TrackBatch] = []
    assert lane_volume_report(SITE, empty, truth, 2.5, 19.9)["station"]["volume_error"] == -1.0
