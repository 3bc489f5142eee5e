"""Scoring each lane's queue against SUMO's truth: the back's error, onset and dissolution
delays, false queues.

Truth is the same estimate (:class:`wz_alert_service.queues.QueueEstimator`, the site's queue
thresholds) run on the true kinematics of every simulated vehicle in the approach that stands
where a sensor of the site can see a car (``coverage``, the weather's; as the tracks are scored:
a queue that forms past the sensors' sight at the taper is found when its back comes into
it, and no software on the mast can do better), as :func:`wz_eval.alerts.truth_batches`
gives them: a lane is queued while 3 of its vehicles
under 8.9 m/s (20 mph) stand within 100 m, stopped while their mean speed is under 2.2 m/s
(HCM's queued vehicle: under 5 mph); the back is the most upstream queued vehicle. The
thresholds are the site file's (``alerts.queue``) and the report states them.

Both are sampled once a second over the scored interval, each at its newest estimate at or
before the second:

- ``back_error_m``: ``|back_estimated - back_true|`` at the seconds where both have the lane
  queued and the true back is inside the sensors' reach (:func:`upstream_reach_m`; beyond it
  no sensor can place the back, and the estimate says ``back_beyond_reach``): median, 90th
  percentile, count. ``beyond_reach_s``: seconds the true back was beyond the reach, and of
  those, how many the estimate flagged ``back_beyond_reach``.
- Episodes: maximal runs of queued seconds per lane. A true episode is *detected* when an
  estimated one overlaps it; ``onset_delay_s`` is the estimate's start minus the truth's (a
  median over the detected episodes, and the worst), ``dissolution_delay_s`` the same for
  their ends (episodes still open at the end are left out of it).
- ``beyond_reach`` (a site with upstream point sensors): at the seconds the estimate had a
  lane's back beyond the reach, the truth's back on the whole approach (every vehicle, seen
  or not: :func:`beyond_reach_report`) against the point sensors' bounds: seconds, seconds
  bounded (a sensor read the lane free upstream), seconds the true back stood within the
  bounds (:data:`BOUND_TOLERANCE_M` either side), the bounds' width, how far outside the
  true back stood, and how far the true back stood from the reach (what "beyond the reach"
  alone leaves unknown).
- ``false_queue``: estimated episodes that overlap no true one, their count per hour of
  scored time and their seconds; ``missed``: true episodes no estimate overlaps.

Pure: no I/O.
"""

from __future__ import annotations

import statistics
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from wz_alert_service.engine import confirmed
from wz_alert_service.queues import QueueEstimator, upstream_reach_m
from wz_alert_service.zone import ZoneGeometry
from wz_eval.alerts import TruthFrames, truth_batches
from wz_shared.coverage import SiteCoverage
from wz_shared.messages import LaneQueue, PointSensorReading, QueueCondition, TrackBatch
from wz_shared.site import Site

#: The sampling step of the comparison [s].
STEP_S = 1.0
#: A true back this close outside the point sensors' bounds [m] still counts as within: one
#: queued car and its gap at jam density, as the reach's margin
#: (:data:`wz_alert_service.queues.REACH_MARGIN_M`).
BOUND_TOLERANCE_M = 15.0


@dataclass(frozen=True)
class _Episode:
    """Queued seconds ``[start_s, end_s)``; ``end_s`` is the last sample when still open."""

    start_s: float
    end_s: float
    open_at_end: bool


def lane_series(
    zone: ZoneGeometry,
    batches: Sequence[TrackBatch],
    reach_m: dict[int, float],
    times: np.ndarray,
    point_readings: Sequence[PointSensorReading] = (),
) -> dict[int, list[LaneQueue]]:
    """Each lane's queue at each of ``times``: the estimate of the newest batch at or before
    it (free before the first batch), the point sensors' readings taken as their stamps come."""
    estimator = QueueEstimator(zone, reach_m)
    free = {lane.lane_index: lane for lane in estimator.lanes}
    out: dict[int, list[LaneQueue]] = {index: [] for index in free}
    readings = sorted(point_readings, key=lambda r: r.stamp)
    k = j = 0
    for t in times:
        while k < len(batches) and batches[k].stamp <= t + 1e-9:
            while j < len(readings) and readings[j].stamp <= batches[k].stamp + 1e-9:
                estimator.observe(readings[j])
                j += 1
            estimator.estimate([tr for tr in batches[k].tracks if confirmed(tr)], batches[k].stamp)
            k += 1
        lanes = {lane.lane_index: lane for lane in estimator.lanes} if k else free
        for index in out:
            out[index].append(lanes[index])
    return out


