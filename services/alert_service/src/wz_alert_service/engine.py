"""The alert engine: rules per track per track batch, with hysteresis and one alert per episode.

:class:`AlertEngine` is fed :class:`~wz_shared.messages.TrackBatch` es in stamp order and
returns :class:`AlertEvent` s. Time is the batches' stamps (capture time), never the wall clock.

**Per batch** (stamp ``t``):

1. the open episodes of tracks no longer in the batch clear at once (the tracker deletes a
   track only after it has coasted for a while, and never reuses an id);
2. each confirmed track's speed joins its history, kept for the longest trend window; a
   track back from an outage (:data:`MEASUREMENT_GAP_S`) starts a new history;
3. every enabled per-track rule of :mod:`wz_alert_service.rules` is evaluated on every
   confirmed track, then the site-level queue rule on all of them;
4. each (track, type) key steps its episode state machine (below).

**Episodes.** For each key (``track_id``, or None for the queue, and the alert type)::

    idle --condition--> pending --held for hold_s--> open --false for clear_s--> idle
      ^                   |                            |                          |
      +---condition false-+                            +-severity rises: update   |
      +----------------- no new pending before t_clear + cooldown_s -------------+

- *pending*: the condition (at its enter threshold) must hold on every batch for ``hold_s``;
  one batch without it and the key is idle again. The start alert's ``onset_stamp`` is the
  first batch of the hold. The alert starts on the first batch after the hold where the track
  is *measured* (status ``confirmed``), not ``coasting``: a coasting track is the tracker's
  prediction, and an alert's evidence must be a sensor's. On the 600 s `wz eval` run the only
  two false speeding alerts both started on coasting tracks, and none of the 35 true ones did:
  each was a short-lived track that a camera box paired with the radar echo of the car one
  lane over had started (at that car's speed, in the other lane), and it met the hold while
  coasting to its deletion.
- *open*: the rule is asked with ``active=True``, i.e. at its exit threshold, looser than the
  enter threshold, so a measurement hovering at the threshold keeps one episode. A batch
  where the severity band rises above the episode's peak emits an update (at most two per
  episode: info, warning, critical).
- *clear*: after ``clear_s`` without the condition (measured from the first batch without it;
  a batch with it again resets the clock), or at once when the track is gone. The key then
  cannot start a new pending hold until ``cooldown_s`` after the clear.

Time comparisons allow ``1e-6`` s, so a hold of 1 s is met by 20 batches 0.05 s apart despite
the floating-point sums of stamps.

The engine does no I/O: the node decodes track batches, calls :meth:`AlertEngine.update`,
turns each event into an :class:`~wz_shared.messages.Alert` with :meth:`AlertEvent.to_message`
and publishes it; :meth:`AlertEngine.active` feeds :func:`wz_alert_service.devices.roadside_devices`.
"""

from __future__ import annotations

import re
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np

from wz_alert_service.queues import QueueEstimator
from wz_alert_service.rules import (
    SEVERITY_RANK,
    Finding,
    aggressive_approach,
    hard_braking,
    intrusion,
    late_merge,
    leaders,
    queue,
    queue_approach,
    short_ttc,
    speed_trend_mps2,
    speed_trend_std_mps2,
    speed_variance,
    speeding,
)
from wz_alert_service.zone import ZoneGeometry
from wz_shared.arrays import F64
from wz_shared.messages import (
    Alert,
    AlertPhase,
    AlertSeverity,
    AlertType,
    LaneQueue,
    Track,
    TrackBatch,
    TrackStatus,
)
from wz_shared.site import AlertRules, EpisodeTiming, Site

#: Tolerance of time comparisons [s].
TIME_EPS_S = 1e-6
#: Fewest speeds for the aggressive-approach speed trend.
TREND_MIN_SAMPLES = 3
#: A track whose newest measurement comes more than this after the one before [s] has been
#: through an outage (occluded, or between sensors): its speed then jumps by the error the
#: prediction gathered over the outage, which is no deceleration of the vehicle. The speed
#: trends start again from that measurement. Sensors here run at 10-20 Hz, so 0.25 s is at
#: least two missed frames of the slowest. (Issue 25: on a generated site 12 of 13 hard-braking
#: alerts in 120 s were such jumps, vehicles re-acquired behind the taper's drums.)
MEASUREMENT_GAP_S = 0.25
_MAX_DESCRIPTION = 500
_PREFIX = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.:-]{0,63}$")

