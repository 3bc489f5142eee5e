"""What a site's sensors cover, for ``wz eval``'s report (:mod:`wz_shared.coverage` in the run's
weather): the covered share of the road inside the circle, up- and downstream of the mast, and
each sensor's reach along the road."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from wz_shared.arrays import F64
from wz_shared.coverage import SiteCoverage
from wz_shared.site import SensorMount, Site
from wz_simulator.sensors.lidar_physics import (
    LidarPhysics,
    fog_extinction_per_m,
    rain_extinction_per_m,
)
from wz_simulator.sensors.scene import WEATHER_PRESETS

#: Spacing of the road samples :func:`coverage_report` counts [m].
COVERAGE_STEP_M = 1.0


def weather_coverage(site: Site, weather: str) -> SiteCoverage:
    """What the site's sensors cover in the run's weather (:data:`WEATHER_PRESETS`): the
    LiDAR's extinction as the simulator computes it (fog and rain), the fog's visibility."""
    conditions = WEATHER_PRESETS[weather]
    physics = LidarPhysics()
    extinction = fog_extinction_per_m(
        conditions.fog_visibility_m, physics.wavelength_nm
    ) + rain_extinction_per_m(
        conditions.rain_mm_per_h,
        physics.rain_attenuation_db_per_km,
        physics.rain_attenuation_exponent,
    )
    return SiteCoverage(site, extinction, conditions.fog_visibility_m)


def coverage_report(
    coverage: SiteCoverage, centre: tuple[float, float], max_range_m: float
) -> dict[str, Any]:
    """How much of the road inside the circle the sensors cover: lane centres sampled every
    :data:`COVERAGE_STEP_M`, the covered share overall, up- and downstream of the mast, and
    each sensor's reach along the road."""
    site = coverage.site
    frame = site.road_frame
    mast_station = float(frame.to_road(*centre)[0])
    stations = np.arange(
        mast_station - max_range_m, mast_station + max_range_m + 1e-9, COVERAGE_STEP_M
    )
    lanes = [
        frame.to_site(stations, np.full_like(stations, lane.center_offset_m)) for lane in site.lanes
    ]
    inside_all: list[F64] = []
    seen_all: list[npt.NDArray[np.bool_]] = []
    for x, y in lanes:
        inside = np.hypot(x - centre[0], y - centre[1]) <= max_range_m
        inside_all.append(np.where(inside, stations - mast_station, np.nan))
        seen_all.append(inside & coverage(x, y))
    rel = np.concatenate(inside_all)
    seen = np.concatenate(seen_all)
    up = rel <= 0.0  # NaN (outside the circle) compares False both ways
    down = rel > 0.0

    def share(part: npt.NDArray[np.bool_]) -> float:
        return round(float(seen[part].sum() / max(1, part.sum())), 3)

    return {
        "covered_share": share(up | down),
        "covered_share_upstream": share(up),
        "covered_share_downstream": share(down),
        "per_sensor_reach_m": {
            m.sensor_id: _reach(coverage, m, lanes, stations, mast_station) for m in site.sensors
        },
    }


def _reach(
    coverage: SiteCoverage,
    mount: SensorMount,
    lanes: list[tuple[F64, F64]],
    stations: F64,
    mast_station: float,
) -> list[float] | None:
    """The stations (from the mast, [m]) between which ``mount`` covers some lane's centre
    (``lanes``: each lane centre's site x, y at ``stations``), or None where it covers none."""
    covered_at = np.zeros(stations.shape, dtype=bool)
    for x, y in lanes:
        covered_at |= coverage.sensor(mount, x, y)
    if not covered_at.any():
        return None
    rel = stations[covered_at] - mast_station
    return [round(float(rel.min()), 1), round(float(rel.max()), 1)]
