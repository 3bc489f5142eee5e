"""The site's upstream point speed sensors as SUMO induction loops (E1 detectors).

A :class:`wz_shared.site.PointSensor` is a side-fire radar or a loop station on its own trailer
upstream of the closure; in simulation one SUMO induction loop per lane stands in for it, at
the sensor's station on the lane's centre line. Every ``interval_s`` each loop gives the
vehicles that passed it, their mean speed and its occupancy (SUMO's ``getLastInterval*``), and
:meth:`PointLoops.readings` turns them into one
:class:`~wz_shared.messages.PointSensorReading` per sensor.

:func:`write_loops` writes the loops into an additional file for SUMO's ``--additional-files``
(loops cannot be added once the simulation runs); a lane's position is the sensor's station
less the edge's start, scaled by the lane's length in the built network over the edge's
station span (a lane on a curve is longer or shorter than the centre line).
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import libsumo

from wz_shared.messages import PointLaneReading, PointSensorReading
from wz_shared.site import Site
from wz_simulator.traffic.network import RoadNetwork

#: A loop stays this far inside its lane's ends [m] (SUMO refuses a loop past the lane's end).
LANE_END_MARGIN_M = 0.5


@dataclass(frozen=True)
class _Loop:
    loop_id: str
    site_lane: int


@dataclass
class _Station:
    sensor_id: str
    station_m: float
    interval_s: float
    loops: list[_Loop]
    next_s: float


def _lane_lengths(net_file: Path) -> dict[str, float]:
    """Every lane's length in the built network [m], by SUMO lane id."""
    lengths: dict[str, float] = {}
    for lane in ET.parse(net_file).getroot().iter("lane"):
        lengths[lane.attrib["id"]] = float(lane.attrib["length"])
    return lengths


def write_loops(site: Site, network: RoadNetwork, path: Path) -> list[_Station]:
    """Write one induction loop per lane of every point sensor of ``site`` into ``path`` (a
    SUMO additional file); the stations whose loops were written.

    Raises
    ------
    ValueError
        When a point sensor stands outside every edge of the network.
    """
    lengths = _lane_lengths(network.net_file)
    root = ET.Element("additional")
    stations: list[_Station] = []
    for sensor in site.point_sensors:
        edge = next(
            (e for e in network.edges if e.start_station_m <= sensor.station_m <= e.end_station_m),
            None,
        )
        if edge is None:
            raise ValueError(
                f"point sensor {sensor.sensor_id} at {sensor.station_m} m is on no road edge"
            )
        fraction = (sensor.station_m - edge.start_station_m) / (
            edge.end_station_m - edge.start_station_m
        )
        loops = []
        for lane_id, site_lane in zip(edge.lane_ids, edge.site_lanes, strict=True):
            length = lengths[lane_id]
            pos = min(max(fraction * length, LANE_END_MARGIN_M), length - LANE_END_MARGIN_M)
            loop_id = f"{sensor.sensor_id}__{site_lane}"
            ET.SubElement(
                root,
                "inductionLoop",
                id=loop_id,
                lane=lane_id,
                pos=f"{pos:.3f}",
                period=f"{sensor.interval_s:g}",
                file=os.devnull,
            )
            loops.append(_Loop(loop_id, site_lane))
        stations.append(
            _Station(
                sensor.sensor_id, sensor.station_m, sensor.interval_s, loops, sensor.interval_s
            )
        )
    path.parent.mkdir(parents=True, exist_ok=True)
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)
    return stations


class PointLoops:
    """The point sensors' loops of a running simulation; :meth:`readings` after each step."""

    def __init__(self, site_id: str, stations: list[_Station]) -> None:
        self.site_id = site_id
        self._stations = stations

    def readings(self, now_s: float) -> list[PointSensorReading]:
        """One reading per sensor whose interval ended at or before ``now_s`` (simulation
        time after the step) since the last call: the newest interval's (after steps taken
        without a call, as in a warm-up, the ones before it are gone, as SUMO keeps them)."""
        out = []
        for station in self._stations:
            if now_s + 1e-6 < station.next_s:
                continue
            ended_s = math.floor((now_s + 1e-6) / station.interval_s) * station.interval_s
            lanes = []
            for loop in station.loops:
                count = int(libsumo.inductionloop.getLastIntervalVehicleNumber(loop.loop_id))
                speed = float(libsumo.inductionloop.getLastIntervalMeanSpeed(loop.loop_id))
                occupancy = float(libsumo.inductionloop.getLastIntervalOccupancy(loop.loop_id))
                lanes.append(
                    PointLaneReading(
                        lane_index=loop.site_lane,
                        vehicle_count=count,
                        mean_speed_mps=speed
                        if count > 0 and speed >= 0.0 and math.isfinite(speed)
                        else None,
                        occupancy_percent=min(max(occupancy, 0.0), 100.0),
                    )
                )
            out.append(
                PointSensorReading(
                    site=self.site_id,
                    source_id=station.sensor_id,
                    stamp=ended_s,
                    station_m=station.station_m,
                    interval_s=station.interval_s,
                    lanes=lanes,
                )
            )
            station.next_s = ended_s + station.interval_s
        return out
