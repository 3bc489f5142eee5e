"""When a track ends, and its smoothed trajectory written then.

A track *life* is a track id in one run of the tracker: from the first stored batch that holds
it to the last. It ends when

- it has been missing from the batches for longer than ``track_end_after_s`` of stamps (the
  tracker deleted it; a batch or two lost on the way does not end it);
- the stamps go back by more than :data:`~wz_gateway.storage.RESTART_TOLERANCE_S` (a new run:
  every track of the old one has ended, and its ids will be used again);
- no batch has come for ``track_end_silence_s`` of wall clock (the tracker stopped).

:class:`TrackEnds` decides that from the batches alone (pure). :class:`TrackFinisher` is what
the node's writer thread runs around it: a life is recorded in the ``tracks`` table before its
first points are written, and when it ends its fused points are RTS-smoothed
(:func:`wz_gateway.smoothing.smooth_trajectory`, with the process noise its first batch
carried, recorded with the life) and written as ``smoothed`` points in the
transaction that marks it ended, so a life is smoothed once, whatever stops when. Ended lives
wait in a queue and are smoothed between groups of messages, a time budget at a time, so a run
that ends fifty tracks at once does not hold the ingestion up. At start, lives left unfinished
by the previous process are taken up again: smoothed at once when they have ended meanwhile,
else followed on.
"""

from __future__ import annotations

import logging
import time
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

from wz_gateway.metrics import GatewayMetrics
from wz_gateway.settings import GatewaySettings
from wz_gateway.smoothing import smooth_trajectory
from wz_gateway.storage import RESTART_TOLERANCE_S, Storage
from wz_gateway.track_lives import TrackLife, TrackLifeStore
from wz_shared.messages import Message, TrackBatch
from wz_shared.motion import ProcessNoise
from wz_shared.site import Site
from wz_shared.timebase import stamp_went_back

log = logging.getLogger(__name__)

#: Smoothing done after one group of messages before the writer takes the next [s] (at least
#: one track is smoothed each time).
SMOOTHING_BUDGET_S = 0.02
#: Attempts at smoothing one life before it is left to the next start (it stays unfinished).
SMOOTHING_ATTEMPTS = 3


@dataclass
class EndsOfBatch:
    """What one batch (or the silence) changed: lives that started and lives that ended."""

    started: list[TrackLife]
    ended: list[TrackLife]


class TrackEnds:
    """Which track lives are open, and which end, from the stored batches in order. Pure.

    Parameters
    ----------
    end_after_s
        A track missing for longer than this [s of stamps] has ended.
    silence_s
        No batch for longer than this [s of wall clock]: every open track has ended.
    restart_tolerance_s
        Stamps that go back by more than this [s] start a new run.
    """

    def __init__(self, end_after_s: float, silence_s: float, restart_tolerance_s: float) -> None:
        self.end_after_s = end_after_s
        self.silence_s = silence_s
        self.restart_tolerance_s = restart_tolerance_s
        self.open: dict[int, TrackLife] = {}
        #: Stamp and arrival (wall clock) of the newest batch.
        self.last_stamp: float | None = None
        self.last_received_at: float | None = None

    def resume(
        self, lives: Iterable[TrackLife], last_stamp: float | None, last_received_at: float | None
    ) -> list[TrackLife]:
        """Take up the lives a previous process left open, as of its newest batch; the lives
        that have ended by then (absent too long, or of an earlier run, or an older life of an
        id that has a newer one)."""
        self.last_stamp, self.last_received_at = last_stamp, last_received_at
        ended: list[TrackLife] = []
        for life in lives:
            superseded = self.open.get(life.track_id)
            if superseded is not None:
                ended.append(superseded)
            self.open[life.track_id] = life
        if last_stamp is not None:
            for track_id, life in list(self.open.items()):
                gone = last_stamp - life.last_stamp > self.end_after_s
                earlier_run = stamp_went_back(life.last_stamp, last_stamp, self.restart_tolerance_s)
                if gone or earlier_run:
                    ended.append(self.open.pop(track_id))
        return ended

    def observe(self, batch: TrackBatch, received_at: float) -> EndsOfBatch:
        """One stored batch: the lives it starts and those that have ended by its stamp."""
        stamp = batch.stamp
        out = EndsOfBatch(started=[], ended=[])
        if stamp_went_back(self.last_stamp, stamp, self.restart_tolerance_s):
            out.ended += self.open.values()  # a new run: the old one's tracks are all over
            self.open.clear()
        self.last_stamp, self.last_received_at = stamp, received_at
        for track in batch.tracks:
            life = self.open.get(track.track_id)
            if life is not None and stamp - life.last_stamp > self.end_after_s:
                out.ended.append(life)  # gone too long: back under the same id, a new life
                life = None
            if life is None:
                life = TrackLife(
                    track.track_id,
                    stamp,
                    received_at,
                    stamp,
                    received_at,
                    process_noise=batch.process_noise,
                )
                self.open[track.track_id] = life
                out.started.append(life)
            else:
                life.last_stamp, life.last_received_at = max(life.last_stamp, stamp), received_at
        for track_id, life in list(self.open.items()):
            if stamp - life.last_stamp > self.end_after_s:
                out.ended.append(self.open.pop(track_id))
        return out

    def silence(self, now: float) -> list[TrackLife]:
        """Every open life, if no batch has come for longer than ``silence_s`` (wall clock)."""
        if self.last_received_at is None or now - self.last_received_at <= self.silence_s:
            return []
        ended = list(self.open.values())
        self.open.clear()
        return ended


