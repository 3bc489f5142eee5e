"""Field validation: each source's trajectory of the RTK-GPS van against the GPS track.

The paper's "Evaluation using Field-collected Data" compares, for the one vehicle carrying RTK
GPS, the trajectories the LiDAR, the radar-camera unit and the KF fusion gave with the GPS
track. This module scores that comparison, as pure functions on arrays (no I/O but
:func:`plot_field`), with the conventions of :mod:`wz_eval.metrics`: errors are ``source - GPS``
in the road frame, longitudinal along the station (positive: the source downstream of the
van) and lateral in offset (positive: the source to the van's left).

Steps, per source
-----------------
1. **Clock offset.** A source's clock may be off from the GPS's by a constant ``offset`` (its
   stamps run ``offset`` ahead: an observation stamped ``t`` happened at GPS time
   ``t - offset``). On a moving vehicle an offset looks like a longitudinal error of
   ``speed x offset`` (0.3 s at 25 m/s: 7.5 m), so it is estimated (:func:`estimate_clock_offset`)
   and every error is taken with it applied; pass ``clock_offsets_s`` to fix it instead.
2. **Association** (:func:`associate`). The observations that are the van: nearest to the GPS
   position (interpolated linearly between fixes, never across a gap in the GPS of more than
   ``max_gps_gap_s``) at the observation's GPS time, within ``gate_m``; one per stamp (of
   several observations with the same stamp, the nearest).
3. **Errors by axis**: count, RMSE, mean (bias), 95th percentile and maximum of the absolute
   error, for the associations inside the evaluation window.
4. **Availability.** The evaluation window is the GPS time the van spent between two stations
   (``station_window_m``; by default the lowest and highest GPS station at any source's
   associations), without the GPS's own gaps. A source is *available* at an instant of the
   window when it has an associated observation within ``availability_half_window_s`` of it
   (0.25 s: a source at 2 Hz or faster that loses no frame is available throughout; a gap of
   ``G`` s between observations costs ``G - 0.5`` s). The longest gap is the longest time
   inside the window between consecutive associated observations (or between a window's edge
   and the nearest one).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from wz_shared.arrays import F64, I64
from wz_shared.geometry import RoadFrame

Intervals = list[tuple[float, float]]


class TruthTrack(Protocol):
    """The GPS vehicle's reference point over time (``wz_drivers.gps.GpsTrack`` is one): ``t``
    stamps [s] strictly increasing, ``x_m``, ``y_m`` site frame [m], shape (N,), N >= 2."""

    @property
    def t(self) -> F64: ...

    @property
    def x_m(self) -> F64: ...

    @property
    def y_m(self) -> F64: ...


@dataclass(frozen=True)
class SourceObservations:
    """What one source reported, every vehicle it saw: shape (M,) each.

    ``times_s``: its stamps [s] on its own clock; ``x_m``, ``y_m``: site frame [m]; ``ids``:
    its track or object ids (optional), to count how often the van's id changed.
    """

    times_s: F64
    x_m: F64
    y_m: F64
    ids: I64 | None = None

    def __post_init__(self) -> None:
        columns = {"times_s": self.times_s, "x_m": self.x_m, "y_m": self.y_m}
        for name, values in columns.items():
            array = np.asarray(values, dtype=np.float64)
            if array.ndim != 1 or not np.all(np.isfinite(array)):
                raise ValueError(f"{name} must be a 1-D array of finite numbers")
            object.__setattr__(self, name, array)
        if self.ids is not None:
            object.__setattr__(self, "ids", np.asarray(self.ids, dtype=np.int64))
        sizes = {len(self.times_s), len(self.x_m), len(self.y_m)}
        if self.ids is not None:
            sizes.add(len(self.ids))
        if len(sizes) != 1:
            raise ValueError("times_s, x_m, y_m (and ids) must have the same length")


@dataclass(frozen=True)
class FieldSettings:
    """Parameters of the field evaluation, with units."""

    #: Largest distance [m] from the GPS position for an observation to be the van: about a
    #: lane width less a margin, so the vehicle in the next lane is not taken.
    gate_m: float = 3.0
    #: Clock offsets searched [s]: keep it inside the time headway of the vehicles around the
    #: van, or a neighbour seen at the wrong offset may pass the gate.
    offset_search_s: tuple[float, float] = (-2.0, 2.0)
    #: Step of the coarse search [s]; then a search at ``offset_refine_step_s`` within one
    #: coarse step of the best.
    offset_step_s: float = 0.01
    offset_refine_step_s: float = 0.001
    #: An offset is a candidate only when it associates at least this share of the most
    #: associations at any offset (and ``min_offset_samples``).
    min_association_share: float = 0.5
    min_offset_samples: int = 10
    #: Below this median along-road speed [m/s] of the van, an offset is not observable.
    min_offset_speed_mps: float = 2.0
    #: An associated observation covers this long [s] either side of it (availability).
    availability_half_window_s: float = 0.25
    #: The GPS is not interpolated across a gap between fixes longer than this [s].
    max_gps_gap_s: float = 1.0
    #: Evaluation window in stations [m]; None: the span of all sources' associations.
    station_window_m: tuple[float, float] | None = None


@dataclass(frozen=True)
class Association:
    """The observations of a source that are the van, in time order: shape (K,) each.

    ``index`` into the source's observations; ``t_s`` GPS time (stamp minus clock offset);
    ``station_m``, ``offset_m`` the observation and ``truth_station_m``, ``truth_offset_m`` the
    GPS at that time, in the road frame; ``truth_speed_mps`` the van's along-road speed.
    """

    index: npt.NDArray[np.intp]
    t_s: F64
    station_m: F64
    offset_m: F64
    truth_station_m: F64
    truth_offset_m: F64
    truth_speed_mps: F64
    ids: I64 | None

    @property
    def longitudinal_error_m(self) -> F64:
        return self.station_m - self.truth_station_m

    @property
    def lateral_error_m(self) -> F64:
        return self.offset_m - self.truth_offset_m

    def __len__(self) -> int:
        return int(self.index.size)

    def subset(self, keep: npt.NDArray[np.bool_]) -> Association:
        return Association(
            index=self.index[keep],
            t_s=self.t_s[keep],
            station_m=self.station_m[keep],
            offset_m=self.offset_m[keep],
            truth_station_m=self.truth_station_m[keep],
            truth_offset_m=self.truth_offset_m[keep],
            truth_speed_mps=self.truth_speed_mps[keep],
            ids=None if self.ids is None else self.ids[keep],
        )


@dataclass(frozen=True)
class AxisStats:
    """Signed errors of one axis [m]: count, RMSE, mean (bias), p95 and max of |error|; None
    where there is no sample."""

    count: int
    rmse_m: float | None
    mean_m: float | None
    p95_abs_m: float | None
    max_abs_m: float | None

    @classmethod
    def of(cls, errors_m: F64) -> AxisStats:
        if errors_m.size == 0:
            return cls(0, None, None, None, None)
        magnitude = np.abs(errors_m)
        return cls(
            count=int(errors_m.size),
            rmse_m=float(np.sqrt(np.mean(errors_m**2))),
            mean_m=float(np.mean(errors_m)),
            p95_abs_m=float(np.percentile(magnitude, 95)),
            max_abs_m=float(np.max(magnitude)),
        )


@dataclass(frozen=True)
class ClockOffset:
    """A source's clock offset [s] (its stamps minus GPS time), whether it was estimated, and
    why not or how well: ``speed_mps`` the van's median along-road speed at the associations
    (an offset error of ``e`` s shows as ``speed x e`` m)."""

    offset_s: float
    estimated: bool
    note: str
    speed_mps: float | None = None


@dataclass(frozen=True)
class SourceResult:
    name: str
    observations: int
    clock: ClockOffset
    association: Association  # inside the evaluation window
    longitudinal: AxisStats
    lateral: AxisStats
    availability: float | None
    longest_gap_s: float | None
    rmse_longitudinal_at_zero_offset_m: float | None
    distinct_ids: int | None
    id_changes: int | None

    @property
    def distance_rmse_m(self) -> float | None:
        """RMSE of the distance to the GPS position [m] (both axes: sqrt of the sum of their
        mean squares)."""
        lon, lat = self.longitudinal.rmse_m, self.lateral.rmse_m
        return None if lon is None or lat is None else math.hypot(lon, lat)

    def summary(self) -> dict[str, Any]:
        """JSON-able, with :meth:`wz_eval.metrics.AxisErrors.summary`'s names."""
        out: dict[str, Any] = {
            "observations": self.observations,
            "samples": self.longitudinal.count,
            "rmse_distance_m": self.distance_rmse_m,
        }
        for axis, stats in (("longitudinal", self.longitudinal), ("lateral", self.lateral)):
            out[f"rmse_{axis}_m"] = stats.rmse_m
            out[f"bias_{axis}_m"] = stats.mean_m
            out[f"p95_abs_{axis}_m"] = stats.p95_abs_m
            out[f"max_abs_{axis}_m"] = stats.max_abs_m
        out.update(
            {
                "availability": self.availability,
                "longest_gap_s": self.longest_gap_s,
                "clock_offset_s": self.clock.offset_s,
                "clock_offset_estimated": self.clock.estimated,
                "clock_offset_note": self.clock.note,
                "clock_offset_speed_mps": self.clock.speed_mps,
                "rmse_longitudinal_at_zero_offset_m": self.rmse_longitudinal_at_zero_offset_m,
                "distinct_ids": self.distinct_ids,
                "id_changes": self.id_changes,
            }
        )
        return out