#: An episode's key: the track (None for a site-level rule) and the rule.
EpisodeKey = tuple[int | None, AlertType]


@dataclass(frozen=True)
class TrackContext:
    """What the per-track rules need beyond the track, computed once per track per batch.

    Attributes
    ----------
    leader : Track or None
        Nearest track ahead in the same lane.
    braking_trend_mps2 : float or None
        Speed slope over the hard-braking window [m/s^2].
    approach_trend_mps2 : float or None
        Speed slope over the aggressive-approach trend window [m/s^2].
    braking_trend_std_mps2 : float or None
        The braking slope's standard deviation from the tracks' own speed variances [m/s^2]
        (:func:`~wz_alert_service.rules.speed_trend_std_mps2`); None: not known.
    lane_queue : LaneQueue or None
        The track's lane's queue in this batch (:mod:`wz_alert_service.queues`).
    """

    leader: Track | None
    braking_trend_mps2: float | None
    approach_trend_mps2: float | None
    braking_trend_std_mps2: float | None = None
    lane_queue: LaneQueue | None = None


TrackRule = Callable[[Track, TrackContext, ZoneGeometry, AlertRules, bool], Finding | None]

#: The per-track rules, in the order their events are emitted within one track.
TRACK_RULES: Mapping[AlertType, TrackRule] = {
    AlertType.SPEEDING: lambda t, c, z, r, a: speeding(t, z, r.speeding, active=a),
    AlertType.AGGRESSIVE_APPROACH: lambda t, c, z, r, a: aggressive_approach(
        t, c.approach_trend_mps2, z, r.aggressive_approach, active=a
    ),
    AlertType.HARD_BRAKING: lambda t, c, z, r, a: hard_braking(
        t,
        c.braking_trend_mps2,
        z,
        r.hard_braking,
        active=a,
        trend_std_mps2=c.braking_trend_std_mps2,
    ),
    AlertType.LATE_MERGE: lambda t, c, z, r, a: late_merge(t, z, r.late_merge, active=a),
    AlertType.SHORT_TTC: lambda t, c, z, r, a: short_ttc(t, c.leader, z, r.short_ttc, active=a),
    AlertType.INTRUSION: lambda t, c, z, r, a: intrusion(t, z, r.intrusion, active=a),
    AlertType.QUEUE_APPROACH: lambda t, c, z, r, a: queue_approach(
        t, c.lane_queue, z, r.queue_approach, slow_speed_mps=r.queue.slow_speed_mps, active=a
    ),
}


def rule_timing(rules: AlertRules, alert_type: AlertType) -> EpisodeTiming:
    """The hold, clear and cool-down times (and the on/off switch) of one rule."""
    timing: EpisodeTiming = getattr(rules, alert_type.value)
    return timing


@dataclass(frozen=True)
class AlertEvent:
    """One event of an episode, as the engine decided it.

    Attributes
    ----------
    phase : {"start", "update", "clear"}
        What happened.
    episode_id : str
        Shared by the start, updates and clear of one episode.
    sequence : int
        0 for the start, then 1, 2... for updates and the clear.
    alert_type, severity
        The rule and the episode's severity (at a clear: its peak).
    stamp : float
        Capture time of the batch that decided the event [s].
    onset_stamp : float
        Capture time at which the condition first held [s].
    finding : Finding
        The rule's measurements: current at a start or update, the last that held at a clear.
    description : str
        One line for an operator.
    evidence : Mapping[str, float]
        The finding's evidence and the episode's timing (``held_s``, ``duration_s``...).
    """

    phase: AlertPhase
    episode_id: str
    sequence: int
    alert_type: AlertType
    severity: AlertSeverity
    stamp: float
    onset_stamp: float
    finding: Finding
    description: str
    evidence: Mapping[str, float] = field(default_factory=dict)

    @property
    def alert_id(self) -> str:
        return f"{self.episode_id}-{self.sequence}"

    @property
    def track_id(self) -> int | None:
        return self.finding.track_id

    def to_message(self, site: str, source_id: str) -> Alert:
        """The bus message of this event (validated by pydantic: ids must be identifiers)."""
        finding = self.finding
        return Alert(
            site=site,
            source_id=source_id,
            stamp=self.stamp,
            alert_id=self.alert_id,
            alert_type=self.alert_type,
            severity=self.severity,
            track_id=finding.track_id,
            station_m=finding.station_m,
            offset_m=finding.offset_m,
            speed_mps=finding.speed_mps,
            measured_value=finding.measured_value,
            threshold_value=finding.threshold_value,
            description=self.description[:_MAX_DESCRIPTION],
            phase=self.phase,
            episode_id=self.episode_id,
            onset_stamp=self.onset_stamp,
            value_unit=finding.value_unit,
            evidence=dict(self.evidence),
            track=finding.track,
        )