def seen_frames(truth_frames: TruthFrames, coverage: SiteCoverage) -> TruthFrames:
    """Each frame's vehicles where a sensor of the site can see a car."""
    out = []
    for stamp, vehicles in truth_frames:
        if not vehicles:
            out.append((stamp, vehicles))
            continue
        xy = np.array([(v.x_m, v.y_m) for v in vehicles])
        seen = coverage(xy[:, 0], xy[:, 1])
        out.append((stamp, [v for v, s in zip(vehicles, seen, strict=True) if s]))
    return out


def _episodes(queued: Sequence[bool], times: np.ndarray) -> list[_Episode]:
    episodes = []
    start: float | None = None
    for t, q in zip(times, queued, strict=True):
        if q and start is None:
            start = float(t)
        elif not q and start is not None:
            episodes.append(_Episode(start, float(t), False))
            start = None
    if start is not None:
        episodes.append(_Episode(start, float(times[-1]), True))
    return episodes


def _overlaps(a: _Episode, b: _Episode) -> bool:
    return a.start_s <= b.end_s and b.start_s <= a.end_s


def _stats(values: Sequence[float]) -> dict[str, float | int | None]:
    if not values:
        return {"median": None, "p90": None, "max": None, "count": 0}
    return {
        "median": round(statistics.median(values), 2),
        "p90": round(float(np.percentile(values, 90)), 2),
        "max": round(max(values), 2),
        "count": len(values),
    }


def beyond_reach_report(
    zone: ZoneGeometry,
    truth_frames: TruthFrames,
    est_lanes: dict[int, list[LaneQueue]],
    times: np.ndarray,
) -> dict[str, Any]:
    """A back beyond the sensors' reach against the truth's back on the whole approach (every
    vehicle, seen or not), at the seconds the estimate had the lane's back beyond the reach
    (see the module's notes)."""
    whole_reach = {lane.index: zone.approach_start_m for lane in zone.site.lanes}
    truth, _ = truth_batches(zone.site, truth_frames)
    whole = lane_series(zone, truth, whole_reach, times)
    seconds = bounded = within = 0
    widths: list[float] = []
    errors: list[float] = []
    past_reach: list[float] = []
    for index, est_lane in est_lanes.items():
        for tl, el in zip(whole[index], est_lane, strict=True):
            if not el.back_beyond_reach or tl.back_station_m is None:
                continue
            seconds += 1
            past_reach.append(abs(el.reach_station_m - tl.back_station_m))
            down = el.back_downstream_bound_m
            up = el.back_upstream_bound_m
            if up is None or down is None:
                continue
            bounded += 1
            widths.append(down - up)
            back = tl.back_station_m
            within += up - BOUND_TOLERANCE_M <= back <= down + BOUND_TOLERANCE_M
            errors.append(max(0.0, up - back, back - down))
    return {
        "seconds": seconds,
        "bounded_s": bounded,
        "truth_within_bounds_s": within,
        "bound_width_m": _stats(widths),
        "outside_by_m": _stats(errors),
        "reach_to_back_m": _stats(past_reach),
        "tolerance_m": BOUND_TOLERANCE_M,
    }


