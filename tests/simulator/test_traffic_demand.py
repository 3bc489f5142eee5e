"""Seeded demand: reproducible, chunk-independent, with the configured flow and shares."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from wz_shared.messages import DriverProfile, VehicleClass
from wz_simulator.traffic.demand import (
    DemandConfig,
    DemandGenerator,
    DemandProfile,
    default_vehicle_types,
    type_id_for,
    work_zone_tau_increase,
    write_routes,
)

CONFIG = DemandConfig(vehicles_per_hour=1400.0, truck_share=0.15, aggressive_share=0.15, seed=3)


def test_same_seed_same_departures_however_fetched() -> None:
    whole = DemandGenerator(CONFIG).until(3600.0)
    chunked_generator = DemandGenerator(CONFIG)
    chunked = [d for end in (10.0, 300.0, 301.0, 3600.0) for d in chunked_generator.until(end)]
    assert whole == chunked
    other = DemandGenerator(DemandConfig(**{**CONFIG.__dict__, "seed": 4})).until(3600.0)
    assert other != whole


def test_flow_shares_and_lanes_match_the_config() -> None:
    hours = 20.0
    departures = DemandGenerator(CONFIG).until(hours * 3600.0)
    types = default_vehicle_types()
    assert len(departures) == pytest.approx(1400 * hours, rel=0.03)
    times = np.array([d.depart_s for d in departures])
    assert np.all(np.diff(times) >= 0.0)
    assert len({d.vehicle_id for d in departures}) == len(departures)
    trucks = np.mean([types[d.type_id].vehicle_class == VehicleClass.TRUCK for d in departures])
    aggressive = np.mean(
        [types[d.type_id].driver_profile == DriverProfile.AGGRESSIVE for d in departures]
    )
    assert trucks == pytest.approx(0.15, abs=0.01)
    assert aggressive == pytest.approx(0.15, abs=0.01)
    lanes = np.bincount([d.depart_lane for d in departures])
    assert lanes.size == 2 and abs(lanes[0] - lanes[1]) < 0.03 * len(departures)
    for departure in departures[:500]:
        low, high = types[departure.type_id].lc_strategic_range
        assert low <= departure.lc_strategic <= high
        assert 0.0 <= departure.notice_fraction <= 1.0


def test_vehicle_types_have_realistic_bodies_and_distinct_profiles() -> None:
    types = default_vehicle_types()
    car = types[type_id_for(VehicleClass.CAR, DriverProfile.NORMAL)]
    truck = types[type_id_for(VehicleClass.TRUCK, DriverProfile.NORMAL)]
    assert (car.length_m, car.width_m, car.height_m) == (4.6, 1.8, 1.5)
    assert (truck.length_m, truck.width_m, truck.height_m) == (16.5, 2.6, 4.0)
    assert truck.sumo_vclass == "truck"
    for vehicle_class in VehicleClass.CAR, VehicleClass.TRUCK:
        normal = types[type_id_for(vehicle_class, DriverProfile.NORMAL)]
        aggressive = types[type_id_for(vehicle_class, DriverProfile.AGGRESSIVE)]
        assert aggressive.speed_factor.mean >= normal.speed_factor.mean + 0.15
        assert aggressive.decel_mps2 > normal.decel_mps2
        assert aggressive.emergency_decel_mps2 > normal.emergency_decel_mps2
        assert aggressive.tau_s < normal.tau_s
        assert max(aggressive.lc_strategic_range) < min(normal.lc_strategic_range)
        assert aggressive.lane_change["lcAssertive"] > normal.lane_change["lcAssertive"]
        assert aggressive.lane_change["lcSpeedGain"] > normal.lane_change["lcSpeedGain"]


def test_route_file_lists_types_route_and_vehicles(tmp_path: Path) -> None:
    departures = DemandGenerator(CONFIG).until(120.0)
    path = write_routes(
        tmp_path / "d.rou.xml", ["e00", "e01"], default_vehicle_types().values(), departures
    )
    root = ET.parse(path).getroot()
    assert {t.attrib["id"] for t in root.iter("vType")} == {
        "car_normal",
        "car_aggressive",
        "truck_normal",
        "truck_aggressive",
    }
    assert root.find("route").attrib["edges"] == "e00 e01"  # type: ignore[union-attr]
    vehicles = root.findall("vehicle")
    assert [v.attrib["id"] for v in vehicles] == [d.vehicle_id for d in departures]
    assert all(v.attrib["departSpeed"] == "desired" for v in vehicles)


def test_bad_config_is_refused() -> None:
    with pytest.raises(ValueError, match="truck_share"):
        DemandConfig(vehicles_per_hour=100.0, truck_share=1.5, aggressive_share=0.1, seed=1)
    with pytest.raises(ValueError, match="vehicles_per_hour"):
        DemandConfig(vehicles_per_hour=0.0, truck_share=0.1, aggressive_share=0.1, seed=1)


def test_a_steady_profile_gives_exactly_the_steady_departures() -> None:
    steady = DemandGenerator(CONFIG).until(3600.0)
    profiled = DemandConfig(**{**CONFIG.__dict__, "profile": DemandProfile.steady(1400.0)})
    assert DemandGenerator(profiled).until(3600.0) == steady


def test_a_ramp_brings_the_flow_of_each_of_its_stretches() -> None:
    """Many seeds: the mean arrivals in each stretch of a ramp are its flow's integral."""
    ramp = DemandProfile.ramp(800.0, 2000.0, start_s=60.0, rise_s=30.0, hold_s=120.0, fall_s=30.0)
    assert ramp.vehicles_per_hour(0.0) == 800.0 and ramp.vehicles_per_hour(75.0) == 1400.0
    assert ramp.vehicles_per_hour(150.0) == 2000.0 and ramp.vehicles_per_hour(1e6) == 800.0
    # The running integral's inverse: 800 veh/h for 60 s is 13.33 vehicles; the rise adds 11.67.
    assert ramp.time_after(0.0, 800.0 / 60.0) == pytest.approx(60.0)
    assert ramp.time_after(0.0, 800.0 / 60.0 + 1400.0 / 120.0) == pytest.approx(90.0)
    assert ramp.time_after(200.0, 2000.0 / 360.0) == pytest.approx(210.0)
    stretches = {(0.0, 60.0): 800.0, (90.0, 210.0): 2000.0, (240.0, 600.0): 800.0}
    counts = dict.fromkeys(stretches, 0)
    seeds = 300
    for seed in range(seeds):
        config = DemandConfig(**{**CONFIG.__dict__, "seed": seed, "profile": ramp})
        times = np.array([d.depart_s for d in DemandGenerator(config).until(600.0)])
        for low, high in stretches:
            counts[(low, high)] += int(((times >= low) & (times < high)).sum())
    for (low, high), flow in stretches.items():
        expected = flow * (high - low) / 3600.0 * seeds
        assert counts[(low, high)] == pytest.approx(expected, rel=0.04), (low, high)


