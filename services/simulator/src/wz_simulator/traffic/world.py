"""The traffic world: a libsumo simulation of the site's lane drop, stepped for ground truth.

:class:`TrafficWorld` builds (or reuses) the site's SUMO network, writes the seeded demand, starts
libsumo and, on every :meth:`TrafficWorld.step`, advances SUMO by one step and returns the true
state of every vehicle on the road as :class:`~wz_shared.messages.VehicleTruth`.

Conversions from SUMO
---------------------
- SUMO's position is the middle of the front bumper and its angle is in degrees clockwise from
  north; the truth's ``heading_rad`` is counter-clockwise from east, ``pi/2 - radians(angle)``,
  and the truth position is the geometric centre, half a length behind the bumper along the
  heading. ``z_m`` is the centre's height above the (flat) road, ``height_m / 2``.
- ``station_m``/``offset_m`` come from the site's road frame (``site.road_frame.to_road``).
- ``lane_index`` is the *site* lane index of the SUMO lane the vehicle is on (after the lane
  drop, SUMO lane 0 of the one-lane edge is the site's open lane). Lane changes are continuous
  by default (the vehicle moves sideways at its vType's ``maxSpeedLat`` and its heading turns
  with it); SUMO switches ``lane_index`` half-way, when the centre crosses the lane line.

Demand and driver awareness
---------------------------
Departures come from the seeded :class:`~wz_simulator.traffic.demand.DemandGenerator`: the
first ``DEMAND_CHUNK_S`` go into the route file (``<work_dir>/run-*/demand.rou.xml``, next to
SUMO's warnings log), later chunks are added through libsumo shortly before they are due, so a
run with ``duration_s = 0`` goes on for ever. Each driver's ``lcStrategic`` stays -1 (unaware of
the closure) until the vehicle reaches its notice station in the advance-warning area.

Counters
--------
Collisions (distinct colliding pairs, physical contact only), teleports, departures, arrivals,
lane changes, and for every vehicle that leaves the closed lane upstream of its end the station
of its centre at that moment (its merge station).

One libsumo simulation per process: a second :class:`TrafficWorld` can only start after the
first is closed.
"""

from __future__ import annotations

import logging
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import libsumo
import numpy as np

from wz_shared.capacity import closure_capacity_vph, open_lanes
from wz_shared.messages import DriverProfile, PointSensorReading, VehicleClass, VehicleTruth
from wz_shared.site import AreaKind, Site
from wz_simulator.settings import SimulatorSettings
from wz_simulator.traffic.demand import (
    ROUTE_ID,
    DemandConfig,
    DemandGenerator,
    DemandProfile,
    Departure,
    VehicleTypeSpec,
    default_vehicle_types,
    work_zone_tau_increase,
    write_routes,
)
from wz_simulator.traffic.loops import PointLoops, write_loops
from wz_simulator.traffic.network import RoadNetwork, build_network

logger = logging.getLogger(__name__)

#: Departures are planned in chunks of this much simulated time [s]; the first chunk goes into
#: the route file, later ones are added through libsumo as the simulation gets near them.
DEMAND_CHUNK_S = 300.0
#: Later chunks are added this long before they start [s].
DEMAND_LOOKAHEAD_S = 30.0

_SUBSCRIBED = (
    libsumo.VAR_POSITION,
    libsumo.VAR_ANGLE,
    libsumo.VAR_SPEED,
    libsumo.VAR_ACCELERATION,
    libsumo.VAR_LANE_ID,
)

_active_world: TrafficWorld | None = None


#: Merges remembered per world (about 7 hours at 1400 veh/h).
MERGE_HISTORY = 10_000


@dataclass
class TrafficCounters:
    """Running totals of a traffic world.

    Attributes
    ----------
    departed, arrived
        Vehicles that entered / left the road.
    collisions
        Distinct pairs of vehicles that touched (SUMO collision, gap < 0).
    teleports
        Vehicles SUMO teleported because they were stuck (should stay 0).
    lane_changes
        Changes of site lane index, all vehicles.
    merge_station_m
        Per vehicle id, the station [m] of its centre when it last left the closed lane
        upstream of the closed lane's end (an aggressive driver may weave in and out; the last
        exit is its merge). The newest ``MERGE_HISTORY`` vehicles are kept.
    """

    departed: int = 0
    arrived: int = 0
    collisions: int = 0
    teleports: int = 0
    lane_changes: int = 0
    merge_station_m: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class _VehicleInfo:
    vehicle_class: VehicleClass
    driver_profile: DriverProfile
    length_m: float
    width_m: float
    height_m: float


