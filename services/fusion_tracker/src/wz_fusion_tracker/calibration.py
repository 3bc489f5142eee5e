"""Calibrated lateral bias of each sensor's detections, removed before they reach the tracker.

A detector's position of a vehicle is not only noisy but biased, and the bias depends on where
the vehicle is as seen from the sensor. Measured against the simulator's truth on the default
site (``wz eval``, seed 7, lane 0, mean lateral error of the detections by distance upstream of
the mast): the LiDAR's boxes sit -0.01 m across the road at 10-30 m, +0.03 m at 50-90 m and
+0.13 m at 90-110 m (a far face's width is completed away from the sensor when its visible
width falls short); the camera-radar channel's -0.05 m at 30-50 m and -0.02 m at 50-70 m. The
Kalman filter takes each measurement as unbiased, so these reach the fused track, weighted.

A *bias map* holds, per sensor, per lane and per bin of station relative to the sensor's own
station, the median lateral error of that sensor's detections measured against truth: in
simulation from ``wz eval --write-bias-map FILE`` (a run with its own seed), in the field from
a probe vehicle with RTK truth driven past the trailer. :class:`LateralBiasCorrector` then
moves each detection across the road by minus its cell's bias before the tracker sees it (the
fusion node with ``WZ_FUSION_BIAS_MAP=FILE``, ``wz eval --bias-map FILE``).

What it does not do: correct along the road (the LiDAR's along-road errors depend on the
capture time of its columns, which the tracker models, and a per-bin median of them made the
fused track worse), or correct a cell with fewer than ``min_samples`` errors behind it. A
vehicle's own width or shape unlike the calibration's vehicles is a bias of its own that no
map removes; in simulation, where every car has one shape, the map fits better than it would
in the field.

Nothing here does I/O but :func:`load_bias_map` and :func:`write_bias_map`.
"""

from __future__ import annotations

import json
import math
from collections import defaultdict
from collections.abc import Iterable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Annotated

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from wz_fusion_tracker.types import Measurement
from wz_shared.site import Site

FiniteFloat = Annotated[float, Field(allow_inf_nan=False)]


class BiasCell(BaseModel):
    """One sensor's median lateral error in one lane over one bin of stations."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    lane_index: Annotated[int, Field(ge=0)]
    #: The bin's first station, relative to the sensor's station (negative: upstream) [m].
    relative_station_m: FiniteFloat
    #: Median of (detected offset - true offset) in the bin [m]; left of travel positive.
    lateral_bias_m: Annotated[float, Field(ge=-2.0, le=2.0, allow_inf_nan=False)]
    samples: Annotated[int, Field(ge=1)]


class BiasMap(BaseModel):
    """Per sensor, the cells of its lateral bias (:mod:`wz_fusion_tracker.calibration`)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    schema_version: int = 1
    site_id: str = Field(min_length=1)
    #: Length of a station bin [m].
    bin_m: Annotated[float, Field(gt=0.0, le=100.0)] = 10.0
    #: What the errors were measured against (e.g. "wz eval seed 11, 600 s").
    source: str = ""
    sensors: dict[str, list[BiasCell]] = Field(default_factory=dict)

    @model_validator(mode="after")
    def _cells_on_the_grid(self) -> BiasMap:
        for sensor_id, cells in self.sensors.items():
            seen: set[tuple[int, int]] = set()
            for cell in cells:
                index = cell.relative_station_m / self.bin_m
                if abs(index - round(index)) > 1e-6:
                    raise ValueError(
                        f"sensor {sensor_id!r}: a cell starts at {cell.relative_station_m} m, "
                        f"not on the {self.bin_m} m grid"
                    )
                key = (cell.lane_index, round(index))
                if key in seen:
                    raise ValueError(
                        f"sensor {sensor_id!r}: two cells for lane {cell.lane_index} at "
                        f"{cell.relative_station_m} m"
                    )
                seen.add(key)
        return self


class BiasMapError(ValueError):
    """A bias map file that cannot be used (unreadable, malformed, another site's)."""


