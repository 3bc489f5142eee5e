"""Scoring the alert service against simulation truth: precision, recall and lead time per type.

Ground truth is what a perfect perception chain would give: the same :class:`AlertEngine`, with
the site's thresholds, hold, clear and cool-down times, run on the *true* kinematics (each
simulated vehicle as a confirmed track with its true station, offset, lane, speed and length).
So speeding truth is "the true speed was above limit + margin for the hold time within the
approach", late-merge truth "the true vehicle was in the closed lane within the taper distance
at speed", and so on; the scores then measure the perception chain (sensors, detectors,
tracker), not the rules.

Matching, per alert type
------------------------
- An alert episode (its start event; updates and the clear only end it) is tied to a vehicle.
  Given the tracks the alerts came from (:func:`track_follows`), it is the vehicle its track
  followed for most of the episode: at each track cycle from its start to its clear, the
  vehicle the track was matched to (one-to-one, least total distance, within ``tie_gate_m``).
  So an alert whose track starts a few metres off its vehicle (a far camera box that took in
  the car in the next lane) is still about the vehicle the track then follows. Without the
  tracks, or when its track matched no vehicle during the episode, it is the truth vehicle
  nearest the alert's position at its start stamp, within ``tie_gate_m`` (3 m) in the road frame,
  ``sqrt(ds^2 + dd^2)`` (truth moved to the stamp from the nearest step, see
  :class:`wz_eval.metrics.TruthIndex`). Site-level alerts (the queue) need no vehicle.
- Each episode spans ``[onset, clear]`` (to the end of the data when it never cleared). An
  alert episode matches a truth episode of the same type and vehicle when their spans,
  widened by ``slack_s`` on each side, overlap. Alert episodes are taken in start order; each
  truth episode takes at most one (the first): a true positive.
- A false positive is an alert episode tied to no vehicle, to a vehicle with no such truth
  episode, or to a truth episode already matched (a duplicate: "one alert per event" broken,
  e.g. by a track that split); ``duplicates`` counts the last kind. A false negative is a
  truth episode no alert matched.
- ``precision = TP / (TP + FP)``, ``recall = TP / (TP + FN)``; None where undefined.

Lead time: for each true positive whose vehicle reaches the taper's start station in the
truth (crossing it between two steps, interpolated), ``t_taper - t_alert_start`` [s]; negative
when the alert came after the vehicle was at the taper. ``lead_time_s`` is their median;
``truth_lead_time_s`` the same for the truth episodes (what a perfect chain would give); for
speeding, ``lead_time_aggressive_s`` restricts the median to aggressive drivers.

The truth covers the whole simulated road; to score the chain within its sensors' coverage,
pass truth frames cut to the covered stretch (a vehicle never seen cannot be alerted on), and
to the vehicles the sensors saw (:func:`observed_truth`): from a mast beside the road a car
overtaking a truck, or side by side with another car further out, is hidden from every sensor
for seconds, and no software on the mast can alert on what it cannot see. That is how MOT
benchmarks treat objects no sensor could see (MOTChallenge leaves out boxes below a visibility
threshold); ``wz eval`` reports the scores both ways.
Pure: no I/O; :func:`run_alert_engine` and :func:`score_alerts` are what ``wz eval`` calls.
"""

from __future__ import annotations

import bisect
import math
import statistics
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from wz_alert_service.engine import AlertEngine, AlertEvent
from wz_alert_service.zone import ZoneGeometry
from wz_eval.metrics import TruthIndex, match
from wz_shared.messages import (
    Alert,
    AlertType,
    DetectionBatch,
    DriverProfile,
    Track,
    TrackBatch,
    TrackStatus,
    VehicleTruth,
)
from wz_shared.site import Site