@pytest.mark.parametrize(
    "knots",
    [(), ((10.0, 100.0), (5.0, 100.0)), ((0.0, 0.0),), ((0.0, float("nan")),)],
)
def test_a_bad_profile_is_refused(knots: tuple[tuple[float, float], ...]) -> None:
    with pytest.raises(ValueError, match="demand profile"):
        DemandProfile(knots)


def test_work_zone_headways_bring_the_fleet_to_the_lane_capacity() -> None:
    types = default_vehicle_types()
    speed_mps, capacity_vph = 20.0, 1400.0
    increase_s = work_zone_tau_increase(types, 0.2, 0.15, speed_mps, capacity_vph)
    # The fleet's mean Krauss headway with the increase is 3600 / capacity.
    mean_s = 0.0
    for spec in types.values():
        share = 0.2 if spec.vehicle_class is VehicleClass.TRUCK else 0.8
        share *= 0.15 if spec.driver_profile is DriverProfile.AGGRESSIVE else 0.85
        mean_s += share * (spec.tau_s + increase_s + (spec.length_m + spec.min_gap_m) / speed_mps)
    assert mean_s == pytest.approx(3600.0 / capacity_vph)
    assert 0.5 < increase_s < 1.5  # a work zone's headway: some 2-2.5 s for a car
    # A capacity above what open-road headways carry (some 2300 veh/h) needs nothing added.
    assert work_zone_tau_increase(types, 0.2, 0.15, speed_mps, 3000.0) == 0.0
