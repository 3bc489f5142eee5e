"""Each lane's queue as data: its back, head, length, speed and the back's growth, once a second.

A lane is *queued* when at least ``min_vehicles`` of its slow confirmed tracks (speed below
``slow_speed_mps``; below ``slow_speed_mps + speed_hysteresis_mps`` while the lane is queued)
stand within ``span_m`` of station: the site's queue rule (:class:`wz_shared.site.QueueRule`)
applied lane by lane (:func:`wz_alert_service.rules.queue_extent`). Its back is the most
upstream queued vehicle, its head the most downstream one; the lane is *stopped* while the
queued vehicles' mean speed is below ``stopped_speed_mps`` (HCM's queued vehicle: under
5 mph), slow again above ``stopped_speed_mps + speed_hysteresis_mps``.

The back's speed along the road (:attr:`LaneQueue.back_speed_mps`) is the least-squares slope
of the back's station over the last :data:`BACK_SPEED_WINDOW_S` seconds: negative while the
queue grows upstream (the shock wave), positive while it dissolves.

**Beyond the sensors' reach.** A queue that grows past the farthest point upstream where the
site's sensors see a car (:func:`upstream_reach_m`, from the site file's sensor geometry,
:class:`wz_shared.coverage.SiteCoverage`) has an unmeasured back: within
:data:`REACH_MARGIN_M` of that reach, the lane's back is reported as ``back_beyond_reach``
(at least that far), never as a measured station.

Pure apart from the per-lane history that :class:`QueueEstimator` keeps; no clock, no I/O.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from wz_alert_service.rules import queue_extent
from wz_alert_service.zone import ZoneGeometry
from wz_shared.coverage import SiteCoverage
from wz_shared.messages import LaneQueue, QueueCondition, QueueState, Track

#: Seconds of back-of-queue stations the back's speed is fitted over.
BACK_SPEED_WINDOW_S = 10.0
#: The back's speed is given once the window holds this many seconds of a queue.
BACK_SPEED_MIN_SPAN_S = 3.0
#: A back this close to the sensors' upstream reach [m] may stand beyond it: about one queued
#: car and its gap at jam density (7.5 m) and the reach's own uncertainty.
REACH_MARGIN_M = 15.0
#: Uncovered stretches this long or shorter [m] do not end the reach: the blind cone under a
#: mast and the hand-over between sensors, which a tracker bridges.
REACH_GAP_M = 60.0
#: Station step of the reach's search [m].
REACH_STEP_M = 2.0
#: The state is published once this many seconds of track stamps have passed, and at once when
#: a lane's condition changes.
PUBLISH_INTERVAL_S = 1.0


def upstream_reach_m(zone: ZoneGeometry, coverage: SiteCoverage | None = None) -> dict[int, float]:
    """How far upstream the site's sensors see a car in each lane [m station].

    Along each lane's centre line through the approach, the covered stations are found
    (:class:`~wz_shared.coverage.SiteCoverage`, clear weather unless ``coverage`` says
    otherwise); from the most downstream covered station the reach runs upstream across
    uncovered stretches of at most :data:`REACH_GAP_M` and ends at the last covered station
    before a longer one. A lane no sensor covers reaches nowhere: its reach is the approach's
    end (every back there is beyond it).
    """
    site = zone.site
    coverage = SiteCoverage(site) if coverage is None else coverage
    stations = np.arange(zone.approach_start_m, zone.approach_end_m, REACH_STEP_M)
    reach: dict[int, float] = {}
    for lane in site.lanes:
        x, y = site.road_frame.to_site(stations, np.full(stations.shape, lane.center_offset_m))
        seen = stations[coverage(x, y)]
        if seen.size == 0:
            reach[lane.index] = zone.approach_end_m
            continue
        gaps = np.diff(seen)
        # walking upstream from the most downstream covered station: stop at a long gap
        breaks = np.flatnonzero(gaps > REACH_GAP_M)
        reach[lane.index] = float(seen[breaks[-1] + 1] if breaks.size else seen[0])
    return reach


@dataclass
class _LaneMemory:
    """What one lane remembers between batches."""

    condition: QueueCondition = QueueCondition.FREE
    backs: deque[tuple[float, float]] = field(default_factory=deque)  # (stamp, back station)


def _back_speed_mps(backs: Sequence[tuple[float, float]]) -> float | None:
    """Least-squares slope of the back's station over time [m/s]; None over too short a span."""
    if len(backs) < 3 or backs[-1][0] - backs[0][0] < BACK_SPEED_MIN_SPAN_S:
        return None
    t = np.array([b[0] for b in backs])
    s = np.array([b[1] for b in backs])
    t = t - t.mean()
    return float(np.dot(t, s - s.mean()) / np.dot(t, t))


