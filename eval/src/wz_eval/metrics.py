"""Scoring estimates against simulation truth in the road frame.

Truth is known at every simulation step (20 Hz); an estimate stamped between steps is compared
with the truth moved to its stamp along each vehicle's heading at its speed (as the sensor rig
moves vehicles to a firing time; steps are 50 ms apart, so the error of that is millimetres).

Matching (:func:`match`): at one instant, estimates and the vehicles within range are paired by
the Hungarian algorithm on Euclidean distance, pairs farther than the gate forbidden. Errors are
``estimate - truth`` in the road frame: longitudinal (station) and lateral (offset), so a
positive longitudinal error is an estimate downstream of the vehicle.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from wz_shared.arrays import F64
from wz_shared.messages import VehicleTruth
from wz_shared.site import Site
from wz_simulator.sensors.rig import moved


class TruthIndex:
    """Truth by time: the vehicles at any stamp within the recorded span."""

    def __init__(self, truth: Sequence[tuple[float, list[VehicleTruth]]]) -> None:
        self._stamps = [stamp for stamp, _ in truth]
        self._vehicles = [vehicles for _, vehicles in truth]

    @property
    def span_s(self) -> tuple[float, float]:
        return (self._stamps[0], self._stamps[-1]) if self._stamps else (math.nan, math.nan)

    def at(self, stamp_s: float, max_gap_s: float = 0.06) -> list[VehicleTruth] | None:
        """The vehicles at ``stamp_s`` (nearest step, moved by the difference), or None when no
        step is within ``max_gap_s``."""
        if not self._stamps:
            return None
        i = bisect.bisect_left(self._stamps, stamp_s)
        candidates = [j for j in (i - 1, i) if 0 <= j < len(self._stamps)]
        j = min(candidates, key=lambda k: abs(self._stamps[k] - stamp_s))
        dt = stamp_s - self._stamps[j]
        if abs(dt) > max_gap_s:
            return None
        return moved(self._vehicles[j], dt)


def match(estimates_xy: F64, truth_xy: F64, gate_m: float) -> list[tuple[int, int]]:
    """Pairs ``(estimate index, truth index)`` minimising total distance, each within ``gate_m``."""
    if len(estimates_xy) == 0 or len(truth_xy) == 0:
        return []
    distance = np.hypot(
        estimates_xy[:, None, 0] - truth_xy[None, :, 0],
        estimates_xy[:, None, 1] - truth_xy[None, :, 1],
    )
    cost = np.where(distance <= gate_m, distance, 1e6)
    rows, cols = linear_sum_assignment(cost)
    return [(int(r), int(c)) for r, c in zip(rows, cols, strict=True) if distance[r, c] <= gate_m]


@dataclass
class AxisErrors:
    """Signed road-frame errors of one source, and its speed errors where it has speeds."""

    longitudinal: list[float] = field(default_factory=list)
    lateral: list[float] = field(default_factory=list)
    speed: list[float] = field(default_factory=list)
    matched: int = 0
    unmatched_estimates: int = 0
    missed_vehicles: int = 0

    def summary(self) -> dict[str, float | int | None]:
        def rmse(values: list[float]) -> float | None:
            return float(np.sqrt(np.mean(np.square(values)))) if values else None

        return {
            "rmse_longitudinal_m": rmse(self.longitudinal),
            "rmse_lateral_m": rmse(self.lateral),
            "rmse_speed_mps": rmse(self.speed),
            "bias_longitudinal_m": float(np.mean(self.longitudinal)) if self.longitudinal else None,
            "matched": self.matched,
            "unmatched_estimates": self.unmatched_estimates,
            "missed_vehicles": self.missed_vehicles,
        }


def in_range(
    site: Site, vehicles: Sequence[VehicleTruth], centre_xy: tuple[float, float], max_range_m: float
) -> list[VehicleTruth]:
    """The vehicles within ``max_range_m`` (ground distance) of ``centre_xy``."""
    return [
        v for v in vehicles if math.hypot(v.x_m - centre_xy[0], v.y_m - centre_xy[1]) <= max_range_m
    ]


def score_instant(
    site: Site,
    errors: AxisErrors,
    estimates: Sequence[tuple[float, float, float | None]],
    vehicles: Sequence[VehicleTruth],
    gate_m: float,
    time_offsets_s: Sequence[float | None] | None = None,
) -> list[tuple[int, VehicleTruth, float, float]]:
    """Match one instant's estimates ``(x, y, speed or None)`` to ``vehicles`` and add the errors.

    ``time_offsets_s``: per estimate, when it was captured after the instant (a LiDAR column's
    time); its matched vehicle is moved along its heading by that much before the errors are
    taken. Returns ``(estimate index, vehicle, longitudinal error, lateral error)`` per match.
    """
    est = np.array([(x, y) for x, y, _ in estimates], dtype=np.float64).reshape(-1, 2)
    tru = np.array([(v.x_m, v.y_m) for v in vehicles], dtype=np.float64).reshape(-1, 2)
    pairs = match(est, tru, gate_m)
    road = site.road_frame
    out = []
    for e, t in pairs:
        vehicle = vehicles[t]
        offset = time_offsets_s[e] if time_offsets_s is not None else None
        if offset:
            (vehicle,) = moved([vehicle], offset)
        s_est, d_est = road.to_road(est[e, 0], est[e, 1])
        s_true, d_true = road.to_road(vehicle.x_m, vehicle.y_m)  # truth moved to the stamp
        lon = float(s_est) - float(s_true)
        lat = float(d_est) - float(d_true)
        errors.longitudinal.append(lon)
        errors.lateral.append(lat)
        speed = estimates[e][2]
        if speed is not None:
            errors.speed.append(speed - vehicle.speed_mps)
        out.append((e, vehicle, lon, lat))
    errors.matched += len(pairs)
    errors.unmatched_estimates += len(estimates) - len(pairs)
    errors.missed_vehicles += len(vehicles) - len(pairs)
    return out