@dataclass(frozen=True)
class FieldResult:
    """Every source's result, the evaluation window, and the GPS track in the road frame
    (``truth_*``, shape (N,), for the plot)."""

    sources: dict[str, SourceResult]
    station_window_m: tuple[float, float] | None
    window_s: tuple[tuple[float, float], ...]
    settings: FieldSettings
    truth_t_s: F64 = field(repr=False)
    truth_station_m: F64 = field(repr=False)
    truth_offset_m: F64 = field(repr=False)

    @property
    def window_duration_s(self) -> float:
        return float(sum(end - start for start, end in self.window_s))

    def to_dict(self) -> dict[str, Any]:
        """JSON-able summary."""
        return {
            "clock_offset_convention": "a source's stamp minus GPS time; errors are taken with "
            "it applied (an observation stamped t against the GPS at t - offset)",
            "error_convention": "source - GPS in the road frame: longitudinal along the "
            "station (positive downstream), lateral in offset (positive left)",
            "station_window_m": None
            if self.station_window_m is None
            else list(self.station_window_m),
            "window_s": self.window_duration_s,
            "window_intervals_s": [list(interval) for interval in self.window_s],
            "settings": {
                k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self.settings).items()
            },
            "sources": {name: result.summary() for name, result in self.sources.items()},
        }


