"""Whether the sensors see each lane at the traffic detector, or a truck hides it
(wz_gateway.lane_sight), and what the WZDx feed then says of the lane's volume."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from tests.gateway.helpers import (
    SITE,
    batch,
    gateway_settings,
    make_track,
    open_storage,
    service_status,
)
from tests.gateway.test_wzdx import (
    KEYS,
    T0_UNIX,
    assert_valid,
    features_by_type,
    feed_of,
    traffic_batches,
)
from wz_gateway.lane_sight import lane_hidden_shares, sight_station_range
from wz_gateway.storage import Storage
from wz_gateway.traffic import HIDDEN_SHARE_LIMIT
from wz_gateway.wzdx import detector_station_m
from wz_shared.messages import Message, Track, VehicleClass

#: The default site's loop is 967 m, 13 m upstream of its mast (7.5 m right of the road, LiDAR
#: 6 m up): lane 0 (right, offset -1.83 m) nearer the mast, lane 1 (left, +1.83 m) beyond it.
LOOP_M = detector_station_m(SITE)


def standing_truck(station_m: float, track_id: int = 900) -> Track:
    """A 16 m semitrailer standing in lane 0 (a queue)."""
    return make_track(track_id, station_m, 0.0, length_m=16.0).model_copy(
        update={"object_class": VehicleClass.TRUCK, "width_m": 2.5}
    )


def shares(tracks: list[Track], station_m: float = LOOP_M) -> dict[int, float]:
    stamps = np.repeat([0.0, 0.5, 1.0], len(tracks))
    rows = tracks * 3
    return lane_hidden_shares(
        SITE,
        station_m,
        stamps,
        [t.x_m for t in rows],
        [t.y_m for t in rows],
        [t.heading_rad for t in rows],
        [t.length_m or np.nan for t in rows],
        [t.width_m or np.nan for t in rows],
        [str(t.object_class) for t in rows],
        0.0,
        1.0,
    )


def test_a_truck_between_the_mast_and_the_far_lane_hides_that_lane_only() -> None:
    assert pytest.approx(967.0) == LOOP_M
    # The sight lines to the far lane's spot cross lane 0 at 970-974 m, 2.7-3.3 m up.
    assert shares([standing_truck(979.0)]) == {0: 0.0, 1: 1.0}
    # The same truck at the loop is the vehicle seen there, not a wall in front of the far lane.
    assert shares([standing_truck(LOOP_M + 4.0)])[0] == 0.0
    # A car there is too low to hide anything from a mast 5-6 m up.
    car = make_track(901, 975.0, 0.0)
    assert shares([car]) == {0: 0.0, 1: 0.0}
    # Nor does a truck downstream of the mast.
    assert shares([standing_truck(1000.0)]) == {0: 0.0, 1: 0.0}


def test_a_spot_no_sensor_covers_is_hidden_and_no_track_hides_nothing() -> None:
    assert shares([make_track(901, 500.0, 25.0)], station_m=400.0) == {0: 1.0, 1: 1.0}
    assert shares([]) == {0: 0.0, 1: 0.0}
    low, high = sight_station_range(SITE, LOOP_M)
    assert low == pytest.approx(LOOP_M - 10.0) and high == pytest.approx(980.2 + 10.0)


@pytest.fixture
def storage(tmp_path: Path) -> Iterator[Storage]:
    store = open_storage(gateway_settings(tmp_path))
    yield store
    store.close()


def test_the_feed_withholds_the_hidden_lanes_volume_and_says_why(storage: Storage) -> None:
    """300 s: 10 cars in lane 0, 5 in lane 1, while a truck stands in lane 0 just past the
    loop (a queue's back). Lane 1 (WZDx order 1) is hidden: its volume and occupancy are
    withheld, the station's too, with a warning; lane 0's stay."""
    truck = standing_truck(979.0)
    messages: list[Message] = [
        b.model_copy(update={"tracks": [*b.tracks, truck]}) for b in traffic_batches()
    ]
    messages.sort(key=lambda m: m.stamp)
    for message in messages:
        storage.ingest([message], geo=SITE.geo_frame, received_at=T0_UNIX + message.stamp)
    storage.ingest([batch(300.0, [], 99_999)], geo=SITE.geo_frame, received_at=T0_UNIX + 300.0)
    now = T0_UNIX + 301.0
    for service, hz in (
        ("lidar-detector", {KEYS.raw_lidar("lidar-mast"): 20.0}),
        ("camera-detector", {KEYS.raw_camera("camera-mast"): 10.0}),
        ("alert-service", {KEYS.tracks: 20.0}),
    ):
        storage.ingest([service_status(service, 300.0, hz)], geo=SITE.geo_frame, received_at=now)
    feed = feed_of(storage, now)
    assert_valid(feed)
    sensor = features_by_type(feed)["traffic-sensor"]["properties"]
    left, right = sensor["lane_data"]
    assert left == {"lane_order": 1, "average_speed_kph": 72.0}
    assert right["lane_order"] == 2 and right["volume_vph"] == 120.0
    assert "volume_vph" not in sensor and "occupancy_percent" not in sensor
    core = sensor["core_details"]
    assert core["device_status"] == "warning"
    (message,) = [m for m in core["status_messages"] if "withheld" in m]
    assert message.startswith("lane 1 volume withheld: hidden from the sensors")
    assert HIDDEN_SHARE_LIMIT == 0.05
