"""Each lane's queue as data (wz_alert_service.queues): back, head, length, speed, the back's
growth, stopped against slow with hysteresis, the back beyond the sensors' reach, the 1 Hz
cadence; the sign's queue message held against flicker (devices.SignHold); and the alert for
approaching the back of the queue too fast (rules.queue_approach)."""

from __future__ import annotations

import pytest

from tests.alert_service.helpers import CLOSED_LANE_D, SITE, batch, make_track, stamps
from tests.alert_service.test_devices import active
from wz_alert_service.devices import STOPPED_TEXT, SignHold, roadside_devices
from wz_alert_service.engine import AlertEngine
from wz_alert_service.node import AlertCore
from wz_alert_service.queues import (
    BACK_SPEED_MAX_MPS,
    POINT_STALE_INTERVALS,
    QueueEstimator,
    point_lane_queued,
    upstream_reach_m,
)
from wz_alert_service.rules import queue_approach
from wz_alert_service.zone import ZoneGeometry
from wz_shared.messages import (
    AlertSeverity,
    AlertType,
    LaneQueue,
    PointLaneReading,
    PointSensorReading,
    QueueCondition,
    RoadsideDeviceState,
)
from wz_shared.site import PointSensor, Site

ZONE = ZoneGeometry.from_site(SITE)  # approach [300, 1700) m, taper from 1000 m
FAR_REACH = {0: 300.0, 1: 300.0}  # the sensors see the whole approach


def queue_of(
    count: int, back_m: float, speed_mps: float, *, spacing_m: float = 12.0, first_id: int = 1
) -> list:
    """``count`` vehicles of the open lane from ``back_m`` downstream, ``spacing_m`` apart."""
    return [make_track(first_id + i, back_m + spacing_m * i, speed_mps) for i in range(count)]


def test_a_lane_queue_has_its_back_head_length_count_and_mean_speed() -> None:
    estimator = QueueEstimator(ZONE, FAR_REACH)
    fast_car = make_track(99, 800.0, 25.0)  # upstream of the back, at speed: not queued
    closed_car = make_track(98, 950.0, 20.0, offset_m=CLOSED_LANE_D)
    lanes = estimator.estimate([*queue_of(5, 900.0, 4.0), fast_car, closed_car], 10.0)
    by_lane = {lane.lane_index: lane for lane in lanes}
    assert by_lane[1].condition is QueueCondition.FREE and by_lane[1].back_station_m is None
    open_lane = by_lane[0]
    assert open_lane.condition is QueueCondition.SLOW
    assert (open_lane.back_station_m, open_lane.head_station_m) == (900.0, 948.0)
    assert (open_lane.length_m, open_lane.vehicle_count) == (48.0, 5)
    assert open_lane.mean_speed_mps == pytest.approx(4.0)
    assert not open_lane.back_beyond_reach
    assert open_lane.back_speed_mps is None  # one instant: no growth yet


def test_two_slow_vehicles_are_no_queue_and_a_tentative_lane_is_free() -> None:
    estimator = QueueEstimator(ZONE, FAR_REACH)
    lanes = estimator.estimate(queue_of(2, 900.0, 1.0), 0.0)
    assert all(lane.condition is QueueCondition.FREE for lane in lanes)


def test_stopped_turns_slow_only_past_the_hysteresis() -> None:
    rule = ZONE.rules.queue  # stopped below 2.2 m/s, slow again above 2.2 + 2.0
    estimator = QueueEstimator(ZONE, FAR_REACH)

    def condition(speed_mps: float, t: float) -> QueueCondition:
        return estimator.estimate(queue_of(4, 900.0, speed_mps), t)[0].condition

    assert condition(1.0, 0.0) is QueueCondition.STOPPED
    assert condition(rule.stopped_speed_mps + 1.0, 0.1) is QueueCondition.STOPPED  # held
    assert (
        condition(rule.stopped_speed_mps + rule.speed_hysteresis_mps + 0.1, 0.2)
        is QueueCondition.SLOW
    )
    assert condition(rule.stopped_speed_mps + 1.0, 0.3) is QueueCondition.SLOW  # not yet stopped
    assert condition(rule.stopped_speed_mps - 0.1, 0.4) is QueueCondition.STOPPED