# --- the GPS track --------------------------------------------------------------------------


class _Truth:
    """The GPS track in both frames, interpolated linearly in time between fixes."""

    def __init__(self, truth: TruthTrack, road: RoadFrame, max_gap_s: float) -> None:
        self.t = np.asarray(truth.t, dtype=np.float64)
        self.x = np.asarray(truth.x_m, dtype=np.float64)
        self.y = np.asarray(truth.y_m, dtype=np.float64)
        if (
            self.t.ndim != 1
            or self.t.size < 2
            or self.x.shape != self.t.shape
            or self.y.shape != self.t.shape
        ):
            raise ValueError("the GPS track needs t, x_m, y_m of one shape (N,), N >= 2")
        if np.any(np.diff(self.t) <= 0.0):
            raise ValueError("the GPS track's stamps must increase strictly")
        self.station, self.offset = road.to_road(self.x, self.y)
        self.speed = np.gradient(self.station, self.t)
        self.segment_ok = np.diff(self.t) <= max_gap_s

    def at(self, times_s: F64) -> tuple[npt.NDArray[np.bool_], F64, F64, F64, F64, F64]:
        """``valid`` (inside the track, not in a gap), x, y, station, offset, along-road speed
        at each time (NaN-free garbage where not valid)."""
        i = np.clip(np.searchsorted(self.t, times_s, side="right") - 1, 0, self.t.size - 2)
        u = (times_s - self.t[i]) / (self.t[i + 1] - self.t[i])
        valid = (u >= 0.0) & (u <= 1.0) & self.segment_ok[i]

        def lerp(values: F64) -> F64:
            result: F64 = values[i] + u * (values[i + 1] - values[i])
            return result

        return (
            valid,
            lerp(self.x),
            lerp(self.y),
            lerp(self.station),
            lerp(self.offset),
            lerp(self.speed),
        )

    def window(self, station_window_m: tuple[float, float]) -> Intervals:
        """The GPS time intervals when the van's station is within the window (station linear
        between fixes; no interval across a GPS gap)."""
        low, high = station_window_m
        s0, s1 = self.station[:-1], self.station[1:]
        ds = s1 - s0
        moving = ds != 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            u_low = np.where(moving, (low - s0) / ds, -np.inf)
            u_high = np.where(moving, (high - s0) / ds, np.inf)
        inside_still = (s0 >= low) & (s0 <= high)
        start = np.where(moving, np.maximum(0.0, np.minimum(u_low, u_high)), 0.0)
        end = np.where(moving, np.minimum(1.0, np.maximum(u_low, u_high)), 1.0)
        keep = self.segment_ok & (start < end) & (moving | inside_still)
        dt = np.diff(self.t)
        starts = self.t[:-1] + start * dt
        ends = self.t[:-1] + end * dt
        return _merge(list(zip(starts[keep].tolist(), ends[keep].tolist(), strict=True)))


