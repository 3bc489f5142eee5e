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

**Upstream point sensors.** Where the site file lists point speed sensors upstream of the reach
(:class:`wz_shared.site.PointSensor`: the side-fire radars or loop stations smart-work-zone
deployments place every quarter to half mile), their readings (:meth:`QueueEstimator.observe`)
bound a back beyond the reach. A sensor reads a lane *queued* when the vehicles that passed it
in its last interval averaged under the queue rule's slow speed (with its hysteresis once
queued), or, none having passed, a vehicle stood over it at least
:data:`JAM_OCCUPANCY_PERCENT` of the interval (a stopped queue over the station); *free*
otherwise, an empty lane included. Walking upstream from the reach, every sensor that reads the
lane queued moves the back's downstream bound (``back_downstream_bound_m``) to its station;
the first that reads it free is the upstream bound (``back_upstream_bound_m``): the back stands
between them. A reading is an interval's summary, and the back moves on after it: each bound
is widened by the farthest the back can have moved since the reading's interval began
(:data:`BACK_SPEED_MAX_MPS` times that time; a downstream bound no farther than the reach).
A reading older than :data:`POINT_STALE_INTERVALS` intervals says nothing and ends the walk.
So the bounds are as good as the sensors' spacing plus a few hundred metres for every minute
of interval: a site's sensors should report every 20-30 s.

Pure apart from the per-lane history that :class:`QueueEstimator` keeps; no clock, no I/O.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from wz_alert_service.rules import queue_extent
from wz_alert_service.zone import ZoneGeometry
from wz_shared.coverage import SiteCoverage
from wz_shared.messages import (
    LaneQueue,
    PointLaneReading,
    PointSensorReading,
    QueueCondition,
    QueueState,
    Track,
)
from wz_shared.site import QueueRule

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
#: The fastest a queue's back moves along the road [m/s], growing or dissolving: the congested
#: branch's wave speed of a triangular fundamental diagram (Newell), ``w = q_c / (k_j - k_c)``,
#: with a lane's capacity ``q_c`` = 2000 veh/h, jam spacing 7.5 m and capacity at 25 m/s: about
#: 5 m/s (18 km/h, the speed of the stop-and-go waves measured on freeways).
BACK_SPEED_MAX_MPS = 5.0
#: A point sensor's reading is used until this many of its intervals after the interval's end.
POINT_STALE_INTERVALS = 2.5
#: None having passed in the interval, a point sensor reads its lane queued when a vehicle stood
#: over its station at least this share of the interval [%]: half the interval stopped is a
#: queue standing on the sensor (free flow at capacity occupies a detector 10-15 %).
JAM_OCCUPANCY_PERCENT = 50.0
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


def point_lane_queued(lane: PointLaneReading, rule: QueueRule, *, queued_before: bool) -> bool:
    """Whether a point sensor's reading shows the lane queued (see the module's notes)."""
    if lane.mean_speed_mps is None:
        return lane.occupancy_percent >= JAM_OCCUPANCY_PERCENT
    slow_mps = rule.slow_speed_mps + (rule.speed_hysteresis_mps if queued_before else 0.0)
    return lane.mean_speed_mps < slow_mps


class _PointMemory:
    """One point sensor's newest reading and each lane's queued state from it."""

    def __init__(self, station_m: float) -> None:
        self.station_m = station_m
        self.stamp_s = -math.inf
        self.interval_s = 0.0
        self.queued: dict[int, bool] = {}

    def observe(self, reading: PointSensorReading, rule: QueueRule) -> None:
        self.stamp_s, self.interval_s = reading.stamp, reading.interval_s
        self.queued = {
            lane.lane_index: point_lane_queued(
                lane, rule, queued_before=self.queued.get(lane.lane_index, False)
            )
            for lane in reading.lanes
        }

    def lane_queued(self, lane_index: int, stamp: float) -> bool | None:
        """The lane's state at ``stamp``; None: no reading of it, or too old."""
        if stamp - self.stamp_s > POINT_STALE_INTERVALS * self.interval_s:
            return None
        return self.queued.get(lane_index)


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
        #: The site's point sensors, by id ...
        self._points = {
            point.sensor_id: _PointMemory(point.station_m) for point in zone.site.point_sensors
        }
        #: ... and the same, the most downstream first (the walk's order).
        self._points_upstream = sorted(self._points.values(), key=lambda m: -m.station_m)
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

    def observe(self, reading: PointSensorReading) -> bool:
        """Take a point sensor's reading; False (and nothing kept) when the site file lists no
        point sensor of that id. Its station is the site file's, not the message's."""
        memory = self._points.get(reading.source_id)
        if memory is None:
            return False
        memory.observe(reading, self.rule)
        return True

    def point_bounds(
        self, lane_index: int, reach_m: float, stamp: float
    ) -> tuple[float | None, float]:
        """The (upstream, downstream) bounds of a back beyond ``reach_m`` in the lane from the
        point sensors upstream of it at ``stamp`` (see the module's notes); the upstream bound
        None when no sensor reads the lane free before the walk ends."""
        downstream = reach_m
        upstream: float | None = None
        for memory in self._points_upstream:
            if memory.station_m >= reach_m:
                continue
            queued = memory.lane_queued(lane_index, stamp)
            if queued is None:
                break
            # The back may have moved this far since the reading's interval began.
            moved_m = BACK_SPEED_MAX_MPS * (stamp - memory.stamp_s + memory.interval_s)
            if not queued:
                upstream = memory.station_m - moved_m
                break
            downstream = min(reach_m, memory.station_m + moved_m)
        return upstream, downstream

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
            beyond = extent.tail_station_m <= reach + REACH_MARGIN_M
            upstream_bound, downstream_bound = (
                self.point_bounds(index, reach, stamp) if beyond else (None, None)
            )
            out.append(
                LaneQueue(
                    lane_index=index,
                    condition=memory.condition,
                    back_station_m=extent.tail_station_m,
                    back_beyond_reach=beyond,
                    head_station_m=extent.head_station_m,
                    length_m=extent.head_station_m - extent.tail_station_m,
                    vehicle_count=len(members),
                    mean_speed_mps=mean_speed,
                    back_speed_mps=_back_speed_mps(memory.backs),
                    reach_station_m=reach,
                    back_upstream_bound_m=upstream_bound,
                    back_downstream_bound_m=downstream_bound,
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
