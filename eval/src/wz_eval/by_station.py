"""The fused track's figures by where the vehicle is: station relative to the mast.

The sensors of a work-zone trailer face the approach; downstream of the mast only the LiDAR
sees, and beyond its reach nothing does. One MOTA over a 150 m circle hides that, so the
report adds, per 50 m of road (negative: upstream of the mast, where traffic comes from), the
vehicles scored, the share missed (no track within the match), and the RMSE of the matched
tracks' speed and lateral offset.

:meth:`StationBreakdown.mast_stretch` sets the speed error within 50 m of the mast, where the
camera and radar hand over to the LiDAR (and under it no sensor sees), against the approach's
further upstream, where every sensor faces the traffic.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Sequence
from typing import Any

from wz_shared.messages import VehicleTruth

#: Bin width along the road [m].
BIN_M = 50.0
#: The mast's stretch: this far either side of it [m] (one bin each way).
MAST_STRETCH_M = 50.0


class StationBreakdown:
    """Accumulates, per bin of station relative to the mast, misses and errors."""

    def __init__(self, mast_station_m: float) -> None:
        self._mast_station_m = mast_station_m
        self._vehicles: dict[int, int] = defaultdict(int)
        self._missed: dict[int, int] = defaultdict(int)
        self._speed_sq: dict[int, list[float]] = defaultdict(list)
        self._lateral_sq: dict[int, list[float]] = defaultdict(list)

    def _bin(self, vehicle: VehicleTruth) -> int:
        return math.floor((vehicle.station_m - self._mast_station_m) / BIN_M)

    def add(
        self,
        vehicles: Sequence[VehicleTruth],
        matched: Sequence[tuple[int, VehicleTruth, float, float]],
        speeds_mps: Sequence[float | None],
    ) -> None:
        """One instant: the scored vehicles and :func:`score_instant`'s matches (estimate
        index, vehicle, longitudinal and lateral error) of estimates with these speeds."""
        found = {vehicle.vehicle_id: (index, lat) for index, vehicle, _, lat in matched}
        for vehicle in vehicles:
            key = self._bin(vehicle)
            self._vehicles[key] += 1
            if vehicle.vehicle_id not in found:
                self._missed[key] += 1
                continue
            index, lateral = found[vehicle.vehicle_id]
            self._lateral_sq[key].append(lateral**2)
            speed = speeds_mps[index]
            if speed is not None:
                self._speed_sq[key].append((speed - vehicle.speed_mps) ** 2)

    def mast_stretch(self) -> dict[str, Any]:
        """Speed RMSE within ``MAST_STRETCH_M`` of the mast, on the approach upstream of that,
        and their ratio (None where either has no sample)."""
        mast: list[float] = []
        approach: list[float] = []
        for key, squares in self._speed_sq.items():
            low_m, high_m = key * BIN_M, (key + 1) * BIN_M
            if low_m >= -MAST_STRETCH_M and high_m <= MAST_STRETCH_M:
                mast += squares
            elif high_m <= -MAST_STRETCH_M:
                approach += squares

        def rmse(squares: list[float]) -> float | None:
            return round(math.sqrt(sum(squares) / len(squares)), 3) if squares else None

        mast_rmse, approach_rmse = rmse(mast), rmse(approach)
        ratio = (
            round(mast_rmse / approach_rmse, 3) if mast_rmse is not None and approach_rmse else None
        )
        return {
            "within_m": MAST_STRETCH_M,
            "rmse_speed_mps": mast_rmse,
            "samples": len(mast),
            "approach_rmse_speed_mps": approach_rmse,
            "approach_samples": len(approach),
            "ratio": ratio,
        }

    def report(self) -> list[dict[str, Any]]:
        rows = []
        for key in sorted(self._vehicles):
            speed, lateral = self._speed_sq[key], self._lateral_sq[key]
            rows.append(
                {
                    "from_mast_m": [key * BIN_M, (key + 1) * BIN_M],
                    "vehicle_samples": self._vehicles[key],
                    "missed_share": round(self._missed[key] / self._vehicles[key], 4),
                    "rmse_speed_mps": round(math.sqrt(sum(speed) / len(speed)), 3)
                    if speed
                    else None,
                    "rmse_lateral_m": round(math.sqrt(sum(lateral) / len(lateral)), 3)
                    if lateral
                    else None,
                }
            )
        return rows