class _Source:
    """A source's observations and their road-frame coordinates."""

    def __init__(self, observations: SourceObservations, road: RoadFrame) -> None:
        self.obs = observations
        self.station, self.offset = road.to_road(observations.x_m, observations.y_m)


# --- association and clock offset ---------------------------------------------------------


def _associate(truth: _Truth, source: _Source, clock_offset_s: float, gate_m: float) -> Association:
    obs = source.obs
    gps_time = obs.times_s - clock_offset_s
    valid, x, y, station, offset, speed = truth.at(gps_time)
    distance = np.hypot(obs.x_m - x, obs.y_m - y)
    candidates = np.flatnonzero(valid & (distance <= gate_m))
    # Nearest first within each stamp, then the first of each stamp.
    order = candidates[np.lexsort((distance[candidates], obs.times_s[candidates]))]
    first = np.ones(order.size, dtype=bool)
    first[1:] = obs.times_s[order[1:]] != obs.times_s[order[:-1]]
    index = order[first]
    return Association(
        index=index,
        t_s=gps_time[index],
        station_m=source.station[index],
        offset_m=source.offset[index],
        truth_station_m=station[index],
        truth_offset_m=offset[index],
        truth_speed_mps=speed[index],
        ids=None if obs.ids is None else obs.ids[index],
    )


def associate(
    truth: TruthTrack,
    observations: SourceObservations,
    road: RoadFrame,
    clock_offset_s: float = 0.0,
    settings: FieldSettings | None = None,
) -> Association:
    """The observations that are the GPS vehicle, with ``clock_offset_s`` applied.

    An observation stamped ``t`` is compared with the GPS position interpolated at
    ``t - clock_offset_s``; it is the vehicle when within ``gate_m`` of it, and the nearest of
    the observations with its stamp.
    """
    settings = settings or FieldSettings()
    return _associate(
        _Truth(truth, road, settings.max_gps_gap_s),
        _Source(observations, road),
        clock_offset_s,
        settings.gate_m,
    )


def _search(
    truth: _Truth, source: _Source, offsets_s: F64, settings: FieldSettings, min_count: int | None
) -> tuple[float, int, int] | None:
    """Among ``offsets_s``, the candidate with the least median |longitudinal error| (ties:
    nearest 0); with its count and the largest count seen; None without a candidate."""
    counts = np.zeros(offsets_s.size, dtype=np.int64)
    medians = np.full(offsets_s.size, np.inf)
    for k, offset in enumerate(offsets_s):
        association = _associate(truth, source, float(offset), settings.gate_m)
        counts[k] = len(association)
        if counts[k]:
            medians[k] = float(np.median(np.abs(association.longitudinal_error_m)))
    most = int(counts.max(initial=0))
    if min_count is None:
        min_count = max(
            settings.min_offset_samples, math.ceil(settings.min_association_share * most)
        )
    candidates = np.flatnonzero(counts >= min_count)
    if candidates.size == 0:
        return None
    best = candidates[np.lexsort((np.abs(offsets_s[candidates]), medians[candidates]))[0]]
    return float(offsets_s[best]), min_count, most


