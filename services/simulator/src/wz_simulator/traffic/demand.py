"""Traffic demand: vehicle types by class and driver profile, and seeded departures.

Four SUMO vTypes: a passenger car and a semi-trailer truck, each driven by a NORMAL or an
AGGRESSIVE driver. The profiles differ in the car-following model (Krauss: desired speed,
braking, headway, imperfection) and in the LC2013 lane-change model:

- NORMAL drivers merge out of the closed lane over the advance-warning area. LC2013 makes an
  urgent strategic lane change when the lane ends within about ``lcStrategic * 10 s * speed``
  (plus two vehicle lengths and the queue ahead); drawn per vehicle in 0.8-3.0 that is some
  200-900 m before the taper end. Before that, LC2013 also moves a vehicle over whenever the
  other lane is no slower. They cooperate (``lcCooperative``) with merging vehicles and do not
  keep right by habit (``lcKeepRight`` 0: US two-lane highway traffic uses both lanes).
- AGGRESSIVE drivers drive some 25 % over the limit, brake harder, keep short headways, stay in
  the closed lane until late (``lcStrategic`` 0.35-0.6: some 100-200 m before the lane end at
  30 m/s), overtake eagerly (``lcSpeedGain`` high) and force their way in (``lcAssertive``
  high, ``lcImpatience``), but still merge before the lane ends. Their lane changes are
  quicker (``maxSpeedLat``).

SUMO sees a lane end kilometres ahead, which real drivers do not: the traffic world keeps a
vehicle's ``lcStrategic`` at -1 (no strategic changes) until it reaches the station where it
takes notice of the closure (``notice_fraction`` of the advance-warning area), then sets the
drawn value (see :mod:`wz_simulator.traffic.world`).

Departures are a Poisson process at the configured flow, steady or following a
:class:`DemandProfile` over time (a ramp that makes a queue form and dissolve): the unit
exponential draws are spent on the flow's running integral, so a steady profile gives exactly
the steady process's departures. Each vehicle's class, profile and entry lane are drawn from one
seeded random generator in a fixed order, so the same seed gives the same vehicles however the
departures are fetched (all at once, or in chunks).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from xml.etree import ElementTree as ET

import numpy as np

from wz_shared.messages import DriverProfile, VehicleClass

#: SUMO id of the one route every vehicle drives (the whole road).
ROUTE_ID = "road"


@dataclass(frozen=True)
class SpeedFactor:
    """Desired speed as a multiple of the limit: normal(mean, dev) clipped to [low, high] [-]."""

    mean: float
    dev: float
    low: float
    high: float

    def sumo(self) -> str:
        return f"normc({self.mean},{self.dev},{self.low},{self.high})"


@dataclass(frozen=True)
class VehicleTypeSpec:
    """One SUMO vType: body, dynamics and driving style.

    Attributes
    ----------
    type_id
        SUMO vType id, ``<class>_<profile>``.
    vehicle_class, driver_profile
        What the ground truth reports for vehicles of this type.
    length_m, width_m, height_m
        Body dimensions [m]; SUMO's position is the middle of the front bumper.
    min_gap_m
        Standstill gap to the leader [m].
    max_speed_mps
        Vehicle's own top speed [m/s] (a governed truck), whatever the speed factor.
    accel_mps2, decel_mps2, emergency_decel_mps2
        Maximum acceleration, comfortable and emergency deceleration [m/s^2].
    tau_s
        Desired time headway of the Krauss model [s].
    sigma
        Krauss driver imperfection in [0, 1] [-].
    speed_factor
        Desired speed over the lane's limit.
    lane_change
        LC2013 parameters (``lcCooperative``, ``lcSpeedGain`` ...) common to the type.
    lc_strategic_range
        ``lcStrategic`` is drawn per vehicle, uniform in this range [-]: how far ahead of the
        lane end (about ``lcStrategic * 10 s * speed``) the driver starts to merge. The vType
        carries the middle of the range.
    max_speed_lat_mps
        Largest lateral speed in a lane change [m/s] (SUMO ``maxSpeedLat``; sets how long a
        continuous lane change takes).
    sumo_vclass, gui_shape
        SUMO vehicle class and drawing shape.
    """

    type_id: str
    vehicle_class: VehicleClass
    driver_profile: DriverProfile
    length_m: float
    width_m: float
    height_m: float
    min_gap_m: float
    max_speed_mps: float
    accel_mps2: float
    decel_mps2: float
    emergency_decel_mps2: float
    tau_s: float
    sigma: float
    speed_factor: SpeedFactor
    lane_change: Mapping[str, float] = field(default_factory=dict)
    lc_strategic_range: tuple[float, float] = (1.0, 1.0)
    max_speed_lat_mps: float = 1.0
    sumo_vclass: str = "passenger"
    gui_shape: str = "passenger"

    def xml_attributes(self) -> dict[str, str]:
        """Attributes of the ``<vType>`` element."""
        attributes = {
            "id": self.type_id,
            "vClass": self.sumo_vclass,
            "guiShape": self.gui_shape,
            "length": f"{self.length_m}",
            "width": f"{self.width_m}",
            "height": f"{self.height_m}",
            "minGap": f"{self.min_gap_m}",
            "maxSpeed": f"{self.max_speed_mps}",
            "accel": f"{self.accel_mps2}",
            "decel": f"{self.decel_mps2}",
            "emergencyDecel": f"{self.emergency_decel_mps2}",
            "apparentDecel": f"{self.decel_mps2}",
            "tau": f"{self.tau_s}",
            "sigma": f"{self.sigma}",
            "speedFactor": self.speed_factor.sumo(),
            "carFollowModel": "Krauss",
            "laneChangeModel": "LC2013",
            "maxSpeedLat": f"{self.max_speed_lat_mps}",
            "lcStrategic": f"{sum(self.lc_strategic_range) / 2}",
        }
        attributes.update({name: f"{value}" for name, value in self.lane_change.items()})
        return attributes


#: Per-vehicle lcStrategic ranges: normal drivers start to merge some 200-900 m before the
#: lane end (the advance-warning area), aggressive ones some 100-200 m before it.
NORMAL_LC_STRATEGIC = (0.8, 3.0)
AGGRESSIVE_LC_STRATEGIC = (0.35, 0.6)
#: Drivers take notice of the closure somewhere in the first 60 % of the advance-warning area.
NOTICE_FRACTION_RANGE = (0.0, 0.6)


def _lane_change_normal() -> Mapping[str, float]:
    return MappingProxyType(
        {
            "lcCooperative": 1.0,
            "lcSpeedGain": 1.0,
            "lcKeepRight": 0.0,
            "lcAssertive": 1.0,
        }
    )


def _lane_change_aggressive() -> Mapping[str, float]:
    return MappingProxyType(
        {
            "lcCooperative": 0.3,
            "lcSpeedGain": 5.0,
            "lcKeepRight": 0.0,
            "lcAssertive": 3.0,
            "lcImpatience": 1.0,
        }
    )


def default_vehicle_types() -> dict[str, VehicleTypeSpec]:
    """The four vTypes: car and truck, each NORMAL and AGGRESSIVE, by type id."""
    normal_speed = SpeedFactor(mean=1.03, dev=0.05, low=0.90, high=1.15)
    aggressive_speed = SpeedFactor(mean=1.25, dev=0.07, low=1.12, high=1.45)
    types = [
        VehicleTypeSpec(
            type_id="car_normal",
            vehicle_class=VehicleClass.CAR,
            driver_profile=DriverProfile.NORMAL,
            length_m=4.6,
            width_m=1.8,
            height_m=1.5,
            min_gap_m=2.5,
            max_speed_mps=55.0,
            accel_mps2=2.6,
            decel_mps2=4.5,
            emergency_decel_mps2=8.0,
            tau_s=1.2,
            sigma=0.5,
            speed_factor=normal_speed,
            lane_change=_lane_change_normal(),
            lc_strategic_range=NORMAL_LC_STRATEGIC,
            max_speed_lat_mps=1.0,
        ),
        VehicleTypeSpec(
            type_id="car_aggressive",
            vehicle_class=VehicleClass.CAR,
            driver_profile=DriverProfile.AGGRESSIVE,
            length_m=4.6,
            width_m=1.8,
            height_m=1.5,
            min_gap_m=1.5,
            max_speed_mps=55.0,
            accel_mps2=3.5,
            decel_mps2=6.5,
            emergency_decel_mps2=9.0,
            tau_s=0.6,
            sigma=0.3,
            speed_factor=aggressive_speed,
            lane_change=_lane_change_aggressive(),
            lc_strategic_range=AGGRESSIVE_LC_STRATEGIC,
            max_speed_lat_mps=1.8,
        ),
        VehicleTypeSpec(
            type_id="truck_normal",
            vehicle_class=VehicleClass.TRUCK,
            driver_profile=DriverProfile.NORMAL,
            length_m=16.5,
            width_m=2.6,
            height_m=4.0,
            min_gap_m=3.0,
            max_speed_mps=33.5,  # governed at 75 mph
            accel_mps2=1.0,
            decel_mps2=3.5,
            emergency_decel_mps2=7.0,
            tau_s=1.5,
            sigma=0.5,
            speed_factor=normal_speed,
            lane_change=_lane_change_normal(),
            lc_strategic_range=NORMAL_LC_STRATEGIC,
            max_speed_lat_mps=0.8,
            sumo_vclass="truck",
            gui_shape="truck/semitrailer",
        ),
        VehicleTypeSpec(
            type_id="truck_aggressive",
            vehicle_class=VehicleClass.TRUCK,
            driver_profile=DriverProfile.AGGRESSIVE,
            length_m=16.5,
            width_m=2.6,
            height_m=4.0,
            min_gap_m=2.0,
            max_speed_mps=33.5,
            accel_mps2=1.3,
            decel_mps2=4.5,
            emergency_decel_mps2=7.5,
            tau_s=0.9,
            sigma=0.3,
            speed_factor=aggressive_speed,
            lane_change=_lane_change_aggressive(),
            lc_strategic_range=AGGRESSIVE_LC_STRATEGIC,
            max_speed_lat_mps=1.3,
            sumo_vclass="truck",
            gui_shape="truck/semitrailer",
        ),
    ]
    return {spec.type_id: spec for spec in types}


def type_id_for(vehicle_class: VehicleClass, driver_profile: DriverProfile) -> str:
    """vType id of a class and profile, e.g. ``car_aggressive``."""
    return f"{vehicle_class.value}_{driver_profile.value}"


def work_zone_tau_increase(
    vehicle_types: Mapping[str, VehicleTypeSpec],
    truck_share: float,
    aggressive_share: float,
    speed_mps: float,
    lane_capacity_vph: float,
) -> float:
    """The time headway every driver adds inside the work zone so that its lanes carry
    ``lane_capacity_vph`` (HCM's work-zone capacity) [s].

    A Krauss driver follows at ``tau + (length + minGap) / v`` seconds at speed ``v``; the
    fleet's mean of that, weighted by the class and profile shares, is the lane's mean headway
    at capacity. Real drivers keep longer headways through a work zone than on the open road
    (narrow lanes, workers, the merge): HCM's 1600 pc/h/ln against some 2300 on an open
    freeway. The increase closes the gap: ``3600 / capacity - mean headway`` (0 if the open-road
    headways already keep the flow under it). SUMO's driver imperfection (``sigma``) lowers the
    flow a little further; the simulated discharge is measured in ``docs/sites.md``.
    """
    if not speed_mps > 0.0 or not lane_capacity_vph > 0.0:
        raise ValueError("the zone's speed and lane capacity must be positive")
    mean_headway_s = 0.0
    for spec in vehicle_types.values():
        share = truck_share if spec.vehicle_class is VehicleClass.TRUCK else 1.0 - truck_share
        share *= (
            aggressive_share
            if spec.driver_profile is DriverProfile.AGGRESSIVE
            else 1.0 - aggressive_share
        )
        mean_headway_s += share * (spec.tau_s + (spec.length_m + spec.min_gap_m) / speed_mps)
    return max(0.0, 3600.0 / lane_capacity_vph - mean_headway_s)


@dataclass(frozen=True)
class DemandProfile:
    """Arrival flow over time: straight lines between knots, flat before the first and after
    the last.

    Attributes
    ----------
    knots
        ``(time [s], flow [veh/h])`` in increasing time, every flow positive.
    """

    knots: tuple[tuple[float, float], ...]

    def __post_init__(self) -> None:
        if not self.knots:
            raise ValueError("a demand profile needs at least one knot")
        times = [t for t, _ in self.knots]
        if any(b <= a for a, b in itertools.pairwise(times)):
            raise ValueError(f"demand profile times must increase, got {times}")
        for t, flow in self.knots:
            if not (math.isfinite(t) and math.isfinite(flow) and flow > 0.0):
                raise ValueError(f"demand profile knot ({t}, {flow}): flow must be positive")

    @classmethod
    def steady(cls, vehicles_per_hour: float) -> DemandProfile:
        return cls(((0.0, vehicles_per_hour),))

    @classmethod
    def ramp(
        cls,
        base_vph: float,
        peak_vph: float,
        start_s: float,
        rise_s: float,
        hold_s: float,
        fall_s: float,
    ) -> DemandProfile:
        """``base_vph`` until ``start_s``, up to ``peak_vph`` over ``rise_s``, held for
        ``hold_s``, back down over ``fall_s`` and ``base_vph`` after (a peak hour in brief)."""
        if min(rise_s, fall_s) <= 0.0 or hold_s < 0.0 or start_s < 0.0:
            raise ValueError("a ramp needs a start >= 0, rise and fall > 0 and a hold >= 0")
        times = [start_s, start_s + rise_s, start_s + rise_s + hold_s]
        times.append(times[-1] + fall_s)
        flows = [base_vph, peak_vph, peak_vph, base_vph]
        knots = [(t, f) for t, f in zip(times, flows, strict=True)]
        if hold_s == 0.0:
            del knots[2]
        return cls(tuple(knots))

    def vehicles_per_hour(self, t_s: float) -> float:
        """The flow at a time [veh/h]."""
        times = [t for t, _ in self.knots]
        flows = [f for _, f in self.knots]
        return float(np.interp(t_s, times, flows))

    def time_after(self, start_s: float, vehicles: float) -> float:
        """The time by which ``vehicles`` (expected arrivals, a float) have come after
        ``start_s``: the inverse of the flow's running integral [s]."""
        remaining = vehicles
        t = start_s
        for t_next, _ in (*self.knots, (math.inf, 0.0)):
            if t_next <= t:
                continue
            rate0 = self.vehicles_per_hour(t) / 3600.0
            if math.isinf(t_next):
                return t + remaining / rate0
            rate1 = self.vehicles_per_hour(t_next) / 3600.0
            span = t_next - t
            area = 0.5 * (rate0 + rate1) * span
            if area >= remaining:
                slope = (rate1 - rate0) / span
                if abs(slope) < 1e-12:
                    return t + remaining / rate0
                # rate0 dt + slope dt^2 / 2 = remaining, the root in [0, span]
                return t + (math.sqrt(rate0 * rate0 + 2.0 * slope * remaining) - rate0) / slope
            remaining -= area
            t = t_next
        raise AssertionError("unreachable: the last segment is open-ended")


@dataclass(frozen=True)
class DemandConfig:
    """How much traffic arrives and of what kind.

    Attributes
    ----------
    vehicles_per_hour
        Total arrival flow over all lanes [veh/h]; arrivals are Poisson.
    truck_share
        Fraction of trucks in [0, 1] [-].
    aggressive_share
        Fraction of aggressive drivers in [0, 1] [-], independent of the class.
    seed
        Seed of the random generator.
    entry_lanes
        Number of lanes at the entry; each vehicle's entry lane is drawn uniformly.
    profile
        The flow over time; None: ``vehicles_per_hour`` throughout.
    """

    vehicles_per_hour: float
    truck_share: float
    aggressive_share: float
    seed: int
    entry_lanes: int = 2
    profile: DemandProfile | None = None

    def __post_init__(self) -> None:
        if not self.vehicles_per_hour > 0.0:
            raise ValueError(f"vehicles_per_hour must be positive, got {self.vehicles_per_hour}")
        for name in ("truck_share", "aggressive_share"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"{name} must be in [0, 1], got {value}")
        if self.entry_lanes < 1:
            raise ValueError(f"entry_lanes must be at least 1, got {self.entry_lanes}")


@dataclass(frozen=True)
class Departure:
    """One planned vehicle: when, what and on which lane of the first edge it enters.

    Attributes
    ----------
    vehicle_id
        SUMO vehicle id (``v000042``).
    depart_s
        Planned departure time [s]; SUMO delays it while the entry is blocked.
    type_id
        vType id.
    depart_lane
        SUMO lane index on the first edge (0 rightmost).
    lc_strategic
        The driver's LC2013 ``lcStrategic`` [-] (merge eagerness).
    notice_fraction
        Where in the advance-warning area the driver takes notice of the closure, as a
        fraction of its length from its start [-] (drivers react to different signs).
    """

    vehicle_id: str
    depart_s: float
    type_id: str
    depart_lane: int
    lc_strategic: float
    notice_fraction: float


class DemandGenerator:
    """Seeded Poisson arrivals with drawn class, driver profile and entry lane.

    Parameters
    ----------
    config
        Flow, shares, seed and entry lanes.
    vehicle_types
        vTypes by id (default: :func:`default_vehicle_types`), for the lcStrategic ranges.

    Notes
    -----
    For each vehicle, in this order: headway from a unit exponential draw spent on the flow's
    running integral (Exp(mean 3600 / vehicles_per_hour s) when steady), truck with
    probability ``truck_share``, aggressive with probability ``aggressive_share``, entry lane
    uniform, lcStrategic uniform in the type's range, notice fraction uniform in
    ``NOTICE_FRACTION_RANGE``. :meth:`until` hands out departures in time order and remembers where it stopped.
    """

    def __init__(
        self, config: DemandConfig, vehicle_types: Mapping[str, VehicleTypeSpec] | None = None
    ) -> None:
        self.config = config
        self.vehicle_types = dict(vehicle_types or default_vehicle_types())
        self._rng = np.random.default_rng(config.seed)
        self._mean_headway_s = 3600.0 / config.vehicles_per_hour
        self._profile = config.profile
        self._count = 0
        self._pending = self._draw(0.0)

    def _draw(self, after_s: float) -> Departure:
        config = self.config
        if self._profile is None:
            depart_s = after_s + float(self._rng.exponential(self._mean_headway_s))
        else:
            depart_s = self._profile.time_after(after_s, float(self._rng.exponential(1.0)))
        is_truck = bool(self._rng.random() < config.truck_share)
        is_aggressive = bool(self._rng.random() < config.aggressive_share)
        lane = int(self._rng.integers(config.entry_lanes))
        type_id = type_id_for(
            VehicleClass.TRUCK if is_truck else VehicleClass.CAR,
            DriverProfile.AGGRESSIVE if is_aggressive else DriverProfile.NORMAL,
        )
        low, high = self.vehicle_types[type_id].lc_strategic_range
        departure = Departure(
            vehicle_id=f"v{self._count:06d}",
            depart_s=round(depart_s, 2),
            type_id=type_id,
            depart_lane=lane,
            lc_strategic=round(float(self._rng.uniform(low, high)), 3),
            notice_fraction=round(float(self._rng.uniform(*NOTICE_FRACTION_RANGE)), 3),
        )
        self._count += 1
        return departure

    def until(self, end_s: float) -> list[Departure]:
        """All departures not handed out yet with ``depart_s < end_s``, in time order."""
        departures: list[Departure] = []
        while self._pending.depart_s < end_s:
            departures.append(self._pending)
            self._pending = self._draw(self._pending.depart_s)
        return departures

    @property
    def next_depart_s(self) -> float:
        """Departure time of the next vehicle not handed out yet [s]."""
        return self._pending.depart_s


def write_routes(
    path: Path,
    route_edge_ids: Sequence[str],
    vehicle_types: Iterable[VehicleTypeSpec],
    departures: Iterable[Departure],
) -> Path:
    """Write a SUMO ``.rou.xml``: the vTypes, the one route and the planned vehicles.

    Vehicles depart at ``departSpeed="desired"`` (their desired speed on the first edge) on
    their drawn lane.
    """
    routes = ET.Element("routes")
    for spec in vehicle_types:
        ET.SubElement(routes, "vType", spec.xml_attributes())
    ET.SubElement(routes, "route", {"id": ROUTE_ID, "edges": " ".join(route_edge_ids)})
    for departure in departures:
        ET.SubElement(
            routes,
            "vehicle",
            {
                "id": departure.vehicle_id,
                "type": departure.type_id,
                "route": ROUTE_ID,
                "depart": f"{departure.depart_s:.2f}",
                "departLane": str(departure.depart_lane),
                "departSpeed": "desired",
            },
        )
    ET.indent(routes)
    path.parent.mkdir(parents=True, exist_ok=True)
    ET.ElementTree(routes).write(path, encoding="utf-8", xml_declaration=True)
    return path