def test_the_backs_speed_is_negative_while_the_queue_grows_upstream() -> None:
    estimator = QueueEstimator(ZONE, FAR_REACH)
    growth_mps = -4.0  # a shock wave at 4 m/s upstream
    lane = None
    for k in range(60):  # 6 s at 10 Hz
        t = 0.1 * k
        back_m = 950.0 + growth_mps * t
        lane = estimator.estimate(queue_of(4, back_m, 1.0), t)[0]
    assert lane is not None and lane.back_speed_mps == pytest.approx(growth_mps, abs=1e-6)
    # the queue dissolves: the lane frees, its history is gone
    assert estimator.estimate([], 6.0)[0].back_speed_mps is None


def test_a_back_at_the_sensors_reach_is_beyond_it() -> None:
    estimator = QueueEstimator(ZONE, {0: 880.0, 1: 880.0})
    lane = estimator.estimate(queue_of(4, 890.0, 1.0), 0.0)[0]
    assert lane.back_beyond_reach and lane.reach_station_m == 880.0
    lane = estimator.estimate(queue_of(4, 920.0, 1.0), 0.1)[0]
    assert not lane.back_beyond_reach


def test_the_reach_follows_the_sensors_in_the_site_file() -> None:
    reach = upstream_reach_m(ZONE)
    # the default site's mast sees the approach some hundred metres upstream of the taper, and
    # not the whole 700 m of approach before it
    for lane in SITE.lanes:
        assert ZONE.approach_start_m < reach[lane.index] < ZONE.taper_start_m
    # without the mast's long-range sensors (the LiDAR alone), the reach is shorter
    lidar_only = SITE.model_copy(update={"sensors": [m for m in SITE.sensors if m.kind == "lidar"]})
    short = upstream_reach_m(ZoneGeometry.from_site(lidar_only))
    for lane in SITE.lanes:
        assert short[lane.index] > reach[lane.index]


def test_published_once_a_second_and_at_once_on_a_change() -> None:
    estimator = QueueEstimator(ZONE, FAR_REACH)
    published = []
    for k in range(40):  # 2 s at 20 Hz, a queue from 1.0 s
        t = 0.05 * k
        tracks = queue_of(4, 900.0, 1.0) if t >= 1.0 else []
        state = estimator.update(tracks, t, site=SITE.site_id, source_id="alert-service")
        if state is not None:
            published.append((t, state.condition))
    assert published == [(0.0, QueueCondition.FREE), (1.0, QueueCondition.STOPPED)]
    state = estimator.update(
        queue_of(4, 900.0, 1.0), 2.0, site=SITE.site_id, source_id="alert-service"
    )
    assert state is not None and state.back_station_m == 900.0


def _device(stamp: float, text: str, cause: AlertType | None = AlertType.QUEUE):
    return RoadsideDeviceState(
        site=SITE.site_id,
        source_id="alert-service",
        stamp=stamp,
        beacon_on=bool(text),
        sign_text=text,
        cause=cause if text else None,
    )


def test_the_sign_holds_a_new_queue_message_until_it_has_held() -> None:
    hold = SignHold(5.0)
    assert hold.apply(_device(0.0, "SLOW TRAFFIC 0.3 MI")).sign_text == "SLOW TRAFFIC 0.3 MI"
    # the distance flickers to 0.2 and back: never shown
    for t, text in [(1.0, "SLOW TRAFFIC 0.2 MI"), (2.0, "SLOW TRAFFIC 0.3 MI")]:
        assert hold.apply(_device(t, text)).sign_text == "SLOW TRAFFIC 0.3 MI"
    # 0.2 for good: shown once it has held 5 s
    for t in (3.0, 5.0, 7.9):
        assert hold.apply(_device(t, "SLOW TRAFFIC 0.2 MI")).sign_text == "SLOW TRAFFIC 0.3 MI"
    assert hold.apply(_device(8.0, "SLOW TRAFFIC 0.2 MI")).sign_text == "SLOW TRAFFIC 0.2 MI"
    # stopped traffic is at once; back to slow only after the hold
    assert hold.apply(_device(8.1, STOPPED_TEXT)).sign_text == STOPPED_TEXT
    assert hold.apply(_device(9.0, "SLOW TRAFFIC 0.2 MI")).sign_text == STOPPED_TEXT
    # another cause, and a blank, are at once
    assert hold.apply(_device(9.1, "MERGE RIGHT NOW", AlertType.LATE_MERGE)).sign_text == (
        "MERGE RIGHT NOW"
    )
    assert hold.apply(_device(9.2, "")).sign_text == ""