def fit_bias_map(
    site: Site,
    errors: Iterable[tuple[str, float, float, float]],
    *,
    bin_m: float = 10.0,
    min_samples: int = 30,
    source: str = "",
) -> BiasMap:
    """The bias map of lateral errors measured against truth.

    Parameters
    ----------
    site
        The site (road frame, lanes, sensor stations).
    errors
        ``(sensor_id, true station [m], true offset [m], lateral error [m])`` per detection
        matched to a vehicle: the error is detected offset minus true offset. Sensors not on
        the site and vehicles outside every lane are skipped.
    bin_m
        Length of a station bin [m].
    min_samples
        A cell needs at least this many errors, or it is left out (no correction there).
    source
        Recorded in the map: what the errors were measured against.
    """
    if bin_m <= 0.0:
        raise ValueError(f"bin_m must be positive, got {bin_m}")
    stations = _sensor_stations(site)
    grouped: dict[tuple[str, int, int], list[float]] = defaultdict(list)
    for sensor_id, station_m, offset_m, lateral_error_m in errors:
        if sensor_id not in stations or not math.isfinite(lateral_error_m):
            continue
        lane = int(site.lane_index_at(offset_m))
        if lane < 0:
            continue
        index = math.floor((station_m - stations[sensor_id]) / bin_m)
        grouped[(sensor_id, lane, index)].append(lateral_error_m)
    sensors: dict[str, list[BiasCell]] = defaultdict(list)
    for (sensor_id, lane, index), values in sorted(grouped.items()):
        if len(values) < min_samples:
            continue
        sensors[sensor_id].append(
            BiasCell(
                lane_index=lane,
                relative_station_m=index * bin_m,
                lateral_bias_m=float(np.clip(np.median(values), -2.0, 2.0)),
                samples=len(values),
            )
        )
    return BiasMap(site_id=site.site_id, bin_m=bin_m, source=source, sensors=dict(sensors))


class LateralBiasCorrector:
    """Removes a :class:`BiasMap`'s lateral bias from a sensor's measurements (pure)."""

    def __init__(self, site: Site, bias_map: BiasMap) -> None:
        _check_site(bias_map, site)
        self._site = site
        self._frame = site.road_frame
        self._bin_m = bias_map.bin_m
        stations = _sensor_stations(site)
        #: sensor id -> (sensor station, {(lane, bin index): bias})
        self._cells: dict[str, tuple[float, dict[tuple[int, int], float]]] = {}
        for sensor_id, cells in bias_map.sensors.items():
            if sensor_id not in stations:
                continue  # a sensor this site does not have: nothing of it arrives
            self._cells[sensor_id] = (
                stations[sensor_id],
                {
                    (c.lane_index, round(c.relative_station_m / bias_map.bin_m)): c.lateral_bias_m
                    for c in cells
                },
            )

    def sensors(self) -> list[str]:
        """The sensors this corrector has cells for."""
        return sorted(self._cells)

    def correct(self, sensor_id: str, measurements: Sequence[Measurement]) -> list[Measurement]:
        """The measurements moved across the road by minus their cell's bias; a measurement
        outside every lane, or in a cell the map does not have, is returned as it is."""
        found = self._cells.get(sensor_id)
        if found is None or not measurements:
            return list(measurements)
        sensor_station, cells = found
        x = np.array([m.x_m for m in measurements], dtype=np.float64)
        y = np.array([m.y_m for m in measurements], dtype=np.float64)
        station, offset = self._frame.to_road(x, y)
        lanes = self._site.lane_index_at(offset)
        bins = np.floor((station - sensor_station) / self._bin_m).astype(np.intp)
        bias = np.array(
            [cells.get((int(lane), int(b)), 0.0) for lane, b in zip(lanes, bins, strict=True)]
        )
        moved = np.flatnonzero(bias != 0.0)  # no cell has lane -1 (off every lane)
        if len(moved) == 0:
            return list(measurements)
        new_x, new_y = self._frame.to_site(station[moved], offset[moved] - bias[moved])
        new_x, new_y = np.asarray(new_x).reshape(-1), np.asarray(new_y).reshape(-1)
        out = list(measurements)
        for k, i in enumerate(moved):
            out[i] = replace(out[i], x_m=float(new_x[k]), y_m=float(new_y[k]))
        return out


def _check_site(bias_map: BiasMap, site: Site) -> None:
    if bias_map.site_id != site.site_id:
        raise BiasMapError(
            f"the bias map is for site {bias_map.site_id!r}, this is {site.site_id!r}"
        )


def _sensor_stations(site: Site) -> dict[str, float]:
    """Each sensor's station on the road [m]."""
    frame = site.road_frame
    return {
        mount.sensor_id: float(np.asarray(frame.to_road(mount.pose.x_m, mount.pose.y_m)[0]))
        for mount in site.sensors
    }


def load_bias_map(path: str | Path, site: Site | None = None) -> BiasMap:
    """Read a bias map (JSON), of ``site`` when given; :class:`BiasMapError` says what is wrong
    with a bad one or another site's."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise BiasMapError(f"bias map {path}: cannot read it ({exc})") from exc
    try:
        bias_map = BiasMap.model_validate(json.loads(text))
    except json.JSONDecodeError as exc:
        raise BiasMapError(f"bias map {path}: not JSON ({exc})") from exc
    except ValidationError as exc:
        raise BiasMapError(f"bias map {path}: {exc}") from exc
    if site is not None:
        _check_site(bias_map, site)
    return bias_map


def write_bias_map(path: str | Path, bias_map: BiasMap) -> None:
    """Write a bias map as JSON."""
    Path(path).write_text(bias_map.model_dump_json(indent=2) + "\n", encoding="utf-8")