def _estimate(truth: _Truth, source: _Source, settings: FieldSettings) -> ClockOffset:
    low, high = settings.offset_search_s
    step, fine_step = settings.offset_step_s, settings.offset_refine_step_s
    # Integer multiples of the step, so 0 is on the grid exactly.
    first, last = math.ceil(low / step - 1e-9), math.floor(high / step + 1e-9)
    coarse = np.arange(first, last + 1, dtype=np.float64) * step
    found = _search(truth, source, coarse, settings, None)
    if found is None:
        return ClockOffset(
            0.0,
            False,
            "not estimated: too few associations at any offset "
            f"(fewer than {settings.min_offset_samples})",
        )
    best, min_count, _ = found
    reach = math.ceil(step / fine_step)
    fine = best + np.arange(-reach, reach + 1, dtype=np.float64) * fine_step
    refined = _search(truth, source, fine, settings, min_count)
    if refined is not None:
        best = refined[0]
    association = _associate(truth, source, best, settings.gate_m)
    speed = float(np.median(np.abs(association.truth_speed_mps)))
    if speed < settings.min_offset_speed_mps:
        return ClockOffset(
            0.0,
            False,
            f"not estimated: the van's median speed {speed:.1f} m/s "
            f"is below {settings.min_offset_speed_mps:g} m/s, where an offset "
            "makes no error to see",
            speed,
        )
    return ClockOffset(
        best,
        True,
        f"estimated: the offset with the least median |longitudinal "
        f"error| in [{low:g}, {high:g}] s (steps of {step:g} s, then "
        f"{fine_step:g} s)",
        speed,
    )


def estimate_clock_offset(
    truth: TruthTrack,
    observations: SourceObservations,
    road: RoadFrame,
    settings: FieldSettings | None = None,
) -> ClockOffset:
    """The constant offset between a source's clock and the GPS's [s] (its stamps minus GPS
    time).

    Grid search over ``offset_search_s`` in ``offset_step_s`` steps, then in
    ``offset_refine_step_s`` steps within one coarse step of the best: each offset is applied,
    the observations associated (:func:`associate`), and the offset with the least median
    absolute longitudinal error wins, among those associating at least
    ``min_association_share`` of the most associations at any offset (an offset that loses
    the van from the gate leaves few, possibly lucky, associations).

    Notes
    -----
    Error = bias + speed x (offset - true offset) along the road, so a constant longitudinal
    bias ``b`` of the source (a sensor reporting the front of the vehicle, say) moves the
    estimate by ``-b / speed``: at one speed the two cannot be told apart, and the offset
    absorbs the bias. Runs at different speeds, or both directions, separate them. When the
    van hardly moves (median speed below ``min_offset_speed_mps``) the offset is not observable:
    0 is returned, not estimated.
    """
    settings = settings or FieldSettings()
    return _estimate(
        _Truth(truth, road, settings.max_gps_gap_s), _Source(observations, road), settings
    )


# --- availability ----------------------------------------------------------------------------


def _merge(intervals: Intervals) -> Intervals:
    """Union of intervals, sorted and disjoint (touching ones joined)."""
    merged: Intervals = []
    for start, end in sorted(intervals):
        if merged and start <= merged[-1][1]:
            merged[-1] = (merged[-1][0], max(merged[-1][1], end))
        else:
            merged.append((start, end))
    return merged


def _overlap_s(first: Intervals, second: Intervals) -> float:
    """Total length of the intersection of two sorted disjoint interval lists."""
    total, i, j = 0.0, 0, 0
    while i < len(first) and j < len(second):
        start = max(first[i][0], second[j][0])
        end = min(first[i][1], second[j][1])
        total += max(0.0, end - start)
        if first[i][1] < second[j][1]:
            i += 1
        else:
            j += 1
    return total


def _availability(
    times_s: F64, window: Intervals, half_window_s: float
) -> tuple[float | None, float | None]:
    """Share of the window within ``half_window_s`` of an associated time, and the longest
    gap inside the window between associated times (or a window edge)."""
    duration = sum(end - start for start, end in window)
    if duration <= 0.0:
        return None, None
    covered = _merge([(t - half_window_s, t + half_window_s) for t in times_s.tolist()])
    longest = 0.0
    times = np.sort(times_s)
    for start, end in window:
        inside = times[(times >= start) & (times <= end)]
        edges = np.concatenate([[start], inside, [end]])
        longest = max(longest, float(np.max(np.diff(edges))))
    return _overlap_s(covered, window) / duration, longest


