"""The alert rules: small pure functions of one track (or all tracks) in the road frame.

Each rule takes what it measures (a track, its speed trend, its leader) with the zone and its
thresholds, and returns a :class:`Finding` when its condition holds, or None. ``active`` says
whether an episode of that rule is open for that track: an open episode is kept by a looser
(exit) threshold than the one that opens it (the enter threshold), so a measurement hovering at
the threshold cannot flicker. Timing (hold, clear, cool-down) is the engine's business
(:mod:`wz_alert_service.engine`), not the rules'.

Conventions: a rule fires at exactly its threshold (``>=`` for "above", ``<=`` for "below");
stations ``s`` [m] increase in the direction of travel, offsets ``d`` [m] are positive to the
left; speeds are the tracks' ground speeds [m/s]. Thresholds in mph (margins over a posted
limit) are converted with :data:`wz_shared.site.MPH_TO_MPS`.

Rules
-----
- :func:`speeding`: ``v - v_limit(s) >= margin``, within the approach.
- :func:`aggressive_approach`: ``a_req = (v^2 - v_zone^2) / (2 (s_taper - s)) >= a_comfort``,
  or past the advance-warning point, above the zone limit and not slowing.
- :func:`hard_braking`: ``-dv/dt >= k g``, ``dv/dt`` the least-squares slope of the speed.
- :func:`late_merge`: in the closed lane within a distance of the taper start, above a speed.
- :func:`short_ttc`: ``TTC = gap / (v_f - v_l)`` to the nearest vehicle ahead in the lane.
- :func:`queue`: several slow vehicles within a station span; reported at the queue's tail.
- :func:`intrusion`: in the closed lane inside the buffer or the activity area.
- :func:`queue_approach`: the deceleration needed to stop behind the back of the lane's queue.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from wz_alert_service.zone import ZoneGeometry
from wz_shared.messages import AlertSeverity, AlertType, LaneQueue, Track
from wz_shared.site import (
    MPH_TO_MPS,
    AggressiveApproachRule,
    HardBrakingRule,
    IntrusionRule,
    LateMergeRule,
    QueueApproachRule,
    QueueRule,
    ShortTtcRule,
    SpeedingRule,
)

#: Standard gravity [m/s^2].
G_MPS2 = 9.80665
#: The deceleration reported for no room left to stop (about 10 g: beyond any brakes).
NO_ROOM_DECEL_MPS2 = 100.0

SEVERITY_RANK: Mapping[AlertSeverity, int] = {
    AlertSeverity.INFO: 0,
    AlertSeverity.WARNING: 1,
    AlertSeverity.CRITICAL: 2,
}


@dataclass(frozen=True)
class Finding:
    """What a rule measured when its condition held, at one stamp.

    Attributes
    ----------
    alert_type, severity
        The rule and the severity band of ``measured_value``.
    measured_value, threshold_value : float
        The rule's quantity and the threshold that decided, both in ``value_unit``.
    value_unit : str
        ``"m/s"``, ``"m/s^2"``, ``"s"``, ``"m"`` or ``"vehicles"``.
    station_m, offset_m : float
        Where [m]: the track's position, or a queue's tail.
    speed_mps : float or None
        The track's speed (the tail vehicle's for a queue) [m/s].
    description : str
        One line for an operator.
    evidence : Mapping[str, float]
        The rule's other numbers, each key ending in its unit.
    track : Track or None
        The track (None for a site-level rule).
    """

    alert_type: AlertType
    severity: AlertSeverity
    measured_value: float
    threshold_value: float
    value_unit: str
    station_m: float
    offset_m: float
    speed_mps: float | None
    description: str
    evidence: Mapping[str, float] = field(default_factory=dict)
    track: Track | None = None

    @property
    def track_id(self) -> int | None:
        return None if self.track is None else self.track.track_id


def _mph(speed_mps: float) -> float:
    return speed_mps / MPH_TO_MPS


def _in_closed_lane(track: Track, zone: ZoneGeometry, widen_m: float, active: bool) -> bool:
    # Entering: the tracker's lane or the offset band; staying: only the widened band, so a
    # lane index flipping at the lane line cannot end the episode.
    if active:
        return zone.in_closed_lane(track.offset_m, widen_m)
    return track.lane_index == zone.closed_lane_index or zone.in_closed_lane(track.offset_m)


# --- speeding -------------------------------------------------------------------------------


def speeding(
    track: Track, zone: ZoneGeometry, rule: SpeedingRule, *, active: bool = False
) -> Finding | None:
    """Speed over the posted limit at the track's station, within the approach.

    Holds when ``v_z - v_limit(s) >= m`` with ``m = margin_mph`` to open and ``m = margin_mph -
    hysteresis_mph`` to stay open (converted to m/s); critical when the excess reaches
    ``critical_excess_mph``. ``v_z = v - z sigma_v`` is the lowest speed the track's
    covariance allows at ``z = certainty_sigmas`` (:func:`speed_variance`; 0: as measured).

    Parameters
    ----------
    track : Track
        ``speed_mps`` [m/s] and ``station_m`` [m] are used.
    zone : ZoneGeometry
        The approach and the posted limits.
    rule : SpeedingRule
        Margins [mph].
    active : bool
        Whether an episode is open (exit threshold).

    Returns
    -------
    Finding or None
        ``measured_value`` the speed [m/s], ``threshold_value`` ``v_limit + m`` [m/s].
    """
    if not zone.in_approach(track.station_m):
        return None
    limit_mps = zone.speed_limit_mps_at(track.station_m)
    margin_mph = rule.margin_mph - (rule.hysteresis_mph if active else 0.0)
    threshold_mps = limit_mps + margin_mph * MPH_TO_MPS
    sure_mps = track.speed_mps
    if rule.certainty_sigmas > 0.0:
        sure_mps -= rule.certainty_sigmas * math.sqrt(speed_variance(track))
    if sure_mps < threshold_mps:
        return None
    excess_mps = track.speed_mps - limit_mps
    critical = excess_mps >= rule.critical_excess_mph * MPH_TO_MPS
    return Finding(
        alert_type=AlertType.SPEEDING,
        severity=AlertSeverity.CRITICAL if critical else AlertSeverity.WARNING,
        measured_value=track.speed_mps,
        threshold_value=threshold_mps,
        value_unit="m/s",
        station_m=track.station_m,
        offset_m=track.offset_m,
        speed_mps=track.speed_mps,
        description=(
            f"speeding: {_mph(track.speed_mps):.0f} mph where the limit is "
            f"{_mph(limit_mps):.0f} mph (+{_mph(excess_mps):.0f} mph)"
        ),
        evidence={
            "speed_limit_mps": limit_mps,
            "excess_mps": excess_mps,
            "margin_mps": margin_mph * MPH_TO_MPS,
        },
        track=track,
    )


# --- aggressive approach --------------------------------------------------------------------


def required_deceleration_mps2(
    speed_mps: float, target_speed_mps: float, distance_m: float
) -> float:
    """Constant deceleration that brings a speed down to a target over a distance.

    ``a = (v^2 - v_target^2) / (2 D)`` [m/s^2], from ``v_target^2 = v^2 - 2 a D``; negative when
    ``v < v_target`` (no braking needed).

    Parameters
    ----------
    speed_mps : float
        Current speed v [m/s].
    target_speed_mps : float
        Speed to reach, v_target [m/s].
    distance_m : float
        Distance D available [m], > 0.
    """
    return (speed_mps**2 - target_speed_mps**2) / (2.0 * distance_m)


def aggressive_approach(
    track: Track,
    speed_trend_mps2: float | None,
    zone: ZoneGeometry,
    rule: AggressiveApproachRule,
    *,
    active: bool = False,
) -> Finding | None:
    """Too fast for the taper ahead: too much braking still needed, or not slowing at all.

    Upstream of the taper (``s < s_taper``, in the approach), with ``D = s_taper - s`` [m]
    and the zone limit ``v_zone`` [m/s] (the posted limit at the taper start), the condition
    holds when the speed is at least ``v_zone + speed_margin`` (while open: above ``v_zone``)
    and either

    - ``a_req = (v^2 - v_zone^2) / (2 D) >= a_c`` [m/s^2], ``a_c = comfortable_decel_mps2``
      to open and ``a_c - hysteresis_mps2`` to stay open; or
    - past the advance-warning point (``s >= advance_warning_m``), the speed trend
      ``dv/dt >= -not_slowing_decel_mps2`` (``- hysteresis_mps2`` more while open): the driver
      is not slowing.

    Critical when ``a_req >= critical_decel_mps2``, otherwise a warning.

    Parameters
    ----------
    track : Track
        ``speed_mps`` [m/s], ``station_m`` [m].
    speed_trend_mps2 : float or None
        Least-squares slope of the track's speed over ``trend_window_s`` [m/s^2] (see
        :func:`speed_trend_mps2`); None when the history is too short (only the first
        condition is then tested).
    zone : ZoneGeometry
        Taper start, zone limit, advance-warning point.
    rule : AggressiveApproachRule
        Thresholds.
    active : bool
        Whether an episode is open.

    Returns
    -------
    Finding or None
        ``measured_value`` ``a_req`` [m/s^2] and ``threshold_value`` ``a_c`` [m/s^2]; the
        evidence says which condition held (``not_slowing`` 1 or 0).
    """
    station_m, speed_mps = track.station_m, track.speed_mps
    if not (zone.in_approach(station_m) and station_m < zone.taper_start_m):
        return None
    zone_limit_mps = zone.zone_limit_mps
    fast_enough = (
        speed_mps > zone_limit_mps
        if active
        else speed_mps >= zone_limit_mps + rule.speed_margin_mph * MPH_TO_MPS
    )
    if not fast_enough:
        return None
    distance_m = zone.taper_start_m - station_m
    required_mps2 = required_deceleration_mps2(speed_mps, zone_limit_mps, distance_m)
    hysteresis = rule.hysteresis_mps2 if active else 0.0
    decel_threshold_mps2 = rule.comfortable_decel_mps2 - hysteresis
    too_hard = required_mps2 >= decel_threshold_mps2
    not_slowing = (
        speed_trend_mps2 is not None
        and station_m >= zone.advance_warning_m
        and speed_trend_mps2 >= -(rule.not_slowing_decel_mps2 + hysteresis)
    )
    if not (too_hard or not_slowing):
        return None
    critical = required_mps2 >= rule.critical_decel_mps2
    why = (
        f"needs {required_mps2:.1f} m/s^2 to reach {_mph(zone_limit_mps):.0f} mph in "
        f"{distance_m:.0f} m"
        if too_hard
        else f"not slowing ({speed_trend_mps2:+.1f} m/s^2) {distance_m:.0f} m before the taper"
    )
    evidence = {
        "required_decel_mps2": required_mps2,
        "distance_to_taper_m": distance_m,
        "zone_limit_mps": zone_limit_mps,
        "not_slowing": 1.0 if not_slowing else 0.0,
    }
    if speed_trend_mps2 is not None:
        evidence["speed_trend_mps2"] = speed_trend_mps2
    return Finding(
        alert_type=AlertType.AGGRESSIVE_APPROACH,
        severity=AlertSeverity.CRITICAL if critical else AlertSeverity.WARNING,
        measured_value=required_mps2,
        threshold_value=decel_threshold_mps2,
        value_unit="m/s^2",
        station_m=station_m,
        offset_m=track.offset_m,
        speed_mps=speed_mps,
        description=f"aggressive approach at {_mph(speed_mps):.0f} mph: {why}",
        evidence=evidence,
        track=track,
    )


# --- hard braking ---------------------------------------------------------------------------


def speed_trend_mps2(
    times_s: npt.ArrayLike, speeds_mps: npt.ArrayLike, *, min_samples: int, min_span_s: float
) -> float | None:
    """Least-squares slope of speed against time [m/s^2].

    ``b = sum((t_i - t_mean) (v_i - v_mean)) / sum((t_i - t_mean)^2)``: the straight line
    through n noisy speeds; with independent noise of std sigma over a span T the slope's std
    is about ``sigma * sqrt(12 / n) / T``, so 16 speeds over 0.8 s turn 0.3 m/s of noise into
    0.3 m/s^2.

    Parameters
    ----------
    times_s : array_like, shape (n,)
        Stamps [s].
    speeds_mps : array_like, shape (n,)
        Speeds [m/s].
    min_samples : int
        Fewest samples for a slope.
    min_span_s : float
        Shortest time span ``max(t) - min(t)`` for a slope [s].

    Returns
    -------
    float or None
        The slope (negative when slowing), or None with too few samples or too short a span.
    """
    t = np.asarray(times_s, dtype=np.float64)
    v = np.asarray(speeds_mps, dtype=np.float64)
    if t.size < min_samples or t.size < 2:
        return None
    span_s = float(t.max() - t.min())
    if span_s <= 0.0 or span_s < min_span_s:
        return None
    dt = t - t.mean()
    return float(np.dot(dt, v - v.mean()) / np.dot(dt, dt))


def _variance_along(track: Track, block: slice) -> float:
    """One 2x2 block of the track's covariance (position ``0:2``, velocity ``2:4``) along its
    direction of travel; half its trace when it stands, its direction unknown."""
    P = np.asarray(track.covariance, dtype=np.float64).reshape(4, 4)[block, block]
    speed = math.hypot(track.vx_mps, track.vy_mps)
    if speed < 0.5:
        return float(np.trace(P)) / 2.0
    axis = np.array([track.vx_mps, track.vy_mps]) / speed
    return float(axis @ P @ axis)


def speed_variance(track: Track) -> float:
    """The variance of the track's speed [m^2/s^2]: its velocity covariance along its
    direction of travel."""
    return _variance_along(track, slice(2, 4))


def position_variance_along(track: Track) -> float:
    """The variance of the track's position along its direction of travel [m^2]."""
    return _variance_along(track, slice(0, 2))