def _set_lc_strategic(vehicle_id: str, lc_strategic: float) -> None:
    libsumo.vehicle.setParameter(vehicle_id, "laneChangeModel.lcStrategic", f"{lc_strategic}")


def demand_of(site: Site, settings: SimulatorSettings) -> tuple[float, DemandProfile | None]:
    """The settings' arrival flow [veh/h] (their ``demand_ratio`` of the closure's capacity,
    or ``vehicles_per_hour``) and its profile over time (None: steady)."""
    capacity_vph = closure_capacity_vph(site, settings.truck_share)
    flow_vph = settings.vehicles_per_hour
    if settings.demand_ratio is not None:
        flow_vph = settings.demand_ratio * capacity_vph
    if settings.demand_profile == "steady":
        return flow_vph, None
    profile = DemandProfile.ramp(
        base_vph=settings.ramp_base_ratio * capacity_vph,
        peak_vph=flow_vph,
        start_s=settings.ramp_start_s,
        rise_s=settings.ramp_rise_s,
        hold_s=settings.ramp_hold_s,
        fall_s=settings.ramp_fall_s,
    )
    return flow_vph, profile


def _sumo_binary() -> str:
    # libsumo only reads the first argument as a program name; no binary is run.
    return "sumo"


class TrafficWorld:
    """A SUMO (libsumo) simulation of a site's work-zone lane drop.

    Parameters
    ----------
    site
        The site: geometry, lanes, work zone and speed limits.
    settings
        Seed, step, demand (flow, truck and aggressive shares), continuous lane changes,
        teleport time and work folder.
    vehicle_types
        vTypes by id (default: :func:`default_vehicle_types`).

    Raises
    ------
    RuntimeError
        If another libsumo simulation is running in this process.
    """

    def __init__(
        self,
        site: Site,
        settings: SimulatorSettings,
        vehicle_types: dict[str, VehicleTypeSpec] | None = None,
    ) -> None:
        global _active_world
        if _active_world is not None or libsumo.simulation.isLoaded():
            raise RuntimeError(
                "a libsumo simulation is already running in this process; close it first "
                "(libsumo allows one simulation per process)"
            )
        self.site = site
        self.settings = settings
        self.vehicle_types = vehicle_types or default_vehicle_types()
        self.counters = TrafficCounters()
        self._step_index = 0
        self._closed = False

        work_dir = Path(settings.work_dir)
        self.network: RoadNetwork = build_network(site, work_dir)
        self._lane_site_index = self.network.lane_site_index()
        self._closed_lane = site.closed_lane_index
        self._closed_lane_end_m = self.network.closed_lane_end_station_m
        self._frame = site.road_frame

        flow_vph, profile = demand_of(site, settings)
        self._demand = DemandGenerator(
            DemandConfig(
                vehicles_per_hour=flow_vph,
                profile=profile,
                truck_share=settings.truck_share,
                aggressive_share=settings.aggressive_share,
                seed=settings.seed,
                entry_lanes=len(self.network.edges[0].site_lanes),
            ),
            self.vehicle_types,
        )
        # Work-zone headways: each vehicle's tau grows by the same increase at the taper.
        self._zone_tau: dict[str, float] = {}
        self._taper_start_m = math.inf
        self._outside_zone: dict[str, float] = {}  # vehicle id -> its tau in the zone [s]
        if settings.work_zone_headways:
            self._taper_start_m = site.area(AreaKind.TRANSITION).start_station_m
            increase_s = work_zone_tau_increase(
                self.vehicle_types,
                settings.truck_share,
                settings.aggressive_share,
                site.speed_limit_mps_at(site.area(AreaKind.TRANSITION).end_station_m),
                closure_capacity_vph(site, settings.truck_share) / open_lanes(site),
            )
            self._zone_tau = {
                type_id: spec.tau_s + increase_s for type_id, spec in self.vehicle_types.items()
            }
            logger.info("work-zone headways: every driver's tau +%.2f s from the taper", increase_s)
        # Drivers learn of the closure in the advance-warning area, each at its own station
        # (its sign): until then their lcStrategic is -1 (no strategic lane changes), then the
        # drawn value. Without this, SUMO's LC2013 sees the lane end from 3 km away and moves
        # vehicles over as soon as the other lane is a little faster.
        self._planned: dict[str, Departure] = {}
        # vehicle id -> (station where it takes notice [m], its lcStrategic)
        self._uninformed: dict[str, tuple[float, float]] = {}
        try:
            warning = site.area(AreaKind.ADVANCE_WARNING)
            self._warning_start_m = warning.start_station_m
            self._warning_length_m = warning.end_station_m - warning.start_station_m
        except KeyError:
            self._warning_start_m = self._warning_length_m = 0.0
        first_chunk_end_s = DEMAND_CHUNK_S
        if settings.duration_s > 0:
            first_chunk_end_s = min(first_chunk_end_s, settings.duration_s)
        self._demand_end_s = first_chunk_end_s
        # One folder per process and seed: the route file and SUMO's warnings, for inspection.
        run_dir = work_dir / f"run-{site.site_id}-seed{settings.seed}-pid{os.getpid()}"
        first_chunk = self._demand.until(first_chunk_end_s)
        self._planned.update((d.vehicle_id, d) for d in first_chunk)
        route_file = write_routes(
            run_dir / "demand.rou.xml",
            self.network.route_edge_ids,
            self.vehicle_types.values(),
            first_chunk,
        )

        self._info: dict[str, _VehicleInfo] = {}
        self._last_lane: dict[str, int] = {}
        self._collided_pairs: set[tuple[str, str]] = set()
        self._type_info = {
            type_id: _VehicleInfo(
                vehicle_class=spec.vehicle_class,
                driver_profile=spec.driver_profile,
                length_m=spec.length_m,
                width_m=spec.width_m,
                height_m=spec.height_m,
            )
            for type_id, spec in self.vehicle_types.items()
        }

        command = [
            _sumo_binary(),
            "--net-file",
            str(self.network.net_file),
            "--route-files",
            str(route_file),
            "--step-length",
            f"{settings.step_s}",
            "--seed",
            str(settings.seed),
            "--no-step-log",
            "true",
            "--duration-log.disable",
            "true",
            "--collision.action",
            "warn",
            "--collision.mingap-factor",
            "0",
            "--time-to-teleport",
            f"{settings.teleport_after_s if settings.teleport_after_s > 0 else -1}",
            # Any positive duration turns continuous lane changes on; each vType's maxSpeedLat
            # then sets how fast a vehicle moves sideways.
            "--lanechange.duration",
            "3" if settings.continuous_lane_changes else "0",
            # SUMO's warnings (emergency braking ...) go to a file, not to our stderr.
            "--error-log",
            str(run_dir / "sumo-warnings.log"),
            "--no-warnings",
            "true",
        ]
        # The site's upstream point speed sensors: one SUMO induction loop per lane each.
        self.point_loops: PointLoops | None = None
        if site.point_sensors:
            loops_file = run_dir / "point-loops.add.xml"
            stations = write_loops(site, self.network, loops_file)
            command += ["--additional-files", str(loops_file)]
            self.point_loops = PointLoops(site.site_id, stations)
        libsumo.start(command)
        _active_world = self
        logger.info(
            "traffic world started: site %s, seed %d, step %.3f s, %.0f veh/h (%s), %d edges",
            site.site_id,
            settings.seed,
            settings.step_s,
            flow_vph,
            settings.demand_profile,
            len(self.network.edges),
        )

    # --- properties ------------------------------------------------------------------------

    @property
    def sim_time_s(self) -> float:
        """Simulation time [s] after the last step."""
        return float(libsumo.simulation.getTime())

    @property
    def step_index(self) -> int:
        """Number of steps taken so far."""
        return self._step_index

    @property
    def finished(self) -> bool:
        """True once ``settings.duration_s`` (if not 0) has been simulated."""
        duration_s = self.settings.duration_s
        return duration_s > 0 and self.sim_time_s >= duration_s - 1e-9

    # --- stepping --------------------------------------------------------------------------

    def _top_up_demand(self, now_s: float) -> None:
        """Add the next chunk of departures through libsumo when it is near."""
        duration_s = self.settings.duration_s
        while now_s + DEMAND_LOOKAHEAD_S >= self._demand_end_s and (
            duration_s <= 0 or self._demand_end_s < duration_s
        ):
            chunk_end_s = self._demand_end_s + DEMAND_CHUNK_S
            if duration_s > 0:
                chunk_end_s = min(chunk_end_s, duration_s)
            for departure in self._demand.until(chunk_end_s):
                self._planned[departure.vehicle_id] = departure
                libsumo.vehicle.add(
                    departure.vehicle_id,
                    ROUTE_ID,
                    typeID=departure.type_id,
                    depart=f"{departure.depart_s:.2f}",
                    departLane=str(departure.depart_lane),
                    departSpeed="desired",
                )
            self._demand_end_s = chunk_end_s

    def step(self) -> list[VehicleTruth]:
        """Advance one simulation step and return every vehicle's true state.

        Returns
        -------
        list of VehicleTruth
            One per vehicle on the road after the step, in SUMO's subscription order.
        """
        if self._closed:
            raise RuntimeError("the traffic world is closed")
        self._top_up_demand(self.sim_time_s)
        libsumo.simulationStep()
        self._step_index += 1
        counters = self.counters

        for vehicle_id in libsumo.simulation.getDepartedIDList():
            libsumo.vehicle.subscribe(vehicle_id, _SUBSCRIBED)
            planned = self._planned.pop(vehicle_id, None)
            if planned is not None:
                notice_m = self._warning_start_m + planned.notice_fraction * self._warning_length_m
                if notice_m > 0.0:
                    self._uninformed[vehicle_id] = (notice_m, planned.lc_strategic)
                    _set_lc_strategic(vehicle_id, -1.0)
                else:
                    _set_lc_strategic(vehicle_id, planned.lc_strategic)
            type_id = libsumo.vehicle.getTypeID(vehicle_id)
            self._info[vehicle_id] = self._type_info[type_id]
            if type_id in self._zone_tau:
                self._outside_zone[vehicle_id] = self._zone_tau[type_id]
            counters.departed += 1
        arrived = libsumo.simulation.getArrivedIDList()
        for vehicle_id in arrived:
            self._info.pop(vehicle_id, None)
            self._last_lane.pop(vehicle_id, None)
            self._uninformed.pop(vehicle_id, None)
            self._outside_zone.pop(vehicle_id, None)
            counters.arrived += 1
        if arrived and self._collided_pairs:
            gone = set(arrived)
            self._collided_pairs = {
                pair for pair in self._collided_pairs if not gone.intersection(pair)
            }
        teleported = libsumo.simulation.getStartingTeleportIDList()
        if teleported:
            counters.teleports += len(teleported)
            logger.warning(
                "SUMO teleported %s at t=%.2f s (stuck longer than %.0f s)",
                ", ".join(teleported),
                self.sim_time_s,
                self.settings.teleport_after_s,
            )
        if libsumo.simulation.getCollidingVehiclesNumber():
            self._count_collisions()

        results = libsumo.vehicle.getAllSubscriptionResults()
        return self._truths(results)

    def _count_collisions(self) -> None:
        for collision in libsumo.simulation.getCollisions():
            pair = (collision.collider, collision.victim)
            if pair not in self._collided_pairs:
                self._collided_pairs.add(pair)
                self.counters.collisions += 1
                logger.warning(
                    "collision at t=%.2f s: %s (%.1f m/s) hit %s (%.1f m/s) on %s",
                    self.sim_time_s,
                    collision.collider,
                    collision.colliderSpeed,
                    collision.victim,
                    collision.victimSpeed,
                    collision.lane,
                )

    def _truths(self, results: dict[str, dict[int, object]]) -> list[VehicleTruth]:
        """Convert SUMO subscription results to truths, and update the lane counters."""
        if not results:
            return []
        ids = list(results)
        rows = [results[vehicle_id] for vehicle_id in ids]
        infos = [self._info[vehicle_id] for vehicle_id in ids]
        front = np.array([row[libsumo.VAR_POSITION] for row in rows], dtype=float)
        angle_deg = np.array([row[libsumo.VAR_ANGLE] for row in rows], dtype=float)
        length = np.array([info.length_m for info in infos])

        # SUMO angle: degrees clockwise from north; heading: radians counter-clockwise from
        # east, heading = pi/2 - angle, wrapped to (-pi, pi] by atan2.
        angle_rad = np.radians(angle_deg)
        heading = np.arctan2(np.cos(angle_rad), np.sin(angle_rad))
        # SUMO's position is the middle of the front bumper: the centre is half a length back.
        centre_x = front[:, 0] - 0.5 * length * np.cos(heading)
        centre_y = front[:, 1] - 0.5 * length * np.sin(heading)
        station, offset = self._frame.to_road(centre_x, centre_y)

        counters = self.counters
        closed = self._closed_lane
        merge_limit_m = self._closed_lane_end_m + 1.0
        lane_of = self._lane_site_index
        last_lane = self._last_lane
        uninformed = self._uninformed
        truths: list[VehicleTruth] = []
        for vehicle_id, row, info, x, y, h, s, d in zip(
            ids,
            rows,
            infos,
            centre_x.tolist(),
            centre_y.tolist(),
            heading.tolist(),
            station.tolist(),
            offset.tolist(),
            strict=True,
        ):
            lane_index = lane_of.get(row[libsumo.VAR_LANE_ID], -1)
            previous = last_lane.get(vehicle_id)
            if (
                previous is not None
                and previous != lane_index
                and previous >= 0
                and lane_index >= 0
            ):
                counters.lane_changes += 1
                if previous == closed and s <= merge_limit_m:
                    merges = counters.merge_station_m
                    merges.pop(vehicle_id, None)  # re-insert: the dict stays oldest-first
                    merges[vehicle_id] = s
                    if len(merges) > MERGE_HISTORY:  # a forever run must not grow without end
                        del merges[next(iter(merges))]
            last_lane[vehicle_id] = lane_index
            if s >= self._taper_start_m and (tau := self._outside_zone.pop(vehicle_id, None)):
                libsumo.vehicle.setTau(vehicle_id, tau)
            notice = uninformed.get(vehicle_id)
            if notice is not None and s >= notice[0]:
                _set_lc_strategic(vehicle_id, notice[1])
                del uninformed[vehicle_id]
            truths.append(
                VehicleTruth(
                    vehicle_id=vehicle_id,
                    vehicle_class=info.vehicle_class,
                    x_m=x,
                    y_m=y,
                    z_m=info.height_m / 2.0,
                    heading_rad=h,
                    speed_mps=max(0.0, row[libsumo.VAR_SPEED]),
                    accel_mps2=row[libsumo.VAR_ACCELERATION],
                    length_m=info.length_m,
                    width_m=info.width_m,
                    height_m=info.height_m,
                    lane_index=lane_index,
                    station_m=s,
                    offset_m=d,
                    driver_profile=info.driver_profile,
                )
            )
        return truths

    def point_readings(self) -> list[PointSensorReading]:
        """The point sensors' readings whose intervals ended by the last step (none without
        point sensors); call after each :meth:`step`."""
        if self.point_loops is None:
            return []
        return self.point_loops.readings(self.sim_time_s)

    # --- life cycle ------------------------------------------------------------------------

    def close(self) -> None:
        """Close libsumo; the world cannot step afterwards. Safe to call twice."""
        global _active_world
        if self._closed:
            return
        self._closed = True
        try:
            libsumo.close()
        finally:
            if _active_world is self:
                _active_world = None
        logger.info(
            "traffic world closed at t=%.1f s: %d departed, %d arrived, %d lane changes, "
            "%d collisions, %d teleports",
            self._step_index * self.settings.step_s,
            self.counters.departed,
            self.counters.arrived,
            self.counters.lane_changes,
            self.counters.collisions,
            self.counters.teleports,
        )

    def __enter__(self) -> TrafficWorld:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
