"""The fused track's errors by station from the mast, and the mast's stretch against the
approach (issue 40: speed held where the sensors hand over)."""

from __future__ import annotations

import math

import pytest

from wz_eval.by_station import StationBreakdown
from wz_shared.messages import DriverProfile, VehicleClass, VehicleTruth


def _vehicle(vehicle_id: str, station_m: float, speed_mps: float) -> VehicleTruth:
    return VehicleTruth(
        vehicle_id=vehicle_id,
        vehicle_class=VehicleClass.CAR,
        x_m=0.0,
        y_m=0.0,
        heading_rad=0.0,
        speed_mps=speed_mps,
        accel_mps2=0.0,
        driver_profile=DriverProfile.NORMAL,
        station_m=station_m,
        offset_m=0.0,
        lane_index=0,
        length_m=4.6,
        width_m=1.8,
        height_m=1.5,
    )


def test_the_mast_s_stretch_is_set_against_the_approach() -> None:
    breakdown = StationBreakdown(mast_station_m=1000.0)
    # Upstream beyond 50 m: speeds 0.4 m/s off; within 50 m either side: 1.0 m/s off; a
    # vehicle missed counts in its bin but has no speed error; one past 50 m downstream is in
    # neither figure.
    vehicles = [
        _vehicle("a", 880.0, 20.0),
        _vehicle("b", 930.0, 20.0),
        _vehicle("c", 970.0, 20.0),
        _vehicle("d", 1030.0, 20.0),
        _vehicle("e", 1080.0, 20.0),
        _vehicle("f", 990.0, 20.0),
    ]
    matched = [(i, v, 0.0, 0.1) for i, v in enumerate(vehicles[:5])]
    breakdown.add(vehicles, matched, [20.4, 19.6, 21.0, 19.0, 25.0])
    stretch = breakdown.mast_stretch()
    assert stretch["rmse_speed_mps"] == pytest.approx(1.0)
    assert stretch["approach_rmse_speed_mps"] == pytest.approx(0.4)
    assert stretch["ratio"] == pytest.approx(2.5)
    assert (stretch["samples"], stretch["approach_samples"]) == (2, 2)
    rows = {tuple(row["from_mast_m"]): row for row in breakdown.report()}
    assert rows[(-50.0, 0.0)]["missed_share"] == 0.5
    assert math.isclose(rows[(50.0, 100.0)]["rmse_speed_mps"], 5.0)


def test_no_approach_sample_gives_no_ratio() -> None:
    breakdown = StationBreakdown(mast_station_m=0.0)
    vehicle = _vehicle("a", 10.0, 20.0)
    breakdown.add([vehicle], [(0, vehicle, 0.0, 0.0)], [21.0])
    assert breakdown.mast_stretch()["ratio"] is None