def speed_trend_std_mps2(times_s: npt.ArrayLike, variances: npt.ArrayLike) -> float | None:
    """The standard deviation of a speed's slope over a window [m/s^2], from the speed's own
    variance at its ends: ``sqrt(var_first + var_last) / span``.

    A filter's speeds from one update to the next are not independent, so the slope's error
    is not the one of n independent samples (:func:`speed_trend_mps2`'s ``sigma sqrt(12/n) /
    T``); the difference of the ends over the span bounds it. None with fewer than two
    samples or no span.
    """
    t = np.asarray(times_s, dtype=np.float64)
    var = np.asarray(variances, dtype=np.float64)
    if t.size < 2:
        return None
    span_s = float(t.max() - t.min())
    if span_s <= 0.0:
        return None
    first, last = int(np.argmin(t)), int(np.argmax(t))
    return math.sqrt(max(float(var[first] + var[last]), 0.0)) / span_s


def hard_braking(
    track: Track,
    speed_trend_mps2: float | None,
    zone: ZoneGeometry,
    rule: HardBrakingRule,
    *,
    active: bool = False,
    trend_std_mps2: float | None = None,
) -> Finding | None:
    """Deceleration beyond a fraction of g, within the approach, on a track whose speed is
    measured well enough to tell it.

    Holds when ``-dv/dt >= k g`` with ``k = decel_g`` to open and ``k = decel_g -
    hysteresis_g`` to stay open (g = 9.80665 m/s^2), and the threshold stands ``z`` of the
    slope's standard deviations clear of no braking at all: ``k g >= z sigma``, ``sigma`` from
    the track's speed variances (``trend_std_mps2``, 0 when not given), ``z =
    certainty_sigmas``. A speed the sensors hardly measure (a vehicle seen by a few beams far
    down the road, a track just handed over) swings by more than braking would: its slope
    cannot tell a stop from steady driving. Critical from ``critical_decel_g``.

    Parameters
    ----------
    track : Track
        Position and speed at this stamp.
    speed_trend_mps2 : float or None
        Least-squares slope of the speed over ``window_s`` [m/s^2]; None: too little history.
    zone : ZoneGeometry
        The approach.
    rule : HardBrakingRule
        Thresholds [g].
    active : bool
        Whether an episode is open.

    Returns
    -------
    Finding or None
        ``measured_value`` the deceleration ``-dv/dt`` [m/s^2], ``threshold_value`` ``k g``.
    """
    if speed_trend_mps2 is None or not zone.in_approach(track.station_m):
        return None
    decel_mps2 = -speed_trend_mps2
    threshold_mps2 = (rule.decel_g - (rule.hysteresis_g if active else 0.0)) * G_MPS2
    if decel_mps2 < threshold_mps2:
        return None
    if rule.certainty_sigmas * (trend_std_mps2 or 0.0) > threshold_mps2:
        return None  # the speed is too uncertain to tell braking from noise
    critical = decel_mps2 >= rule.critical_decel_g * G_MPS2
    return Finding(
        alert_type=AlertType.HARD_BRAKING,
        severity=AlertSeverity.CRITICAL if critical else AlertSeverity.WARNING,
        measured_value=decel_mps2,
        threshold_value=threshold_mps2,
        value_unit="m/s^2",
        station_m=track.station_m,
        offset_m=track.offset_m,
        speed_mps=track.speed_mps,
        description=f"hard braking at {decel_mps2 / G_MPS2:.2f} g from {_mph(track.speed_mps):.0f} mph",
        evidence={
            "decel_g": decel_mps2 / G_MPS2,
            "decel_std_g": (trend_std_mps2 or 0.0) / G_MPS2,
            "window_s": rule.window_s,
        },
        track=track,
    )


