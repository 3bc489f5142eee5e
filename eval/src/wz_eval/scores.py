"""The sources ``wz eval`` scores and what it collects of each: its errors and, per vehicle,
its samples (:class:`Scores`). Filled by :func:`wz_eval.fusion.evaluate`, drawn by
:mod:`wz_eval.plots` (a module of its own so that both import it, neither the other)."""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass, field

from wz_eval.metrics import AxisErrors, score_instant
from wz_shared.messages import VehicleTruth
from wz_shared.site import Site

#: The sources scored (:mod:`wz_eval.fusion`'s docstring says what each is).
SOURCES = (
    "camera",
    "lidar",
    "radar",
    "camera_radar",
    "average",
    "paper_kf",
    "fused",
    "fused_smoothed",
    "fused_stored",
)
#: Gate for matching a source's estimate to a vehicle [m] (the MOT metrics use 3 m).
SOURCE_GATE_M = 5.0


@dataclass
class Scores:
    """Per-source errors, per-vehicle samples for the paper table, MOT events."""

    errors: dict[str, AxisErrors] = field(
        default_factory=lambda: {s: AxisErrors() for s in SOURCES}
    )
    # vehicle id -> source -> stamp -> (lon error, lat error, true station, true offset)
    per_vehicle: dict[str, dict[str, dict[float, tuple[float, float, float, float]]]] = field(
        default_factory=lambda: defaultdict(lambda: defaultdict(dict))
    )

    def add(
        self,
        site: Site,
        source: str,
        stamp_s: float,
        estimates: Sequence[tuple[float, float, float | None]],
        vehicles: Sequence[VehicleTruth],
        time_offsets_s: Sequence[float | None] | None = None,
    ) -> list[tuple[int, VehicleTruth, float, float]]:
        matched = score_instant(
            site, self.errors[source], estimates, vehicles, SOURCE_GATE_M, time_offsets_s
        )
        for _, vehicle, lon, lat in matched:
            station, offset = site.road_frame.to_road(vehicle.x_m, vehicle.y_m)
            self.per_vehicle[vehicle.vehicle_id][source][round(stamp_s, 4)] = (
                lon,
                lat,
                float(station),
                float(offset),
            )
        return matched
