"""SUMO traffic of a work-zone site: network, demand and the stepped world (no bus I/O)."""

from wz_simulator.traffic.demand import (
    DemandConfig,
    DemandGenerator,
    Departure,
    VehicleTypeSpec,
    default_vehicle_types,
)
from wz_simulator.traffic.network import RoadNetwork, build_network
from wz_simulator.traffic.world import TrafficCounters, TrafficWorld

__all__ = [
    "DemandConfig",
    "DemandGenerator",
    "Departure",
    "RoadNetwork",
    "TrafficCounters",
    "TrafficWorld",
    "VehicleTypeSpec",
    "build_network",
    "default_vehicle_types",
]