# --- late merge -----------------------------------------------------------------------------


def late_merge(
    track: Track, zone: ZoneGeometry, rule: LateMergeRule, *, active: bool = False
) -> Finding | None:
    """Still in the closed lane close to (or inside) the taper, at speed.

    Holds for ``s_taper - distance_m <= s < s_taper_end``, in the closed lane (its index, or
    ``low <= d < high``; while open: ``low - h <= d < high + h``, h = ``lateral_hysteresis_m``)
    at ``v >= min_speed_mps`` (while open ``min_speed_mps - speed_hysteresis_mps``). Critical
    inside the taper, a warning before it.

    Parameters
    ----------
    track : Track
        ``station_m``, ``offset_m`` [m], ``lane_index``, ``speed_mps`` [m/s].
    zone : ZoneGeometry
        Taper and closed lane.
    rule : LateMergeRule
        Thresholds.
    active : bool
        Whether an episode is open.

    Returns
    -------
    Finding or None
        ``measured_value`` the distance to the taper start ``s_taper - s`` [m] (negative inside
        the taper), ``threshold_value`` ``distance_m``.
    """
    distance_m = zone.taper_start_m - track.station_m
    if not (distance_m <= rule.distance_m and track.station_m < zone.taper_end_m):
        return None
    min_speed_mps = rule.min_speed_mps - (rule.speed_hysteresis_mps if active else 0.0)
    if track.speed_mps < min_speed_mps:
        return None
    if not _in_closed_lane(track, zone, rule.lateral_hysteresis_m, active):
        return None
    in_taper = distance_m <= 0.0
    where = "in the taper" if in_taper else f"{distance_m:.0f} m before the taper"
    return Finding(
        alert_type=AlertType.LATE_MERGE,
        severity=AlertSeverity.CRITICAL if in_taper else AlertSeverity.WARNING,
        measured_value=distance_m,
        threshold_value=rule.distance_m,
        value_unit="m",
        station_m=track.station_m,
        offset_m=track.offset_m,
        speed_mps=track.speed_mps,
        description=f"late merge: still in the closed lane {where} at {_mph(track.speed_mps):.0f} mph",
        evidence={
            "distance_to_taper_m": distance_m,
            "depth_in_closed_lane_m": zone.depth_in_closed_lane_m(track.offset_m),
            "min_speed_mps": min_speed_mps,
        },
        track=track,
    )