def test_the_sign_says_stopped_traffic_from_the_lanes_queue() -> None:
    estimator = QueueEstimator(ZONE, FAR_REACH)
    state = estimator.update(
        queue_of(4, 900.0, 0.5), 0.0, site=SITE.site_id, source_id="alert-service"
    )
    devices = roadside_devices([active(AlertType.QUEUE, 900.0)], ZONE, 0.0, queue_state=state)
    assert devices.sign_text == STOPPED_TEXT
    slow = estimator.update(
        queue_of(4, 900.0, 7.0, first_id=10), 1.0, site=SITE.site_id, source_id="x"
    )
    devices = roadside_devices([active(AlertType.QUEUE, 900.0)], ZONE, 1.0, queue_state=slow)
    assert devices.sign_text == "SLOW TRAFFIC 0.2 MI"  # 400 m past the sign at 500 m
    beyond = QueueEstimator(ZONE, {0: 890.0, 1: 890.0}).update(
        queue_of(4, 900.0, 7.0), 0.0, site=SITE.site_id, source_id="x"
    )
    devices = roadside_devices([active(AlertType.QUEUE, 900.0)], ZONE, 0.0, queue_state=beyond)
    assert devices.sign_text == "SLOW TRAFFIC AHEAD"  # no distance beyond the reach


# --- the upstream point sensors: a back beyond the reach bounded --------------------------


def reading(
    sensor_id: str,
    stamp: float,
    speed_mps: float | None,
    *,
    occupancy: float = 20.0,
    interval_s: float = 30.0,
    site: Site = SITE,
) -> PointSensorReading:
    """The open lane's reading of one of the site's point sensors (the closed lane empty)."""
    station = next(p.station_m for p in site.point_sensors if p.sensor_id == sensor_id)
    open_lane = PointLaneReading(
        lane_index=0,
        vehicle_count=0 if speed_mps is None else 8,
        mean_speed_mps=speed_mps,
        occupancy_percent=occupancy,
    )
    closed = PointLaneReading(lane_index=1, vehicle_count=0, occupancy_percent=0.0)
    return PointSensorReading(
        site=site.site_id,
        source_id=sensor_id,
        stamp=stamp,
        station_m=station,
        interval_s=interval_s,
        lanes=[open_lane, closed],
    )


def test_point_sensors_bound_a_back_beyond_the_reach() -> None:
    """The default site's speed-1 (600 m) reads the open lane crawling, speed-2 (350 m) free:
    the back is between them, each bound widened by the farthest the back can have moved
    since the reading's interval began (5 m/s for 30 + 10 s: 200 m)."""
    estimator = QueueEstimator(ZONE, {0: 890.0, 1: 890.0})
    assert estimator.observe(reading("speed-1", 30.0, 3.0))
    assert estimator.observe(reading("speed-2", 30.0, 24.0))
    lane = estimator.estimate(queue_of(4, 895.0, 2.0), 40.0)[0]
    moved_m = BACK_SPEED_MAX_MPS * (40.0 - 30.0 + 30.0)
    assert lane.back_beyond_reach
    assert lane.back_downstream_bound_m == pytest.approx(600.0 + moved_m)
    assert lane.back_upstream_bound_m == pytest.approx(350.0 - moved_m)
    # a back the tracks measure inside the reach has no bounds
    inside = estimator.estimate(queue_of(4, 950.0, 2.0, first_id=20), 41.0)[0]
    assert not inside.back_beyond_reach
    assert inside.back_upstream_bound_m is inside.back_downstream_bound_m is None