@dataclass(frozen=True)
class ActiveAlert:
    """An open episode: what the roadside devices and a dashboard show now.

    Attributes
    ----------
    episode_id : str
        The episode.
    alert_type : AlertType
        The rule.
    track_id : int or None
        The track (None for the queue).
    severity : AlertSeverity
        The episode's peak severity.
    onset_stamp, start_stamp : float
        When the condition first held, and when the episode started [s].
    finding : Finding
        The latest measurements that held (a queue's current tail, for instance).
    """

    episode_id: str
    alert_type: AlertType
    track_id: int | None
    severity: AlertSeverity
    onset_stamp: float
    start_stamp: float
    finding: Finding


@dataclass
class EngineCounters:
    """What the engine did, for the service's health report."""

    batches: int = 0
    batches_out_of_order: int = 0
    starts: int = 0
    updates: int = 0
    clears: int = 0


@dataclass
class _Episode:
    """State of one key: pending (``episode_id`` empty) or open."""

    alert_type: AlertType
    onset_s: float
    finding: Finding
    episode_id: str = ""
    start_s: float = 0.0
    severity: AlertSeverity = AlertSeverity.INFO
    sequence: int = 0
    false_since_s: float | None = None

    @property
    def open(self) -> bool:
        return bool(self.episode_id)


def confirmed(track: Track) -> bool:
    """Whether the rules see a track: confirmed, and not tentative."""
    return track.confirmed and track.status is not TrackStatus.TENTATIVE