# --- short time to collision ----------------------------------------------------------------


def leaders(tracks: Iterable[Track]) -> dict[int, Track]:
    """The nearest track ahead in the same lane, for each track that has one.

    Ahead means a strictly greater station; tracks between lanes (``lane_index`` -1) have no
    leader and lead no one.

    Returns
    -------
    dict
        ``{follower track_id: leader Track}``.
    """
    by_lane: defaultdict[int, list[Track]] = defaultdict(list)
    for track in tracks:
        if track.lane_index >= 0:
            by_lane[track.lane_index].append(track)
    result: dict[int, Track] = {}
    for lane_tracks in by_lane.values():
        ordered = sorted(lane_tracks, key=lambda t: (t.station_m, t.track_id))
        for i, follower in enumerate(ordered):
            for candidate in ordered[i + 1 :]:
                if candidate.station_m > follower.station_m:
                    result[follower.track_id] = candidate
                    break
    return result


def bumper_gap_m(follower: Track, leader: Track, default_length_m: float) -> float:
    """Gap from the follower's front to the leader's rear [m].

    ``gap = s_l - s_f - (L_f + L_l) / 2``: stations are the vehicles' centres; a length the
    tracker has not estimated is ``default_length_m``.
    """
    length_f = follower.length_m if follower.length_m is not None else default_length_m
    length_l = leader.length_m if leader.length_m is not None else default_length_m
    return leader.station_m - follower.station_m - 0.5 * (length_f + length_l)