@dataclass
class TrackFinisher:
    """Track lives around the writer: recorded when they start, smoothed when they end.

    Parameters
    ----------
    storage : Storage
    site : Site
    ends : TrackEnds
    metrics : GatewayMetrics
    clock : callable
        Wall clock [Unix s]: ``ended_at``, and the silence.
    """

    storage: Storage
    site: Site
    ends: TrackEnds
    metrics: GatewayMetrics
    clock: Callable[[], float] = time.time

    def __post_init__(self) -> None:
        self.lives = TrackLifeStore(self.storage.engine)
        self.pending: deque[TrackLife] = deque()
        self._failures: dict[int, int] = {}  # by id() of a pending life

    @classmethod
    def of(
        cls,
        storage: Storage,
        site: Site,
        settings: GatewaySettings,
        metrics: GatewayMetrics,
        clock: Callable[[], float] = time.time,
    ) -> TrackFinisher:
        """The finisher the settings describe."""
        ends = TrackEnds(
            settings.track_end_after_s, settings.track_end_silence_s, RESTART_TOLERANCE_S
        )
        return cls(storage, site, ends, metrics, clock)

    def resume(self) -> int:
        """Take up what the previous process left: its unfinished lives, as of its newest
        batch. The lives queued for smoothing."""
        try:
            lives = self.lives.unfinished(self.site.site_id)
            newest = self.storage.latest(self.site.site_id, "tracks")
        except Exception:  # they stay unfinished in the database, for the next start
            log.exception("could not read the track lives left unfinished")
            return 0
        ended = self.ends.resume(
            lives,
            None if newest is None else newest.stamp,
            None if newest is None else newest.received_at,
        )
        self.pending.extend(ended)
        self.pending.extend(self.ends.silence(self.clock()))
        if lives:
            log.info(
                "%d track lives left unfinished: %d ended meanwhile, %d followed on",
                len(lives),
                len(self.pending),
                len(self.ends.open),
            )
        return len(self.pending)

    def before_write(self, group: Sequence[Message], received_at: float) -> None:
        """A group is about to be stored with this ``received_at``: record the lives it starts
        (before their points, so a crash never leaves points of an unrecorded life) and queue
        those that have ended, to smooth once the group is stored."""
        started: list[TrackLife] = []
        for message in group:
            if isinstance(message, TrackBatch) and message.site == self.site.site_id:
                change = self.ends.observe(message, received_at)
                started += change.started
                self.pending.extend(change.ended)
        if not started:
            return
        try:
            self.lives.record(self.site.site_id, started)
        except Exception:  # the life is recorded when it ends instead (life_id stays None)
            log.exception("could not record %d new track lives", len(started))

    def work(self, budget_s: float = SMOOTHING_BUDGET_S) -> int:
        """Smooth queued lives for about ``budget_s`` (one at least); the lives finished."""
        self.pending.extend(self.ends.silence(self.clock()))
        finished = 0
        deadline = time.perf_counter() + budget_s
        while self.pending and (finished == 0 or time.perf_counter() < deadline):
            life = self.pending.popleft()
            try:
                self.finish(life)
            except Exception:  # the database refused: tried again later, behind the others
                failures = self._failures.get(id(life), 0) + 1
                if failures < SMOOTHING_ATTEMPTS:
                    log.exception("could not smooth track %d; will try again", life.track_id)
                    self._failures[id(life)] = failures
                    self.pending.append(life)
                else:
                    log.exception(
                        "could not smooth track %d after %d attempts; left for the next start",
                        life.track_id,
                        failures,
                    )
                    self._failures.pop(id(life), None)
                return finished
            self._failures.pop(id(life), None)
            finished += 1
        return finished

    def finish(self, life: TrackLife) -> int:
        """Smooth one ended life with its process noise (the model's defaults where none was
        recorded) and store it, marked ended, in one transaction; its points."""
        started = time.perf_counter()
        points = self.lives.points(self.site.site_id, life)
        smoothed = None
        if len(points):
            smoothed = smooth_trajectory(points, self.site, life.process_noise or ProcessNoise())
        written = self.lives.finish(self.site.site_id, life, smoothed, ended_at=self.clock())
        if written:
            self.metrics.smoothed_tracks.inc()
            self.metrics.smoothed_points.inc(len(points))
            self.metrics.smoothing_seconds.observe(time.perf_counter() - started)
        return len(points) if written else 0


@dataclass
class SiteFinishers:
    """One :class:`TrackFinisher` per site, for a gateway that serves several; the writer
    uses it as it would one finisher (each finisher only looks at its own site's batches)."""

    finishers: list[TrackFinisher]

    @classmethod
    def of(
        cls,
        storage: Storage,
        sites: Iterable[Site],
        settings: GatewaySettings,
        metrics: GatewayMetrics,
        clock: Callable[[], float] = time.time,
    ) -> SiteFinishers:
        return cls([TrackFinisher.of(storage, site, settings, metrics, clock) for site in sites])

    def resume(self) -> int:
        return sum(finisher.resume() for finisher in self.finishers)

    def before_write(self, group: Sequence[Message], received_at: float) -> None:
        for finisher in self.finishers:
            finisher.before_write(group, received_at)

    def work(self, budget_s: float = SMOOTHING_BUDGET_S) -> int:
        share = budget_s / max(1, len(self.finishers))
        return sum(finisher.work(share) for finisher in self.finishers)
