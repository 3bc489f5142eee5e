"""Beacon and message sign from the open episodes: which alerts light them, the sign's priority
and its text, the queue's distance in tenths of a mile, and the engine feeding them."""

from __future__ import annotations

import dataclasses

import pytest

from tests.alert_service.helpers import SITE, batch, make_track, stamps
from wz_alert_service.devices import (
    DEFAULT_SOURCE_ID,
    METERS_PER_MILE,
    queue_sign_text,
    roadside_devices,
)
from wz_alert_service.engine import ActiveAlert, AlertEngine
from wz_alert_service.rules import Finding
from wz_alert_service.zone import ZoneGeometry
from wz_shared import codec
from wz_shared.messages import AlertSeverity, AlertType, RoadsideDeviceState

ZONE = ZoneGeometry.from_site(SITE)  # sign at 500 m, activity area ends at 1700 m


def active(alert_type: AlertType, station_m: float) -> ActiveAlert:
    finding = Finding(
        alert_type=alert_type,
        severity=AlertSeverity.WARNING,
        measured_value=1.0,
        threshold_value=1.0,
        value_unit="m",
        station_m=station_m,
        offset_m=0.0,
        speed_mps=10.0,
        description="test",
    )
    return ActiveAlert(
        episode_id=f"{alert_type.value}-1",
        alert_type=alert_type,
        track_id=None,
        severity=AlertSeverity.WARNING,
        onset_stamp=0.0,
        start_stamp=1.0,
        finding=finding,
    )


def test_nothing_active_means_beacon_off_and_sign_blank() -> None:
    assert roadside_devices([], ZONE, 5.0) == RoadsideDeviceState(
        site=SITE.site_id, source_id=DEFAULT_SOURCE_ID, stamp=5.0, beacon_on=False, sign_text=""
    )


def test_the_state_is_a_bus_message_that_compares_without_its_stamp() -> None:
    state = roadside_devices([active(AlertType.SPEEDING, 1000.0)], ZONE, 5.0, source_id="x")
    assert (state.site, state.source_id) == (SITE.site_id, "x")
    assert codec.decode_json(codec.encode_json(state), RoadsideDeviceState) == state
    later = roadside_devices([active(AlertType.SPEEDING, 900.0)], ZONE, 6.0, source_id="x")
    assert state.shows_same_as(later) and not state.shows_same_as(None)
    assert not state.shows_same_as(roadside_devices([], ZONE, 6.0, source_id="x"))


@pytest.mark.parametrize(
    ("alert_type", "text"),
    [
        (AlertType.SPEEDING, "SLOW DOWN"),
        (AlertType.AGGRESSIVE_APPROACH, "SLOW DOWN"),
        (AlertType.SHORT_TTC, "SLOW DOWN"),
        (AlertType.LATE_MERGE, "MERGE RIGHT NOW"),
        (AlertType.QUEUE, "SLOW TRAFFIC 0.3 MI"),  # 1000 - 500 = 500 m = 0.31 mi
        (AlertType.HARD_BRAKING, ""),
        (AlertType.INTRUSION, ""),
    ],
)
def test_each_alert_type_alone(alert_type: AlertType, text: str) -> None:
    state = roadside_devices([active(alert_type, 1000.0)], ZONE, 5.0)
    assert state.beacon_on is bool(text)
    assert state.sign_text == text
    assert state.cause is (alert_type if text else None)


def test_only_alerts_upstream_of_the_activity_area_end_light_the_beacon() -> None:
    assert roadside_devices([active(AlertType.SPEEDING, 1699.9)], ZONE, 0.0).beacon_on
    assert not roadside_devices([active(AlertType.SPEEDING, 1700.0)], ZONE, 0.0).beacon_on


def test_sign_priority_queue_then_merge_then_slow_down() -> None:
    alerts = [
        active(AlertType.SPEEDING, 800.0),
        active(AlertType.LATE_MERGE, 950.0),
        active(AlertType.INTRUSION, 1400.0),
    ]
    assert roadside_devices(alerts, ZONE, 0.0).sign_text == "MERGE RIGHT NOW"
    state = roadside_devices([*alerts, active(AlertType.QUEUE, 900.0)], ZONE, 0.0)
    # 900 - 500 = 400 m = 0.2485 mi -> 0.2
    assert (state.sign_text, state.cause, state.queue_tail_station_m) == (
        "SLOW TRAFFIC 0.2 MI",
        AlertType.QUEUE,
        900.0,
    )
    assert state.beacon_on


@pytest.mark.parametrize(
    ("tail_m", "text"),
    [
        (500.0 + 0.0499 * METERS_PER_MILE, "SLOW TRAFFIC AHEAD"),  # 0.0499 mi rounds to 0.0
        (500.0 + 0.0501 * METERS_PER_MILE, "SLOW TRAFFIC 0.1 MI"),
        (500.0 + 0.3449 * METERS_PER_MILE, "SLOW TRAFFIC 0.3 MI"),
        (500.0 + 0.3501 * METERS_PER_MILE, "SLOW TRAFFIC 0.4 MI"),
        (500.0 + 1.0 * METERS_PER_MILE, "SLOW TRAFFIC 1.0 MI"),
        (450.0, "SLOW TRAFFIC AHEAD"),  # behind the sign
    ],
)
def test_queue_distance_in_tenths_of_a_mile(tail_m: float, text: str) -> None:
    assert queue_sign_text(tail_m, 500.0) == text


def test_merge_left_where_the_right_lane_is_closed() -> None:
    zone = dataclasses.replace(ZONE, merge_direction="LEFT")
    assert roadside_devices([active(AlertType.LATE_MERGE, 950.0)], zone, 0.0).sign_text == (
        "MERGE LEFT NOW"
    )


def test_engine_feeds_the_devices() -> None:
    engine = AlertEngine(SITE)
    stopped = [make_track(i, 1100.0 - 15.0 * i, 0.5) for i in range(1, 5)]  # tail at 1040 m
    for k, t in enumerate(stamps(4.0)):
        engine.update(batch(t, stopped, k))
    state = roadside_devices(engine.active(), engine.zone, 4.0)
    # 1040 - 500 = 540 m = 0.336 mi
    assert state == RoadsideDeviceState(
        site=SITE.site_id,
        source_id=DEFAULT_SOURCE_ID,
        stamp=4.0,
        beacon_on=True,
        sign_text="SLOW TRAFFIC 0.3 MI",
        cause=AlertType.QUEUE,
        queue_tail_station_m=1040.0,
    )