def time_to_collision_s(gap_m: float, closing_speed_mps: float) -> float:
    """``TTC = gap / closing speed`` [s]; infinite when not closing (``closing <= 0``)."""
    if closing_speed_mps <= 0.0:
        return float("inf")
    return gap_m / closing_speed_mps


def short_ttc(
    follower: Track,
    leader: Track | None,
    zone: ZoneGeometry,
    rule: ShortTtcRule,
    *,
    active: bool = False,
) -> Finding | None:
    """Time to collision with the vehicle ahead below SSAM-style bins, within the approach.

    ``TTC = gap / (v_f - v_l)`` with ``gap = s_l - s_f - (L_f + L_l) / 2`` [m]. What is
    decided on is the longest TTC the tracks' covariances allow at ``z = certainty_sigmas``:
    ``TTC_z = (gap + z sigma_gap) / (v_f - v_l - z sigma_closing)``, ``sigma_gap^2`` the sum
    of the two positions' variances along the road, ``sigma_closing^2`` of their speeds'
    (:func:`speed_variance`); a speed noise of 0.5 m/s each is a closing speed of 1.4 m/s at
    2 sigma. Holds for ``v_f - v_l - z sigma_closing >= min_closing_speed_mps``, ``gap > 0``
    and ``TTC_z <= max_ttc_s`` (while open ``max_ttc_s + hysteresis_s``), both tracks at
    least ``min_track_age_s`` old. Severity by
    ``TTC_z``: critical ``<= critical_ttc_s``, warning ``<= warning_ttc_s``, info otherwise.
    Overlapping boxes (``gap <= 0``) are one vehicle tracked twice or a crash; a TTC
    describes neither, so they do not hold.

    Parameters
    ----------
    follower, leader : Track
        The follower and the nearest vehicle ahead in its lane (see :func:`leaders`).
    zone : ZoneGeometry
        The approach.
    rule : ShortTtcRule
        Bins [s], default length [m].
    active : bool
        Whether an episode is open.

    Returns
    -------
    Finding or None
        ``measured_value`` ``TTC_z`` [s], ``threshold_value`` the bound that decided [s];
        the evidence has the TTC as measured.
    """
    if leader is None or not zone.in_approach(follower.station_m):
        return None
    if min(follower.age_s, leader.age_s) < rule.min_track_age_s:
        return None
    z = rule.certainty_sigmas
    closing_mps = follower.speed_mps - leader.speed_mps
    closing_sure_mps = closing_mps - z * math.sqrt(
        speed_variance(follower) + speed_variance(leader)
    )
    gap_m = bumper_gap_m(follower, leader, rule.default_vehicle_length_m)
    if closing_sure_mps < rule.min_closing_speed_mps or gap_m <= 0.0:
        return None
    gap_sure_m = gap_m + z * math.sqrt(
        position_variance_along(follower) + position_variance_along(leader)
    )
    ttc_s = time_to_collision_s(gap_sure_m, closing_sure_mps)
    threshold_s = rule.max_ttc_s + (rule.hysteresis_s if active else 0.0)
    if ttc_s > threshold_s:
        return None
    if ttc_s <= rule.critical_ttc_s:
        severity = AlertSeverity.CRITICAL
    elif ttc_s <= rule.warning_ttc_s:
        severity = AlertSeverity.WARNING
    else:
        severity = AlertSeverity.INFO
    return Finding(
        alert_type=AlertType.SHORT_TTC,
        severity=severity,
        measured_value=ttc_s,
        threshold_value=threshold_s,
        value_unit="s",
        station_m=follower.station_m,
        offset_m=follower.offset_m,
        speed_mps=follower.speed_mps,
        description=(
            f"short time to collision {ttc_s:.2f} s: {gap_m:.1f} m behind track "
            f"{leader.track_id}, closing at {closing_mps:.1f} m/s"
        ),
        evidence={
            "gap_m": gap_m,
            "closing_speed_mps": closing_mps,
            "measured_ttc_s": time_to_collision_s(gap_m, closing_mps),
            "leader_track_id": float(leader.track_id),
            "leader_station_m": leader.station_m,
            "leader_speed_mps": leader.speed_mps,
        },
        track=follower,
    )