def test_a_stale_or_silent_sensor_ends_the_walk() -> None:
    estimator = QueueEstimator(ZONE, {0: 890.0, 1: 890.0})
    estimator.observe(reading("speed-1", 30.0, 24.0))  # free at 600 m
    stale_s = 30.0 + POINT_STALE_INTERVALS * 30.0 + 1.0
    lane = estimator.estimate(queue_of(4, 895.0, 2.0), stale_s)[0]
    assert (lane.back_upstream_bound_m, lane.back_downstream_bound_m) == (None, 890.0)
    # no reading yet of speed-1: nothing bounds the back, though speed-2 reads free
    fresh = QueueEstimator(ZONE, {0: 890.0, 1: 890.0})
    fresh.observe(reading("speed-2", 30.0, 24.0))
    lane = fresh.estimate(queue_of(4, 895.0, 2.0), 40.0)[0]
    assert lane.back_upstream_bound_m is None


def test_a_queue_standing_on_a_sensor_reads_queued_and_an_empty_lane_free() -> None:
    rule = ZONE.rules.queue
    stopped = PointLaneReading(lane_index=0, vehicle_count=0, occupancy_percent=80.0)
    empty = PointLaneReading(lane_index=0, vehicle_count=0, occupancy_percent=0.0)
    assert point_lane_queued(stopped, rule, queued_before=False)
    assert not point_lane_queued(empty, rule, queued_before=False)
    between = PointLaneReading(
        lane_index=0,
        vehicle_count=5,
        mean_speed_mps=rule.slow_speed_mps + 1.0,
        occupancy_percent=30.0,
    )
    assert not point_lane_queued(between, rule, queued_before=False)
    assert point_lane_queued(between, rule, queued_before=True)  # the queue rule's hysteresis


def test_only_the_site_files_point_sensors_are_taken() -> None:
    core = AlertCore(SITE, lambda reason, detail: None)
    forged = reading("speed-1", 30.0, 3.0).model_copy(update={"source_id": "speed-9"})
    assert core.add_point(forged) == "unknown_sensor"
    other = reading("speed-1", 30.0, 3.0).model_copy(update={"site": "elsewhere"})
    assert core.add_point(other) == "wrong_site"
    assert core.add_point(reading("speed-1", 30.0, 3.0)) is None
    # the station is the site file's, whatever the message says
    moved = reading("speed-2", 30.0, 24.0).model_copy(update={"station_m": 880.0})
    assert core.add_point(moved) is None
    estimator = core.engine.queues
    assert estimator.point_bounds(0, 890.0, 40.0)[0] == pytest.approx(350.0 - 200.0)


def test_the_sign_gives_the_distance_to_the_nearest_the_back_may_stand() -> None:
    """A sensor 850 m reading free 10 s ago over 10 s: the back is downstream of 850 - 100 m,
    400 m past the sign at 500 m (0.2 mi); without the reading, no distance."""
    site = SITE.model_copy(
        update={"point_sensors": [PointSensor(sensor_id="near", station_m=850.0, interval_s=10.0)]}
    )
    zone = ZoneGeometry.from_site(site)
    estimator = QueueEstimator(zone, {0: 890.0, 1: 890.0})
    estimator.observe(reading("near", 10.0, 25.0, interval_s=10.0, site=site))
    state = estimator.update(queue_of(4, 895.0, 7.0), 20.0, site=site.site_id, source_id="x")
    assert state is not None and state.lanes[0].back_upstream_bound_m == pytest.approx(750.0)
    devices = roadside_devices([active(AlertType.QUEUE, 895.0)], zone, 20.0, queue_state=state)
    assert devices.sign_text == "SLOW TRAFFIC 0.2 MI"
    unbounded = QueueEstimator(zone, {0: 890.0, 1: 890.0}).update(
        queue_of(4, 895.0, 7.0), 20.0, site=site.site_id, source_id="x"
    )
    devices = roadside_devices([active(AlertType.QUEUE, 895.0)], zone, 20.0, queue_state=unbounded)
    assert devices.sign_text == "SLOW TRAFFIC AHEAD"


# --- approaching the queue too fast ----------------------------------------------------------


def stopped_lane(back_m: float = 900.0) -> LaneQueue:
    return LaneQueue(
        lane_index=0,
        condition=QueueCondition.STOPPED,
        back_station_m=back_m,
        head_station_m=back_m + 36.0,
        length_m=36.0,
        vehicle_count=4,
        mean_speed_mps=0.0,
        reach_station_m=300.0,
    )