TruthFrames = Sequence[tuple[float, Sequence[VehicleTruth]]]
#: Largest distance from an alert's position to the vehicle it is tied to [m].
TIE_GATE_M = 3.0
#: How far apart in time an alert's and a truth episode's spans may be and still match [s].
MATCH_SLACK_S = 1.0
#: Largest gap between an alert's stamp and the nearest truth step [s].
MAX_TRUTH_GAP_S = 0.06
TRUTH_SOURCE = "truth"
#: False alerts listed per type in the report (where each started), to find why.
MAX_FALSE_STARTS = 20


@dataclass(frozen=True)
class Episode:
    """One alert episode, from the perception chain or from the truth.

    Attributes
    ----------
    episode_id : str
        The engine's id.
    alert_type : AlertType
        The rule.
    vehicle_id : str or None
        The truth vehicle it is tied to (None: a site-level alert, or tied to no vehicle).
    start_s, onset_s, end_s : float
        When it started, when its condition first held, when it cleared (``inf``: never) [s].
    site_level : bool
        A queue: no vehicle to tie.
    """

    episode_id: str
    alert_type: AlertType
    vehicle_id: str | None
    start_s: float
    onset_s: float
    end_s: float
    site_level: bool = False

    def overlaps(self, other: Episode, slack_s: float) -> bool:
        """Whether the spans ``[onset, end]`` widened by ``slack_s`` a side overlap."""
        return self.onset_s - slack_s <= other.end_s and other.onset_s - slack_s <= self.end_s


@dataclass(frozen=True)
class _Event:
    """An AlertEvent or an Alert message, reduced to what scoring needs."""

    episode_id: str
    alert_type: AlertType
    phase: str
    stamp_s: float
    onset_s: float
    station_m: float
    offset_m: float
    site_level: bool
    track_id: int | None = None


def _as_event(event: AlertEvent | Alert) -> _Event:
    if isinstance(event, AlertEvent):
        return _Event(
            event.episode_id,
            event.alert_type,
            event.phase,
            event.stamp,
            event.onset_stamp,
            event.finding.station_m,
            event.finding.offset_m,
            event.track_id is None,
            event.track_id,
        )
    onset = event.stamp if event.onset_stamp is None else event.onset_stamp
    return _Event(
        event.episode_id or event.alert_id,
        event.alert_type,
        event.phase,
        event.stamp,
        onset,
        event.station_m,
        event.offset_m,
        event.track_id is None,
        event.track_id,
    )


def run_alert_engine(site: Site, track_batches: Iterable[TrackBatch]) -> list[AlertEvent]:
    """The events of a fresh :class:`AlertEngine` (the site's thresholds) fed ``track_batches``
    in the order given (as the node would be; batches older than the last are ignored)."""
    engine = AlertEngine(site)
    events: list[AlertEvent] = []
    for batch in track_batches:
        events += engine.update(batch)
    return events


def truth_batches(site: Site, truth_frames: TruthFrames) -> tuple[list[TrackBatch], dict[int, str]]:
    """Each truth frame as a track batch: every vehicle a confirmed track with its true state.

    Returns
    -------
    batches : list of TrackBatch
        One per frame, in the frames' order.
    vehicle_of : dict
        ``{track_id: vehicle_id}`` (track ids given in order of first appearance).
    """
    track_of: dict[str, int] = {}
    first_seen_s: dict[str, float] = {}
    batches = []
    for index, (stamp_s, vehicles) in enumerate(truth_frames):
        tracks = []
        for v in vehicles:
            track_id = track_of.setdefault(v.vehicle_id, len(track_of))
            age_s = stamp_s - first_seen_s.setdefault(v.vehicle_id, stamp_s)
            tracks.append(
                Track(
                    track_id=track_id,
                    x_m=v.x_m,
                    y_m=v.y_m,
                    vx_mps=v.speed_mps * math.cos(v.heading_rad),
                    vy_mps=v.speed_mps * math.sin(v.heading_rad),
                    covariance=[0.0] * 16,
                    station_m=v.station_m,
                    offset_m=v.offset_m,
                    speed_mps=v.speed_mps,
                    heading_rad=v.heading_rad,
                    lane_index=v.lane_index,
                    object_class=v.vehicle_class,
                    age_s=max(0.0, age_s),
                    hits=1,
                    confirmed=True,
                    sources=[TRUTH_SOURCE],
                    status=TrackStatus.CONFIRMED,
                    length_m=v.length_m,
                    width_m=v.width_m,
                    last_update_s=stamp_s,
                )
            )
        batches.append(
            TrackBatch(
                site=site.site_id,
                source_id=TRUTH_SOURCE,
                stamp=stamp_s,
                cycle_index=index,
                tracks=tracks,
            )
        )
    return batches, {track_id: vehicle_id for vehicle_id, track_id in track_of.items()}