# --- queue ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class QueueExtent:
    """Slow vehicles that form a queue.

    Attributes
    ----------
    tail_station_m, head_station_m : float
        The most upstream and most downstream queued vehicle [m].
    vehicle_count : int
        Slow vehicles that belong to a group of ``min_vehicles`` within ``span_m``.
    """

    tail_station_m: float
    head_station_m: float
    vehicle_count: int


def queue_extent(
    stations_m: Sequence[float], *, min_vehicles: int, span_m: float
) -> QueueExtent | None:
    """Where slow vehicles form a queue: k of them within a span of station.

    With the slow vehicles' stations sorted, ``s_0 <= s_1 <= ...``, vehicles ``j .. j+k-1``
    form a group when ``s_{j+k-1} - s_j <= span_m`` (k = ``min_vehicles``). Every vehicle of a
    group is queued; the tail is the lowest queued station, the head the highest.

    Parameters
    ----------
    stations_m : sequence of float
        Stations of the slow vehicles [m], any order.
    min_vehicles : int
        k >= 1.
    span_m : float
        Longest station span of a group [m].

    Returns
    -------
    QueueExtent or None
        None when no group exists.
    """
    ordered = sorted(stations_m)
    k = min_vehicles
    queued = [False] * len(ordered)
    for j in range(len(ordered) - k + 1):
        if ordered[j + k - 1] - ordered[j] <= span_m:
            queued[j : j + k] = [True] * k
    members = [s for s, q in zip(ordered, queued, strict=True) if q]
    if not members:
        return None
    return QueueExtent(members[0], members[-1], len(members))