RULE = SITE.alerts.queue_approach  # 3.4 m/s^2, critical 4.9, stopping 7.5 m behind the back
SLOW = SITE.alerts.queue.slow_speed_mps


@pytest.mark.parametrize(
    ("gap_m", "expected"),
    [
        # a = v^2 / (2 (gap - 7.5)) at 25 m/s
        (100.0, None),  # 625 / 185 = 3.38
        (90.0, AlertSeverity.WARNING),  # 625 / 165 = 3.79
        (70.0, AlertSeverity.CRITICAL),  # 625 / 125 = 5.0
        (5.0, AlertSeverity.CRITICAL),  # no room left
    ],
)
def test_the_deceleration_needed_to_stop_behind_the_back(
    gap_m: float, expected: AlertSeverity | None
) -> None:
    car = make_track(50, 900.0 - gap_m, 25.0)
    finding = queue_approach(car, stopped_lane(), ZONE, RULE, slow_speed_mps=SLOW)
    if expected is None:
        assert finding is None
        return
    assert finding is not None and finding.severity is expected
    room_m = gap_m - RULE.stop_spacing_m
    if room_m > 0:
        assert finding.measured_value == pytest.approx(25.0**2 / (2.0 * room_m))
    assert finding.evidence["time_to_back_s"] == pytest.approx(max(0.0, room_m) / 25.0)
    assert finding.evidence["queue_back_station_m"] == 900.0


def test_queue_approach_hysteresis_and_what_is_not_approaching() -> None:
    near_threshold = make_track(50, 900.0 - 100.0, 25.0)  # 3.38 m/s^2: under 3.4, over 3.0
    assert queue_approach(near_threshold, stopped_lane(), ZONE, RULE, slow_speed_mps=SLOW) is None
    assert (
        queue_approach(near_threshold, stopped_lane(), ZONE, RULE, slow_speed_mps=SLOW, active=True)
        is not None
    )
    crawling = make_track(51, 880.0, SLOW - 0.1)  # part of the queue's traffic
    past = make_track(52, 910.0, 25.0)  # downstream of the back
    for track in (crawling, past):
        assert queue_approach(track, stopped_lane(), ZONE, RULE, slow_speed_mps=SLOW) is None
    free = LaneQueue(lane_index=0, condition=QueueCondition.FREE, reach_station_m=300.0)
    car = make_track(53, 850.0, 25.0)
    assert queue_approach(car, free, ZONE, RULE, slow_speed_mps=SLOW) is None
    assert queue_approach(car, None, ZONE, RULE, slow_speed_mps=SLOW) is None
    # A back beyond the sensors' reach stands upstream of every track they see: a fast track
    # 90 m downstream of where the queue leaves their sight is not closing on it.
    beyond = stopped_lane().model_copy(update={"back_beyond_reach": True})
    seen = make_track(54, 900.0 - 90.0, 25.0)
    assert queue_approach(seen, stopped_lane(), ZONE, RULE, slow_speed_mps=SLOW) is not None
    assert queue_approach(seen, beyond, ZONE, RULE, slow_speed_mps=SLOW) is None


def test_the_engine_alerts_a_car_closing_on_a_stopped_queue() -> None:
    engine = AlertEngine(SITE, reach_m=FAR_REACH)
    stopped = queue_of(4, 900.0, 0.0)
    starts = []
    for k, t in enumerate(stamps(3.0)):
        car = make_track(60, 760.0 + 25.0 * t, 25.0)  # 140 m behind the back at t = 0
        events = engine.update(batch(t, [*stopped, car], k))
        starts += [
            e for e in events if e.phase == "start" and e.alert_type is AlertType.QUEUE_APPROACH
        ]
    assert len(starts) == 1 and starts[0].track_id == 60
    # a = 625 / (2 D) >= 3.4 from D <= 91.9 m, i.e. the car within 99.4 m of the back, at
    # t >= 1.62 s; started after the 0.5 s hold
    assert starts[0].stamp == pytest.approx(1.62 + RULE.hold_s, abs=0.06)
    assert starts[0].finding.evidence["time_to_back_s"] > 2.0