class QueueEstimator:
    """Per-lane queue state from confirmed tracks, batch after batch.

    Parameters
    ----------
    zone : ZoneGeometry
        The approach, the lanes and the queue rule's thresholds (``zone.rules.queue``).
    reach_m : dict of int to float, optional
        Each lane's upstream reach [m]; default :func:`upstream_reach_m` of the site.
    """

    def __init__(self, zone: ZoneGeometry, reach_m: dict[int, float] | None = None) -> None:
        self.zone = zone
        self.rule = zone.rules.queue
        self.reach_m = upstream_reach_m(zone) if reach_m is None else reach_m
        self._lanes = sorted(lane.index for lane in zone.site.lanes)
        self._memory = {index: _LaneMemory() for index in self._lanes}
        self._published_s: float | None = None
        self._changed = False
        #: Every lane's queue as of the last :meth:`estimate`.
        self.lanes: list[LaneQueue] = [
            LaneQueue(
                lane_index=i,
                condition=QueueCondition.FREE,
                reach_station_m=self.reach_m.get(i, zone.approach_end_m),
            )
            for i in self._lanes
        ]

    def lane(self, index: int) -> LaneQueue | None:
        """Lane ``index``'s queue as of the last :meth:`estimate` (None: no such lane)."""
        for lane in self.lanes:
            if lane.lane_index == index:
                return lane
        return None

    def lane_of(self, track: Track) -> int:
        """The track's lane: the tracker's, or the lane at its offset."""
        if track.lane_index >= 0:
            return track.lane_index
        return int(self.zone.site.lane_index_at(track.offset_m))

    def estimate(self, tracks: Iterable[Track], stamp: float) -> list[LaneQueue]:
        """Every lane's queue at ``stamp`` from the batch's confirmed tracks (updates the
        lanes' memory: conditions and the back's recent stations; kept in :attr:`lanes`)."""
        before = [self._memory[i].condition for i in self._lanes]
        self.lanes = self._estimate(tracks, stamp)
        self._changed |= before != [lane.condition for lane in self.lanes]
        return self.lanes

    def _estimate(self, tracks: Iterable[Track], stamp: float) -> list[LaneQueue]:
        rule = self.rule
        by_lane: dict[int, list[Track]] = {index: [] for index in self._lanes}
        for track in tracks:
            lane = self.lane_of(track)
            if lane in by_lane and self.zone.in_approach(track.station_m):
                by_lane[lane].append(track)
        out: list[LaneQueue] = []
        for index in self._lanes:
            memory = self._memory[index]
            queued = memory.condition is not QueueCondition.FREE
            slow_mps = rule.slow_speed_mps + (rule.speed_hysteresis_mps if queued else 0.0)
            slow = [t for t in by_lane[index] if t.speed_mps < slow_mps]
            extent = queue_extent(
                [t.station_m for t in slow], min_vehicles=rule.min_vehicles, span_m=rule.span_m
            )
            reach = self.reach_m.get(index, self.zone.approach_end_m)
            while memory.backs and memory.backs[0][0] < stamp - BACK_SPEED_WINDOW_S:
                memory.backs.popleft()
            if extent is None:
                memory.condition = QueueCondition.FREE
                memory.backs.clear()
                out.append(
                    LaneQueue(
                        lane_index=index, condition=QueueCondition.FREE, reach_station_m=reach
                    )
                )
                continue
            members = [
                t for t in slow if extent.tail_station_m <= t.station_m <= extent.head_station_m
            ]
            mean_speed = float(np.mean([t.speed_mps for t in members]))
            stopped_mps = rule.stopped_speed_mps + (
                rule.speed_hysteresis_mps if memory.condition is QueueCondition.STOPPED else 0.0
            )
            memory.condition = (
                QueueCondition.STOPPED if mean_speed < stopped_mps else QueueCondition.SLOW
            )
            memory.backs.append((stamp, extent.tail_station_m))
            out.append(
                LaneQueue(
                    lane_index=index,
                    condition=memory.condition,
                    back_station_m=extent.tail_station_m,
                    back_beyond_reach=extent.tail_station_m <= reach + REACH_MARGIN_M,
                    head_station_m=extent.head_station_m,
                    length_m=extent.head_station_m - extent.tail_station_m,
                    vehicle_count=len(members),
                    mean_speed_mps=mean_speed,
                    back_speed_mps=_back_speed_mps(memory.backs),
                    reach_station_m=reach,
                )
            )
        return out

    def due(self, stamp: float, *, site: str, source_id: str) -> QueueState | None:
        """The lanes' queue of the last :meth:`estimate` as a message, or None when it is not
        due: it is due for the first batch, once :data:`PUBLISH_INTERVAL_S` of stamps have
        passed since the last one, and whenever a lane's condition changed since."""
        if (
            not self._changed
            and self._published_s is not None
            and stamp - self._published_s < PUBLISH_INTERVAL_S
            and stamp >= self._published_s
        ):
            return None
        self._published_s, self._changed = stamp, False
        return QueueState(site=site, source_id=source_id, stamp=stamp, lanes=self.lanes)

    def update(
        self, tracks: Iterable[Track], stamp: float, *, site: str, source_id: str
    ) -> QueueState | None:
        """:meth:`estimate`, then :meth:`due`."""
        self.estimate(tracks, stamp)
        return self.due(stamp, site=site, source_id=source_id)