def queue(
    tracks: Iterable[Track], zone: ZoneGeometry, rule: QueueRule, *, active: bool = False
) -> Finding | None:
    """Slow or stopped traffic in the approach; a site-level finding at the queue's tail.

    A track is slow at ``v < slow_speed_mps`` (while open ``slow_speed_mps +
    speed_hysteresis_mps``); the slow tracks in the approach form a queue by
    :func:`queue_extent`. Critical when the tail is ``critical_backup_m`` or more upstream of
    the taper start (``s_taper - s_tail >= critical_backup_m``), otherwise a warning.

    Parameters
    ----------
    tracks : iterable of Track
        Every track of the batch.
    zone : ZoneGeometry
        The approach and the taper.
    rule : QueueRule
        Thresholds.
    active : bool
        Whether a queue episode is open.

    Returns
    -------
    Finding or None
        ``station_m`` the tail [m]; ``measured_value`` the queued vehicles, ``threshold_value``
        ``min_vehicles``; ``track`` None.
    """
    slow_mps = rule.slow_speed_mps + (rule.speed_hysteresis_mps if active else 0.0)
    slow = [t for t in tracks if zone.in_approach(t.station_m) and t.speed_mps < slow_mps]
    extent = queue_extent(
        [t.station_m for t in slow], min_vehicles=rule.min_vehicles, span_m=rule.span_m
    )
    if extent is None:
        return None
    tail = min((t for t in slow if t.station_m == extent.tail_station_m), key=lambda t: t.track_id)
    backup_m = zone.taper_start_m - extent.tail_station_m
    critical = backup_m >= rule.critical_backup_m
    return Finding(
        alert_type=AlertType.QUEUE,
        severity=AlertSeverity.CRITICAL if critical else AlertSeverity.WARNING,
        measured_value=float(extent.vehicle_count),
        threshold_value=float(rule.min_vehicles),
        value_unit="vehicles",
        station_m=extent.tail_station_m,
        offset_m=tail.offset_m,
        speed_mps=tail.speed_mps,
        description=(
            f"queue of {extent.vehicle_count} slow vehicles, tail at {extent.tail_station_m:.0f} m "
            f"({backup_m:.0f} m before the taper)"
        ),
        evidence={
            "queue_tail_station_m": extent.tail_station_m,
            "queue_head_station_m": extent.head_station_m,
            "queue_length_m": extent.head_station_m - extent.tail_station_m,
            "tail_to_taper_m": backup_m,
            "tail_track_id": float(tail.track_id),
            "slow_speed_mps": slow_mps,
        },
        track=None,
    )


# --- approaching the queue too fast ---------------------------------------------------------


