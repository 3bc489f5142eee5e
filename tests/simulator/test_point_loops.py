"""The site's upstream point speed sensors as SUMO induction loops (wz_simulator.traffic.loops):
each interval's count and mean speed per lane are the vehicles that crossed the station in the
truth; a queue standing over a sensor reads as occupied; a site without point sensors has none."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from wz_shared.messages import PointSensorReading
from wz_shared.site import AreaKind, PointSensor, Site
from wz_simulator.settings import SimulatorSettings
from wz_simulator.traffic.world import TrafficWorld


def _run(site: Site, work_dir: Path, **settings: object) -> tuple[list, dict]:
    """The readings of a run, and per (station, lane) the truth's crossings (time, speed)."""
    stations = [p.station_m for p in site.point_sensors]
    readings: list[PointSensorReading] = []
    crossings: dict[tuple[float, int], list[tuple[float, float]]] = {}
    previous: dict[str, float] = {}
    values = {"seed": 3, "work_dir": work_dir, **settings}
    with TrafficWorld(site, SimulatorSettings(**values)) as world:  # type: ignore[arg-type]
        while not world.finished:
            for v in world.step():
                before = previous.get(v.vehicle_id)
                # SUMO's position is the front bumper: the loop sees the front cross it
                front = v.station_m + v.length_m / 2.0
                for s in stations:
                    if before is not None and before < s <= front:
                        crossings.setdefault((s, v.lane_index), []).append(
                            (world.sim_time_s, v.speed_mps)
                        )
                previous[v.vehicle_id] = front
            readings += world.point_readings()
    return readings, crossings


def test_each_interval_counts_the_vehicles_that_crossed_at_their_speed(
    site: Site, sim_work_dir: Path
) -> None:
    site = site.model_copy(
        update={
            "point_sensors": [
                PointSensor(sensor_id="speed-a", station_m=400.0, interval_s=30.0),
                PointSensor(sensor_id="speed-b", station_m=800.0, interval_s=20.0),
            ]
        }
    )
    readings, crossings = _run(site, sim_work_dir, duration_s=120.0, vehicles_per_hour=1800.0)
    by_sensor = {r.source_id: [] for r in readings}
    for r in readings:
        by_sensor[r.source_id].append(r.stamp)
    assert by_sensor == {
        "speed-a": [30.0, 60.0, 90.0, 120.0],
        "speed-b": [20.0 * k for k in range(1, 7)],
    }
    counted = 0
    for r in readings:
        assert sorted(lane.lane_index for lane in r.lanes) == [0, 1]
        for lane in r.lanes:
            crossed = [
                c
                for c in crossings.get((r.station_m, lane.lane_index), [])
                if r.stamp - r.interval_s < c[0] <= r.stamp + 1e-6
            ]
            # a crossing within a step of the interval's edge may fall on either side
            assert abs(lane.vehicle_count - len(crossed)) <= 1, (r, crossed)
            counted += lane.vehicle_count
            if lane.vehicle_count and len(crossed) == lane.vehicle_count:
                assert lane.mean_speed_mps == pytest.approx(
                    np.mean([c[1] for c in crossed]), abs=0.5
                )
            if lane.vehicle_count == 0:
                assert lane.mean_speed_mps is None
    assert counted >= 60  # 1800 veh/h for 2 minutes past two stations


def test_a_queue_over_a_sensor_reads_slow_or_occupied(site: Site, sim_work_dir: Path) -> None:
    """1.4 times the closure's capacity queues from the taper back over a sensor 150 m
    upstream of it: its open lane reads slow or, none passing, occupied."""
    taper_m = site.area(AreaKind.TRANSITION).start_station_m
    site = site.model_copy(
        update={
            "point_sensors": [
                PointSensor(sensor_id="near", station_m=taper_m - 150.0, interval_s=20.0)
            ]
        }
    )
    readings, _ = _run(
        site,
        sim_work_dir,
        duration_s=420.0,
        demand_ratio=1.4,
        work_zone_headways=True,
        truck_share=0.2,
    )
    open_lane = next(i for i in range(2) if i != site.closed_lane_index)
    # free once traffic reaches it (the road starts empty), queued at the end
    first = next(r for r in readings if r.stamp == 100.0).lanes[open_lane]
    last = readings[-1].lanes[open_lane]
    assert first.mean_speed_mps is not None and first.mean_speed_mps > 15.0, first
    assert (last.mean_speed_mps is not None and last.mean_speed_mps < 8.9) or (
        last.vehicle_count == 0 and last.occupancy_percent >= 50.0
    ), last


def test_no_point_sensors_no_readings(site: Site, sim_work_dir: Path) -> None:
    bare = site.model_copy(update={"point_sensors": []})
    readings, _ = _run(bare, sim_work_dir, duration_s=40.0)
    assert readings == []