# --- the evaluation --------------------------------------------------------------------------


def _in_window(
    association: Association, station_window_m: tuple[float, float] | None
) -> Association:
    """The associations whose GPS station is within the window."""
    if station_window_m is None:
        return association
    low, high = station_window_m
    return association.subset(
        (association.truth_station_m >= low) & (association.truth_station_m <= high)
    )


def evaluate_field(
    truth: TruthTrack,
    sources: Mapping[str, SourceObservations],
    road: RoadFrame,
    settings: FieldSettings | None = None,
    *,
    clock_offsets_s: Mapping[str, float] | None = None,
) -> FieldResult:
    """Score each source against the GPS track (see the module's docstring).

    Parameters
    ----------
    truth : TruthTrack
        The GPS vehicle's reference point, shape (N,), N >= 2.
    sources : mapping of name to SourceObservations
        E.g. ``{"lidar": ..., "radar-camera": ..., "fused": ...}``; every vehicle each saw.
    road : RoadFrame
        The site's road frame (``site.road_frame``).
    settings : FieldSettings, optional
    clock_offsets_s : mapping of name to float, optional
        Offsets [s] to use instead of estimating them (the sources not named are estimated).

    Returns
    -------
    FieldResult
    """
    settings = settings or FieldSettings()
    gps = _Truth(truth, road, settings.max_gps_gap_s)
    fixed = dict(clock_offsets_s or {})
    prepared = {name: _Source(observations, road) for name, observations in sources.items()}
    clocks: dict[str, ClockOffset] = {}
    associations: dict[str, Association] = {}
    for name, source in prepared.items():
        if name in fixed:
            clocks[name] = ClockOffset(float(fixed[name]), False, "given")
        else:
            clocks[name] = _estimate(gps, source, settings)
        associations[name] = _associate(gps, source, clocks[name].offset_s, settings.gate_m)

    station_window = settings.station_window_m
    if station_window is None:
        stations = np.concatenate(
            [np.empty(0), *(a.truth_station_m for a in associations.values())]
        )
        if stations.size:
            station_window = (float(stations.min()), float(stations.max()))
    window = gps.window(station_window) if station_window is not None else []

    results: dict[str, SourceResult] = {}
    for name, source in prepared.items():
        association = _in_window(associations[name], station_window)
        availability, longest_gap = _availability(
            association.t_s, window, settings.availability_half_window_s
        )
        at_zero = _in_window(_associate(gps, source, 0.0, settings.gate_m), station_window)
        ids = association.ids
        results[name] = SourceResult(
            name=name,
            observations=len(source.obs.times_s),
            clock=clocks[name],
            association=association,
            longitudinal=AxisStats.of(association.longitudinal_error_m),
            lateral=AxisStats.of(association.lateral_error_m),
            availability=availability,
            longest_gap_s=longest_gap,
            rmse_longitudinal_at_zero_offset_m=AxisStats.of(at_zero.longitudinal_error_m).rmse_m,
            distinct_ids=None if ids is None else int(np.unique(ids).size),
            id_changes=None if ids is None else int(np.count_nonzero(np.diff(ids))),
        )
    return FieldResult(
        sources=results,
        station_window_m=station_window,
        window_s=tuple(window),
        settings=settings,
        truth_t_s=gps.t,
        truth_station_m=gps.station,
        truth_offset_m=gps.offset,
    )


# --- report ------------------------------------------------------------------------------------