def queue_approach(
    track: Track,
    lane_queue: LaneQueue | None,
    zone: ZoneGeometry,
    rule: QueueApproachRule,
    *,
    slow_speed_mps: float,
    active: bool = False,
) -> Finding | None:
    """Closing on the back of the lane's queue faster than a comfortable stop allows.

    With the queue's back ``s_b`` and mean speed ``u``, the track at ``s < s_b`` with speed
    ``v > u``: ``D = s_b - s - stop_spacing_m`` and ``a = (v^2 - u^2) / (2 D)`` (``a`` taken as
    infinite for ``D <= 0``: no room left). Holds at ``a >= comfortable_decel_mps2`` (while
    open: ``comfortable_decel_mps2 - hysteresis_mps2``); critical from
    ``critical_decel_mps2``. A track slow itself (below ``slow_speed_mps``, the queue's own
    threshold) is part of the traffic the queue is made of, not approaching it. Nor is any
    track while the lane's back stands beyond the sensors' reach (``back_beyond_reach``): the
    back is then somewhere upstream of all the sensors see, so every seen track is in the
    queue or past its back, and a fast one there is a track new at the edge of sight whose
    speed is not yet known; the sign warns of the queue (docs/alerts.md).

    Parameters
    ----------
    track : Track
        ``station_m``, ``speed_mps``.
    lane_queue : LaneQueue or None
        The track's lane's queue now (None, or a free lane: nothing to approach).
    zone : ZoneGeometry
        The approach.
    rule : QueueApproachRule
        Thresholds.
    slow_speed_mps : float
        The queue rule's slow speed [m/s].
    active : bool
        Whether an episode is open (exit threshold).

    Returns
    -------
    Finding or None
        ``measured_value`` ``a`` [m/s^2] (capped at 100 for no room), ``threshold_value`` the
        threshold; evidence: the back, the room, the queue's speed and the lead time
        ``time_to_back_s = D / (v - u)``.
    """
    if lane_queue is None or lane_queue.back_station_m is None or lane_queue.back_beyond_reach:
        return None
    if not zone.in_approach(track.station_m) or track.speed_mps < slow_speed_mps:
        return None
    back_m = lane_queue.back_station_m
    queue_mps = lane_queue.mean_speed_mps or 0.0
    closing_mps = track.speed_mps - queue_mps
    if track.station_m >= back_m or closing_mps <= 0.0:
        return None
    room_m = back_m - track.station_m - rule.stop_spacing_m
    needed = (
        NO_ROOM_DECEL_MPS2
        if room_m <= 0.0
        else min(NO_ROOM_DECEL_MPS2, required_deceleration_mps2(track.speed_mps, queue_mps, room_m))
    )
    threshold = rule.comfortable_decel_mps2 - (rule.hysteresis_mps2 if active else 0.0)
    if needed < threshold:
        return None
    critical = needed >= rule.critical_decel_mps2
    lead_s = max(0.0, room_m) / closing_mps
    return Finding(
        alert_type=AlertType.QUEUE_APPROACH,
        severity=AlertSeverity.CRITICAL if critical else AlertSeverity.WARNING,
        measured_value=needed,
        threshold_value=threshold,
        value_unit="m/s^2",
        station_m=track.station_m,
        offset_m=track.offset_m,
        speed_mps=track.speed_mps,
        description=(
            f"approaching the queue too fast: {_mph(track.speed_mps):.0f} mph, "
            f"{max(0.0, room_m):.0f} m to stop behind the back of lane {lane_queue.lane_index}'s "
            f"queue ({needed:.1f} m/s^2 needed, {lead_s:.1f} s)"
        ),
        evidence={
            "queue_back_station_m": back_m,
            "room_m": room_m,
            "queue_speed_mps": queue_mps,
            "time_to_back_s": lead_s,
        },
        track=track,
    )


# --- intrusion ------------------------------------------------------------------------------


def intrusion(
    track: Track, zone: ZoneGeometry, rule: IntrusionRule, *, active: bool = False
) -> Finding | None:
    """A vehicle in the closed lane inside the buffer or the activity area.

    Holds for ``s_buffer <= s < s_activity_end`` in the closed lane (its index, or ``low <= d
    < high``; while open ``low - h <= d < high + h``, h = ``lateral_hysteresis_m``) at ``v >=
    min_speed_mps`` (while open at any speed: an errant vehicle that stops among the workers is
    still there). Critical in the activity area, a warning in the buffer.

    Parameters
    ----------
    track : Track
        ``station_m``, ``offset_m`` [m], ``lane_index``, ``speed_mps`` [m/s].
    zone : ZoneGeometry
        Buffer, activity area and the closed lane.
    rule : IntrusionRule
        Thresholds.
    active : bool
        Whether an episode is open.

    Returns
    -------
    Finding or None
        ``measured_value`` the depth inside the closed lane's band ``min(d - low, high - d)``
        [m], ``threshold_value`` 0 (``-h`` while open).
    """
    station_m = track.station_m
    if not (zone.work_space_start_m <= station_m < zone.approach_end_m):
        return None
    if not active and track.speed_mps < rule.min_speed_mps:
        return None
    if not _in_closed_lane(track, zone, rule.lateral_hysteresis_m, active):
        return None
    in_activity = station_m >= zone.activity_start_m
    return Finding(
        alert_type=AlertType.INTRUSION,
        severity=AlertSeverity.CRITICAL if in_activity else AlertSeverity.WARNING,
        measured_value=zone.depth_in_closed_lane_m(track.offset_m),
        threshold_value=-rule.lateral_hysteresis_m if active else 0.0,
        value_unit="m",
        station_m=station_m,
        offset_m=track.offset_m,
        speed_mps=track.speed_mps,
        description=(
            f"intrusion into the closed lane in the {'activity area' if in_activity else 'buffer'}"
            f" at {_mph(track.speed_mps):.0f} mph"
        ),
        evidence={
            "closed_lane_low_m": zone.closed_low_m,
            "closed_lane_high_m": zone.closed_high_m,
            "min_speed_mps": rule.min_speed_mps,
        },
        track=track,
    )