def queue_report(
    site: Site,
    track_batches: Sequence[TrackBatch],
    truth_frames: TruthFrames,
    start_s: float,
    end_s: float,
    coverage: SiteCoverage | None = None,
    point_readings: Sequence[PointSensorReading] = (),
) -> dict[str, Any]:
    """The lanes' queue estimated from ``track_batches`` (and the site's upstream point
    sensors' ``point_readings``) against the truth, over ``[start_s, end_s]`` (see the module's
    notes); ``coverage``: where the sensors see a car (default: the site's in clear
    weather)."""
    zone = ZoneGeometry.from_site(site)
    coverage = SiteCoverage(site) if coverage is None else coverage
    reach = upstream_reach_m(zone, coverage)
    times = np.arange(start_s, end_s + 1e-9, STEP_S)
    truth, _ = truth_batches(site, seen_frames(truth_frames, coverage))
    true_lanes = lane_series(zone, truth, reach, times)
    est_lanes = lane_series(zone, track_batches, reach, times, point_readings)
    hours = max(end_s - start_s, 1e-9) / 3600.0
    rule = site.alerts.queue
    lanes_report: dict[str, Any] = {}
    all_errors: list[float] = []
    onset: list[float] = []
    dissolution: list[float] = []
    totals = {"true_episodes": 0, "detected": 0, "false_episodes": 0, "false_s": 0.0}
    for index in sorted(true_lanes):
        truth_lane, est_lane = true_lanes[index], est_lanes[index]
        errors = []
        beyond_s = flagged_s = 0
        for tl, el in zip(truth_lane, est_lane, strict=True):
            if tl.back_station_m is None or el.back_station_m is None:
                continue
            if tl.back_beyond_reach:
                beyond_s += 1
                flagged_s += el.back_beyond_reach
            else:
                errors.append(abs(el.back_station_m - tl.back_station_m))
        t_eps = _episodes([q.condition is not QueueCondition.FREE for q in truth_lane], times)
        e_eps = _episodes([q.condition is not QueueCondition.FREE for q in est_lane], times)
        lane_onsets, lane_ends = [], []
        detected = 0
        for te in t_eps:
            match = [ee for ee in e_eps if _overlaps(te, ee)]
            if not match:
                continue
            detected += 1
            lane_onsets.append(match[0].start_s - te.start_s)
            if not te.open_at_end and not match[-1].open_at_end:
                lane_ends.append(match[-1].end_s - te.end_s)
        false = [ee for ee in e_eps if not any(_overlaps(ee, te) for te in t_eps)]
        false_s = sum(ee.end_s - ee.start_s + (STEP_S if ee.open_at_end else 0.0) for ee in false)
        all_errors += errors
        onset += lane_onsets
        dissolution += lane_ends
        totals["true_episodes"] += len(t_eps)
        totals["detected"] += detected
        totals["false_episodes"] += len(false)
        totals["false_s"] += false_s
        lanes_report[str(index)] = {
            "reach_station_m": round(reach[index], 1),
            "true_queued_s": sum(q.condition is not QueueCondition.FREE for q in truth_lane),
            "estimated_queued_s": sum(q.condition is not QueueCondition.FREE for q in est_lane),
            "back_error_m": _stats(errors),
            "beyond_reach_s": beyond_s,
            "beyond_reach_flagged_s": flagged_s,
            "true_episodes": len(t_eps),
            "detected_episodes": detected,
            "onset_delay_s": _stats(lane_onsets),
            "dissolution_delay_s": _stats(lane_ends),
            "false_episodes": len(false),
            "false_queued_s": false_s,
        }
    return {
        "definition": {
            "slow_speed_mps": rule.slow_speed_mps,
            "stopped_speed_mps": rule.stopped_speed_mps,
            "min_vehicles": rule.min_vehicles,
            "span_m": rule.span_m,
            "step_s": STEP_S,
        },
        "back_error_m": _stats(all_errors),
        "onset_delay_s": _stats(onset),
        "dissolution_delay_s": _stats(dissolution),
        "true_episodes": totals["true_episodes"],
        "detected_episodes": totals["detected"],
        "false_episodes": totals["false_episodes"],
        "false_episodes_per_hour": round(totals["false_episodes"] / hours, 2),
        "false_queued_s": totals["false_s"],
        "lanes": lanes_report,
        "beyond_reach": beyond_reach_report(zone, truth_frames, est_lanes, times)
        if site.point_sensors
        else None,
    }


def summary_line(report: dict[str, Any]) -> str:
    """One line for ``wz eval``'s summary."""
    back = report["back_error_m"]
    onset = report["onset_delay_s"]
    return (
        f"queue: {report['detected_episodes']}/{report['true_episodes']} lane episodes found, "
        f"back error median {back['median']} m (n={back['count']}), onset delay median "
        f"{onset['median']} s (worst {onset['max']}), {report['false_episodes']} false "
        f"({report['false_episodes_per_hour']}/h)"
    )
