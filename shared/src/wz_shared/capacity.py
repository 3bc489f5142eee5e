"""The capacity of a work zone's lane closure, and traffic demand stated against it.

Whether a closure queues depends on demand relative to what the open lanes carry, not on
demand alone: 1800 veh/h is free flow where three lanes drop to two and a queue where two drop
to one. So the simulator and ``wz eval`` can take demand as a ratio of this capacity.

The capacity is the Highway Capacity Manual's for a short-term freeway work zone (HCM 2010,
Chapter 10, Equation 10-14, the form TRB's work-zone studies and most state guides use):

    c = (1600 + I - R) * f_HV * N      [veh/h]

- 1600 pc/h/ln: the base capacity of a short-term closure (Krammes and Lopez's field data);
- ``I``, ``R``: adjustments for work intensity and for a ramp within 500 ft of the closure,
  both 0 here (the generated sites have no ramps; the intensity is unknown, HCM's default);
- ``f_HV = 1 / (1 + P_T (E_T - 1))``: the heavy-vehicle factor, ``P_T`` the truck share and
  ``E_T`` = 1.5 passenger-car equivalents per truck (HCM 2010 Exhibit 11-10, level terrain);
- ``N``: the lanes open through the closure (the site's lanes less its closed one).

This is the field value a DOT plans with; what the simulation's drivers actually discharge at
the taper is measured and stated beside it in ``docs/sites.md``.
"""

from __future__ import annotations

from wz_shared.site import Site

#: Base capacity of a short-term freeway work-zone lane [pc/h/ln] (HCM 2010 Eq. 10-14).
BASE_CAPACITY_PCPHPL = 1600.0
#: Passenger-car equivalents of one truck on level terrain [-] (HCM 2010 Exhibit 11-10).
TRUCK_PCE = 1.5


def heavy_vehicle_factor(truck_share: float, truck_pce: float = TRUCK_PCE) -> float:
    """HCM's ``f_HV = 1 / (1 + P_T (E_T - 1))`` [-]."""
    if not 0.0 <= truck_share <= 1.0:
        raise ValueError(f"truck_share must be in [0, 1], got {truck_share}")
    if truck_pce < 1.0:
        raise ValueError(f"a truck is at least one passenger car, got E_T = {truck_pce}")
    return 1.0 / (1.0 + truck_share * (truck_pce - 1.0))


def open_lanes(site: Site) -> int:
    """Lanes open through the closure: the site's lanes less its one closed lane (a site has
    two lanes at least: :class:`~wz_shared.site.Site` refuses a one-lane "lane drop")."""
    return len(site.lanes) - 1


def closure_capacity_vph(site: Site, truck_share: float) -> float:
    """Vehicles an hour the closure's open lanes carry at capacity (HCM 2010 Eq. 10-14)."""
    return BASE_CAPACITY_PCPHPL * heavy_vehicle_factor(truck_share) * open_lanes(site)