class AlertEngine:
    """Evaluates the alert rules on track batches and keeps one episode per (track, type).

    Parameters
    ----------
    site : Site
        The site: geometry, limits, and (unless ``rules`` is given) its ``alerts:`` thresholds.
    rules : AlertRules, optional
        Thresholds to use instead of the site's.
    id_prefix : str
        Put before every episode id (e.g. the service's start time), so ids stay unique across
        restarts; letters, digits and ``_ . : -``.
    reach_m : dict of int to float, optional
        Each lane's upstream reach for the queue estimate (default: from the site's sensors,
        :func:`~wz_alert_service.queues.upstream_reach_m`).

    Notes
    -----
    Only confirmed tracks (``confirmed`` and not tentative) are evaluated; a tentative track is
    treated as absent. A batch with a stamp before the previous batch's is counted in
    ``counters.batches_out_of_order`` and ignored (episodes move forward in time only).
    """

    def __init__(
        self,
        site: Site,
        rules: AlertRules | None = None,
        *,
        id_prefix: str = "",
        reach_m: dict[int, float] | None = None,
    ) -> None:
        if id_prefix and not _PREFIX.match(id_prefix):
            raise ValueError(
                f"id_prefix {id_prefix!r}: use letters, digits and '_', '.', ':', '-' "
                "(64 characters at most, starting with a letter or digit)"
            )
        self.zone = ZoneGeometry.from_site(site, rules)
        self.rules = self.zone.rules
        self.counters = EngineCounters()
        self._id_prefix = f"{id_prefix}-" if id_prefix else ""
        self._track_rules = [
            (alert_type, rule)
            for alert_type, rule in TRACK_RULES.items()
            if rule_timing(self.rules, alert_type).enabled
        ]
        self._episodes: dict[EpisodeKey, _Episode] = {}
        self._cooldown_until_s: dict[EpisodeKey, float] = {}
        #: Per track: (stamp, speed, the speed's variance along the track) of the last seconds.
        self._history: dict[int, deque[tuple[float, float, float]]] = {}
        #: Each track's newest measurement stamp seen, to tell an outage (see MEASUREMENT_GAP_S).
        self._measured_s: dict[int, float] = {}
        self._history_s = max(
            self.rules.hard_braking.window_s, self.rules.aggressive_approach.trend_window_s
        )
        self._last_stamp_s: float | None = None
        #: Each lane's queue, estimated from every batch's tracks before the rules run.
        self.queues = QueueEstimator(self.zone, reach_m)
        #: Episodes opened so far: the number in each episode id (a successor engine of a new
        #: run carries it on, so ids never repeat in one process).
        self.episode_count = 0

    # --- public ---------------------------------------------------------------------------

    def update(self, batch: TrackBatch) -> list[AlertEvent]:
        """Evaluate one track batch; return its events (starts, updates, clears) in order.

        Parameters
        ----------
        batch : TrackBatch
            Every track of one tracker cycle, at ``batch.stamp`` [s].

        Returns
        -------
        list of AlertEvent
            Clears of lost tracks first, then by track id and rule, the queue last.
        """
        t = batch.stamp
        if self._last_stamp_s is not None and t < self._last_stamp_s:
            self.counters.batches_out_of_order += 1
            return []
        self._last_stamp_s = t
        self.counters.batches += 1
        tracks = sorted((tr for tr in batch.tracks if confirmed(tr)), key=lambda tr: tr.track_id)
        present = {tr.track_id for tr in tracks}
        events = self._forget_lost_tracks(present, t)
        self._cooldown_until_s = {k: u for k, u in self._cooldown_until_s.items() if u > t}
        for track in tracks:
            self._remember_speed(track, t)
        track_leaders = leaders(tracks)
        self.queues.estimate(tracks, t)
        for track in tracks:
            context = self._context(track, track_leaders.get(track.track_id), t)
            measured = track.status is not TrackStatus.COASTING
            for alert_type, rule in self._track_rules:
                key: EpisodeKey = (track.track_id, alert_type)
                finding = rule(track, context, self.zone, self.rules, self._is_open(key))
                events.extend(self._step(key, finding, t, measured))
        if self.rules.queue.enabled:
            key = (None, AlertType.QUEUE)
            finding = queue(tracks, self.zone, self.rules.queue, active=self._is_open(key))
            events.extend(self._step(key, finding, t))
        return events

    def active(self) -> list[ActiveAlert]:
        """The open episodes, by rule then track (the queue's ``track_id`` None first)."""
        order = {alert_type: i for i, alert_type in enumerate(AlertType)}
        open_items = sorted(
            ((key, ep) for key, ep in self._episodes.items() if ep.open),
            key=lambda item: (order[item[0][1]], -1 if item[0][0] is None else item[0][0]),
        )
        return [
            ActiveAlert(
                episode_id=ep.episode_id,
                alert_type=ep.alert_type,
                track_id=key[0],
                severity=ep.severity,
                onset_stamp=ep.onset_s,
                start_stamp=ep.start_s,
                finding=ep.finding,
            )
            for key, ep in open_items
        ]

    # --- per batch ------------------------------------------------------------------------

    def _is_open(self, key: EpisodeKey) -> bool:
        episode = self._episodes.get(key)
        return episode is not None and episode.open

    def _forget_lost_tracks(self, present: set[int], t: float) -> list[AlertEvent]:
        events: list[AlertEvent] = []
        lost = sorted(
            (key for key in self._episodes if key[0] is not None and key[0] not in present),
            key=lambda key: (key[0], list(AlertType).index(key[1])),
        )
        for key in lost:
            episode = self._episodes.pop(key)
            if episode.open:
                events.append(self._clear(key, episode, t, track_lost=True))
        for track_id in [tid for tid in self._history if tid not in present]:
            del self._history[track_id]
            self._measured_s.pop(track_id, None)
        return events

    def _remember_speed(self, track: Track, t: float) -> None:
        history = self._history.setdefault(track.track_id, deque())
        measured_s = track.last_update_s
        if measured_s is not None:
            previous_s = self._measured_s.get(track.track_id)
            if previous_s is not None and measured_s - previous_s > MEASUREMENT_GAP_S + TIME_EPS_S:
                history.clear()  # back from an outage: the jump is the prediction's error
            self._measured_s[track.track_id] = measured_s
        history.append((t, track.speed_mps, speed_variance(track)))
        while history and history[0][0] < t - self._history_s - TIME_EPS_S:
            history.popleft()

    def _window(self, track_id: int, t: float, window_s: float) -> F64:
        """The track's (stamp, speed, variance) rows of the last ``window_s``, shape (n, 3)."""
        rows = [s for s in self._history[track_id] if s[0] >= t - window_s - TIME_EPS_S]
        return np.array(rows, dtype=np.float64).reshape(-1, 3)

    def _trend(self, track_id: int, t: float, window_s: float, min_samples: int) -> float | None:
        rows = self._window(track_id, t, window_s)
        if not len(rows):
            return None
        return speed_trend_mps2(
            rows[:, 0], rows[:, 1], min_samples=min_samples, min_span_s=0.5 * window_s
        )

    def _context(self, track: Track, leader: Track | None, t: float) -> TrackContext:
        braking = self.rules.hard_braking
        approach = self.rules.aggressive_approach
        return TrackContext(
            leader=leader,
            braking_trend_mps2=self._trend(
                track.track_id, t, braking.window_s, braking.min_samples
            ),
            braking_trend_std_mps2=speed_trend_std_mps2(
                *self._window(track.track_id, t, braking.window_s)[:, [0, 2]].T
            ),
            approach_trend_mps2=self._trend(
                track.track_id, t, approach.trend_window_s, TREND_MIN_SAMPLES
            ),
            lane_queue=self.queues.lane(self.queues.lane_of(track)),
        )

    # --- the episode state machine --------------------------------------------------------

    def _step(
        self, key: EpisodeKey, finding: Finding | None, t: float, measured: bool = True
    ) -> list[AlertEvent]:
        """Advance ``key``'s episode by one batch; ``measured``: its track was updated by a
        sensor (not coasting), without which a pending hold does not start an alert yet."""
        timing = rule_timing(self.rules, key[1])
        episode = self._episodes.get(key)
        if episode is None:
            if finding is None or t < self._cooldown_until_s.get(key, -np.inf):
                return []
            episode = _Episode(alert_type=key[1], onset_s=t, finding=finding)
            self._episodes[key] = episode
        if not episode.open:
            if finding is None:
                del self._episodes[key]
                return []
            episode.finding = finding
            if measured and t - episode.onset_s >= timing.hold_s - TIME_EPS_S:
                return [self._start(key, episode, t)]
            return []
        if finding is not None:
            episode.finding = finding
            episode.false_since_s = None
            if SEVERITY_RANK[finding.severity] > SEVERITY_RANK[episode.severity]:
                return [self._escalate(episode, t)]
            return []
        if episode.false_since_s is None:
            episode.false_since_s = t
        if t - episode.false_since_s >= timing.clear_s - TIME_EPS_S:
            del self._episodes[key]
            return [self._clear(key, episode, t, track_lost=False)]
        return []

    def _start(self, key: EpisodeKey, episode: _Episode, t: float) -> AlertEvent:
        self.episode_count += 1
        subject = "site" if key[0] is None else str(key[0])
        episode.episode_id = f"{self._id_prefix}{key[1].value}-{subject}-{self.episode_count}"
        episode.start_s = t
        episode.severity = episode.finding.severity
        self.counters.starts += 1
        return AlertEvent(
            phase="start",
            episode_id=episode.episode_id,
            sequence=0,
            alert_type=episode.alert_type,
            severity=episode.severity,
            stamp=t,
            onset_stamp=episode.onset_s,
            finding=episode.finding,
            description=episode.finding.description,
            evidence={**episode.finding.evidence, "held_s": t - episode.onset_s},
        )

    def _escalate(self, episode: _Episode, t: float) -> AlertEvent:
        episode.severity = episode.finding.severity
        episode.sequence += 1
        self.counters.updates += 1
        return AlertEvent(
            phase="update",
            episode_id=episode.episode_id,
            sequence=episode.sequence,
            alert_type=episode.alert_type,
            severity=episode.severity,
            stamp=t,
            onset_stamp=episode.onset_s,
            finding=episode.finding,
            description=f"{episode.finding.description} (now {episode.severity.value})",
            evidence={**episode.finding.evidence, "duration_s": t - episode.onset_s},
        )

    def _clear(
        self, key: EpisodeKey, episode: _Episode, t: float, *, track_lost: bool
    ) -> AlertEvent:
        episode.sequence += 1
        self.counters.clears += 1
        self._cooldown_until_s[key] = t + rule_timing(self.rules, key[1]).cooldown_s
        why = "track lost" if track_lost else "condition ended"
        duration_s = t - episode.onset_s
        return AlertEvent(
            phase="clear",
            episode_id=episode.episode_id,
            sequence=episode.sequence,
            alert_type=episode.alert_type,
            severity=episode.severity,
            stamp=t,
            onset_stamp=episode.onset_s,
            finding=episode.finding,
            description=(
                f"{episode.alert_type.value} cleared ({why}) after {duration_s:.1f} s, "
                f"peak {episode.severity.value}"
            ),
            evidence={
                **episode.finding.evidence,
                "duration_s": duration_s,
                "track_lost": 1.0 if track_lost else 0.0,
            },
        )