def _episodes(events: Iterable[_Event], vehicle_of_start: dict[str, str | None]) -> list[Episode]:
    """Episodes from their events: spans from the starts and clears."""
    starts: dict[str, _Event] = {}
    ends: dict[str, float] = {}
    for event in events:
        if event.phase == "start":
            starts.setdefault(event.episode_id, event)
        elif event.phase == "clear":
            ends[event.episode_id] = event.stamp_s
    ordered = sorted(starts.items(), key=lambda item: item[1].stamp_s)
    return [
        Episode(
            episode_id,
            start.alert_type,
            vehicle_of_start.get(episode_id),
            start.stamp_s,
            start.onset_s,
            ends.get(episode_id, math.inf),
            start.site_level,
        )
        for episode_id, start in ordered
    ]


def truth_episodes(site: Site, truth_frames: TruthFrames) -> list[Episode]:
    """The episodes the engine finds on the true kinematics, each with its vehicle. What the
    rules ask of a track's evidence (the short-TTC rule's ``min_track_age_s``: a vehicle
    followed long enough for its speed to be known) does not apply to the truth, whose every
    vehicle is known from its first frame."""
    batches, vehicle_of = truth_batches(site, truth_frames)
    rules = site.alerts.model_copy(
        update={"short_ttc": site.alerts.short_ttc.model_copy(update={"min_track_age_s": 0.0})}
    )
    events = run_alert_engine(site.model_copy(update={"alerts": rules}), batches)
    vehicles = {
        e.episode_id: None if e.track_id is None else vehicle_of[e.track_id]
        for e in events
        if e.phase == "start"
    }
    return _episodes(map(_as_event, events), vehicles)


def without_cooldowns(site: Site) -> Site:
    """``site`` with every alert rule's ``cooldown_s`` at 0: each of a vehicle's episodes
    stands, also one that follows another of its kind within the cooldown."""
    changed = {
        name: rule.model_copy(update={"cooldown_s": 0.0})
        for name, rule in site.alerts
        if hasattr(rule, "cooldown_s")
    }
    return site.model_copy(update={"alerts": site.alerts.model_copy(update=changed)})


def tie_to_vehicle(
    truth: TruthIndex, stamp_s: float, station_m: float, offset_m: float, gate_m: float = TIE_GATE_M
) -> str | None:
    """The truth vehicle nearest ``(station, offset)`` at ``stamp_s`` within ``gate_m``."""
    vehicles = truth.at(stamp_s, MAX_TRUTH_GAP_S)
    if not vehicles:
        return None
    nearest = min(
        vehicles, key=lambda v: math.hypot(v.station_m - station_m, v.offset_m - offset_m)
    )
    distance_m = math.hypot(nearest.station_m - station_m, nearest.offset_m - offset_m)
    return nearest.vehicle_id if distance_m <= gate_m else None


#: Per track id, ``(stamp [s], vehicle id)`` of each cycle its track was matched to a vehicle.
TrackFollows = dict[int, list[tuple[float, str]]]