def markdown_table(result: FieldResult) -> str:
    """The paper-style table: a row per source; RMSE and bias by axis, p95, availability,
    longest gap, clock offset; and what the columns mean."""

    def cell(value: float | None, digits: int = 2) -> str:
        return "-" if value is None else f"{value:.{digits}f}"

    lines = [
        "| source | samples | RMSE distance [m] | RMSE longitudinal [m] | RMSE lateral [m] "
        "| bias longitudinal [m] "
        "| bias lateral [m] | p95 longitudinal [m] | p95 lateral [m] | available [%] "
        "| longest gap [s] | clock offset [s] |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, row in result.sources.items():
        availability = None if row.availability is None else 100.0 * row.availability
        offset = f"{row.clock.offset_s:+.3f}" + (
            "" if row.clock.estimated else f" ({row.clock.note.split(':')[0]})"
        )
        lines.append(
            f"| {name} | {row.longitudinal.count} | {cell(row.distance_rmse_m)} | "
            f"{cell(row.longitudinal.rmse_m)} | "
            f"{cell(row.lateral.rmse_m)} | {cell(row.longitudinal.mean_m)} | "
            f"{cell(row.lateral.mean_m)} | {cell(row.longitudinal.p95_abs_m)} | "
            f"{cell(row.lateral.p95_abs_m)} | {cell(availability, 1)} | "
            f"{cell(row.longest_gap_s, 1)} | {offset} |"
        )
    window = result.station_window_m
    where = (
        "no window (no source saw the GPS vehicle)"
        if window is None
        else (
            f"{result.window_duration_s:.1f} s of GPS time between stations {window[0]:.0f} and "
            f"{window[1]:.0f} m"
        )
    )
    half = result.settings.availability_half_window_s
    lines += [
        "",
        f"Errors are source - GPS in the road frame (longitudinal positive downstream, lateral "
        f"positive left) over {where}, with each source's clock offset applied (its stamp "
        f"minus GPS time: an observation stamped t is compared with the GPS at t - offset). "
        f"Associated: nearest to the GPS within {result.settings.gate_m:g} m, one per stamp. "
        f"Available: an associated observation within {half:g} s.",
    ]
    return "\n".join(lines) + "\n"


#: Styles by source name, in the colours of :data:`wz_eval.plots.STYLE`.
PLOT_STYLE: dict[str, dict[str, Any]] = {
    "lidar": {"marker": "x", "linestyle": "none", "markersize": 4, "color": "tab:orange"},
    "radar-camera": {"marker": "o", "linestyle": "none", "markersize": 3, "color": "tab:blue"},
    "camera": {"marker": "o", "linestyle": "none", "markersize": 3, "color": "tab:blue"},
    "radar": {"marker": "s", "linestyle": "none", "markersize": 3, "color": "tab:red"},
    "fused": {
        "marker": ".",
        "linestyle": "-",
        "linewidth": 1.2,
        "markersize": 3,
        "color": "tab:green",
    },
}
_OTHER_COLOURS = ("tab:purple", "tab:brown", "tab:pink", "tab:olive", "tab:cyan")


def plot_field(result: FieldResult, path: Path, *, names: Sequence[str] | None = None) -> Path:
    """PNG of the GPS track and each source's associated positions in the road frame (station
    vs offset), and their longitudinal and lateral errors over time; returns ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    chosen = list(names) if names is not None else list(result.sources)
    t0 = result.window_s[0][0] if result.window_s else float(result.truth_t_s[0])
    figure, (track, longitudinal, lateral) = plt.subplots(3, 1, figsize=(9, 9))
    in_window = np.zeros(result.truth_t_s.size, dtype=bool)
    for start, end in result.window_s:
        in_window |= (result.truth_t_s >= start) & (result.truth_t_s <= end)
    if not in_window.any():
        in_window[:] = True
    track.plot(
        result.truth_station_m[in_window],
        result.truth_offset_m[in_window],
        "k--",
        linewidth=0.9,
        label="GPS",
    )
    for k, name in enumerate(chosen):
        association = result.sources[name].association
        style = PLOT_STYLE.get(
            name,
            {
                "marker": ".",
                "linestyle": "none",
                "markersize": 3,
                "color": _OTHER_COLOURS[k % len(_OTHER_COLOURS)],
            },
        )
        track.plot(association.station_m, association.offset_m, label=name, **style)
        error_style = {**style, "linestyle": "-", "linewidth": 0.7}
        longitudinal.plot(
            association.t_s - t0, association.longitudinal_error_m, label=name, **error_style
        )
        lateral.plot(association.t_s - t0, association.lateral_error_m, label=name, **error_style)
    track.set_xlabel("station along the road [m]")
    track.set_ylabel("offset [m]")
    track.set_title("GPS vehicle: GPS track and each source's associated positions", fontsize=9)
    for axis, what in ((longitudinal, "longitudinal"), (lateral, "lateral")):
        axis.axhline(0.0, color="k", linewidth=0.6)
        axis.set_xlabel("GPS time from the window's start [s]")
        axis.set_ylabel(f"{what} error [m]")
    for axis in (track, longitudinal, lateral):
        axis.legend(fontsize=7, ncol=4)
    figure.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path