def _matched(
    index: TruthIndex, stamp_s: float, estimates_xy: list[tuple[float, float]], gate_m: float
) -> list[tuple[int, VehicleTruth]]:
    """``(estimate index, vehicle)`` pairs: site positions matched one-to-one to the truth at
    ``stamp_s`` (least total distance, pairs within ``gate_m``)."""
    vehicles = index.at(stamp_s, MAX_TRUTH_GAP_S)
    if not vehicles or not estimates_xy:
        return []
    truth_xy = np.array([(v.x_m, v.y_m) for v in vehicles], dtype=np.float64)
    pairs = match(np.array(estimates_xy, dtype=np.float64), truth_xy, gate_m)
    return [(e, vehicles[v]) for e, v in pairs]


def track_follows(
    track_batches: Iterable[TrackBatch], truth_frames: TruthFrames, gate_m: float = TIE_GATE_M
) -> TrackFollows:
    """Which vehicle each track followed, cycle by cycle: the batch's tracks matched one-to-one
    to the truth at its stamp (least total distance, pairs within ``gate_m``)."""
    index = TruthIndex([(stamp, list(vehicles)) for stamp, vehicles in truth_frames])
    follows: TrackFollows = {}
    for batch in track_batches:
        estimates = [(t.x_m, t.y_m) for t in batch.tracks]
        for t, vehicle in _matched(index, batch.stamp, estimates, gate_m):
            follows.setdefault(batch.tracks[t].track_id, []).append(
                (batch.stamp, vehicle.vehicle_id)
            )
    return follows


#: A vehicle counts as seen for this long after a detection within the tie gate [s]: a sensor
#: misses a frame or two, and a rule's hold needs its kinematics continuously.
OBSERVED_HOLD_S = 1.0


def observed_truth(
    truth_frames: TruthFrames,
    detection_batches: Iterable[DetectionBatch],
    gate_m: float = TIE_GATE_M,
    hold_s: float = OBSERVED_HOLD_S,
) -> list[tuple[float, list[VehicleTruth]]]:
    """The truth frames cut to the vehicles some sensor saw: at each stamp, the vehicles with a
    detection (any sensor, matched one-to-one within ``gate_m``) in the last ``hold_s``."""
    index = TruthIndex([(stamp, list(vehicles)) for stamp, vehicles in truth_frames])
    seen: dict[str, list[float]] = {}
    for batch in sorted(detection_batches, key=lambda b: b.stamp):
        estimates = [(d.x_m, d.y_m) for d in batch.detections]
        for _, vehicle in _matched(index, batch.stamp, estimates, gate_m):
            seen.setdefault(vehicle.vehicle_id, []).append(batch.stamp)

    def recently_seen(vehicle_id: str, stamp_s: float) -> bool:
        stamps = seen.get(vehicle_id, [])
        i = bisect.bisect_right(stamps, stamp_s + 1e-9)
        return i > 0 and stamp_s - stamps[i - 1] <= hold_s

    return [
        (stamp, [v for v in vehicles if recently_seen(v.vehicle_id, stamp)])
        for stamp, vehicles in truth_frames
    ]


def _followed(
    follows: TrackFollows, track_id: int | None, start_s: float, end_s: float
) -> str | None:
    """The vehicle ``track_id`` was matched to most often within ``[start_s, end_s]``."""
    if track_id is None:
        return None
    counts = Counter(
        vehicle for stamp, vehicle in follows.get(track_id, ()) if start_s <= stamp <= end_s
    )
    return counts.most_common(1)[0][0] if counts else None


def taper_arrivals(truth_frames: TruthFrames, taper_start_m: float) -> dict[str, float]:
    """When each vehicle's centre crosses the taper's start station [s], interpolated between
    steps; vehicles first seen at or past it, or never reaching it, are left out."""
    last: dict[str, tuple[float, float]] = {}
    arrivals: dict[str, float] = {}
    for stamp_s, vehicles in truth_frames:
        for v in vehicles:
            before = last.get(v.vehicle_id)
            last[v.vehicle_id] = (stamp_s, v.station_m)
            if v.vehicle_id in arrivals or before is None or v.station_m < taper_start_m:
                continue
            t0, s0 = before
            if s0 >= taper_start_m:
                continue
            arrivals[v.vehicle_id] = t0 + (taper_start_m - s0) / (v.station_m - s0) * (stamp_s - t0)
    return arrivals


def _median(values: Sequence[float]) -> float | None:
    return statistics.median(values) if values else None


def _ratio(numerator: int, denominator: int) -> float | None:
    return numerator / denominator if denominator else None


def score_alerts(
    site: Site,
    truth_frames: TruthFrames,
    events: Iterable[AlertEvent | Alert],
    *,
    tie_gate_m: float = TIE_GATE_M,
    slack_s: float = MATCH_SLACK_S,
    follows: TrackFollows | None = None,
) -> dict[str, dict[str, Any]]:
    """Precision, recall and lead time of the alerts per type, against the truth.

    Parameters
    ----------
    site : Site
        The site the alerts and the truth belong to (its thresholds define the truth).
    truth_frames : sequence of (float, sequence of VehicleTruth)
        The simulation's truth, ``(stamp [s], vehicles)`` per step, in stamp order.
    events : iterable of AlertEvent or Alert
        What the alert engine produced on the fused tracks (e.g. :func:`run_alert_engine`),
        or the alert messages from the bus; every phase may be given (starts, updates, clears).
    tie_gate_m : float
        Largest distance from an alert's position to its vehicle [m].
    slack_s : float
        Slack on each side of the episodes' spans when matching [s].
    follows : TrackFollows or None
        Which vehicle each track followed (:func:`track_follows` of the batches the alerts
        came from), to tie an episode to the vehicle its track followed; None to tie by the
        start position alone.

    Returns
    -------
    dict
        Keyed by alert type (``"speeding"``...), each: ``precision``, ``recall`` (None when
        undefined), ``true_positives``, ``false_positives``, ``false_negatives``,
        ``duplicates``, ``true_within_truth_cooldown`` (alerts on a vehicle's real episode
        that the truth's cooldown after an earlier one of the same vehicle left out: right,
        and in the precision, but no found episode for the recall), ``alerts`` (alert
        episodes), ``truth_episodes``, ``lead_time_s`` and
        ``truth_lead_time_s`` (medians [s], None without samples), ``lead_time_samples``,
        ``false_positive_starts`` (where and when the first :data:`MAX_FALSE_STARTS` false
        alerts started, to find why), ``false_positive_stamps_s`` (when every false alert
        started [s]); for speeding also ``lead_time_aggressive_s``.
    """
    index = TruthIndex([(stamp, list(vehicles)) for stamp, vehicles in truth_frames])
    profile = {v.vehicle_id: v.driver_profile for _, vehicles in truth_frames for v in vehicles}
    reduced = [_as_event(e) for e in events]
    clears = {e.episode_id: e.stamp_s for e in reduced if e.phase == "clear"}

    def tie(start: _Event) -> str | None:
        if start.site_level:
            return None
        end_s = clears.get(start.episode_id, math.inf)
        followed = _followed(follows or {}, start.track_id, start.stamp_s, end_s)
        return followed or tie_to_vehicle(
            index, start.stamp_s, start.station_m, start.offset_m, tie_gate_m
        )

    tied = {e.episode_id: tie(e) for e in reduced if e.phase == "start"}
    starts = {e.episode_id: e for e in reduced if e.phase == "start"}
    alert_episodes = _episodes(reduced, tied)
    truths = truth_episodes(site, truth_frames)
    # What the truth's cooldowns hid: a vehicle that brakes hard twice within the cooldown
    # gives one truth episode; an engine that missed the first and alerted on the second was
    # right on a real event (counted apart, neither a false alert nor a found episode).
    uncooled = truth_episodes(without_cooldowns(site), truth_frames)
    arrivals = taper_arrivals(truth_frames, ZoneGeometry.from_site(site).taper_start_m)

    def lead(episode: Episode) -> float | None:
        if episode.vehicle_id is None or episode.vehicle_id not in arrivals:
            return None
        return arrivals[episode.vehicle_id] - episode.start_s

    report: dict[str, dict[str, Any]] = {}
    for alert_type in AlertType:
        candidates = [t for t in truths if t.alert_type is alert_type]
        matched: set[str] = set()
        true_positives: list[Episode] = []
        false_positives = duplicates = within_cooldown = 0
        hidden = [t for t in uncooled if t.alert_type is alert_type]
        false_starts: list[dict[str, Any]] = []
        false_stamps: list[float] = []
        for alert in (a for a in alert_episodes if a.alert_type is alert_type):
            overlapping = [
                t
                for t in candidates
                if (
                    alert.site_level
                    or (alert.vehicle_id is not None and t.vehicle_id == alert.vehicle_id)
                )
                and alert.overlaps(t, slack_s)
            ]
            free = [t for t in overlapping if t.episode_id not in matched]
            if free:
                matched.add(min(free, key=lambda t: t.onset_s).episode_id)
                true_positives.append(alert)
            elif (
                not overlapping
                and alert.vehicle_id is not None
                and any(
                    t.vehicle_id == alert.vehicle_id and alert.overlaps(t, slack_s) for t in hidden
                )
            ):
                within_cooldown += 1
            else:
                false_positives += 1
                duplicates += bool(overlapping)
                false_stamps.append(round(alert.start_s, 2))
                start = starts.get(alert.episode_id)
                if start is not None and len(false_starts) < MAX_FALSE_STARTS:
                    false_starts.append(
                        {
                            "stamp_s": round(start.stamp_s, 2),
                            "station_m": round(start.station_m, 1),
                            "offset_m": round(start.offset_m, 2),
                            "track_id": start.track_id,
                            "vehicle_id": alert.vehicle_id,
                            "duplicate": bool(overlapping),
                        }
                    )
        tp, fn = len(true_positives), len(candidates) - len(matched)
        leads = [x for x in map(lead, true_positives) if x is not None]
        entry: dict[str, Any] = {
            "precision": _ratio(tp + within_cooldown, tp + within_cooldown + false_positives),
            "recall": _ratio(tp, tp + fn),
            "true_positives": tp,
            "false_positives": false_positives,
            "false_negatives": fn,
            "duplicates": duplicates,
            "true_within_truth_cooldown": within_cooldown,
            "alerts": tp + within_cooldown + false_positives,
            "truth_episodes": len(candidates),
            "lead_time_s": _median(leads),
            "lead_time_samples": len(leads),
            "truth_lead_time_s": _median([x for x in map(lead, candidates) if x is not None]),
            "false_positive_starts": false_starts,
            "false_positive_stamps_s": false_stamps,
        }
        if alert_type is AlertType.SPEEDING:
            aggressive = [
                x
                for a in true_positives
                if a.vehicle_id is not None
                and profile.get(a.vehicle_id) is DriverProfile.AGGRESSIVE
                and (x := lead(a)) is not None
            ]
            entry["lead_time_aggressive_s"] = _median(aggressive)
        report[alert_type.value] = entry
    return report


def summary_lines(report: dict[str, dict[str, Any]]) -> list[str]:
    """One line per alert type: ``type  P  R  TP/FP/FN  lead``, for a log or a report."""

    def cell(value: float | None, fmt: str) -> str:
        return "-" if value is None else format(value, fmt)

    return [
        f"{name}: precision {cell(e['precision'], '.2f')}, recall {cell(e['recall'], '.2f')}, "
        f"TP {e['true_positives']}, FP {e['false_positives']}, FN {e['false_negatives']}, "
        f"lead {cell(e['lead_time_s'], '.1f')} s"
        for name, e in report.items()
    ]
