"""The WZDx 4.2 DeviceFeed: valid against the published schema (offline, every $ref resolved
from the spec folder, date-time formats checked), and its numbers and states right."""

from __future__ import annotations

import json
from collections.abc import Iterator
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import pytest
from jsonschema import Draft7Validator
from referencing import Registry, Resource
from referencing.exceptions import Unresolvable
from referencing.jsonschema import DRAFT7

from tests.gateway.helpers import (
    SITE,
    SPEC_DIR,
    batch,
    car_batches,
    devices_state,
    gateway_settings,
    open_storage,
    service_status,
)
from wz_gateway import views, wzdx
from wz_gateway.storage import Storage
from wz_shared.keys import Keys
from wz_shared.messages import (
    BEACON_DEVICE,
    SIGN_DEVICE,
    AlertType,
    DeviceLink,
    Message,
    PointLaneReading,
    PointSensorReading,
    ServiceState,
    TrackBatch,
)

KEYS = Keys(SITE.site_id)
T0_UNIX = 1_750_000_000.0  # wall clock at stamp 0 in these tests


def wzdx_validator(schema_file: str = "DeviceFeed.json") -> Draft7Validator:
    """A draft-07 validator whose registry holds every schema of the spec folder by its $id;
    it has no way to fetch anything, so an unresolved $ref fails instead of going online."""
    resources = []
    for path in sorted(SPEC_DIR.glob("*.json")):
        contents = json.loads(path.read_text(encoding="utf-8"))
        resources.append((contents["$id"], Resource.from_contents(contents, DRAFT7)))
    registry: Registry[Any] = Registry().with_resources(resources)
    schema = json.loads((SPEC_DIR / schema_file).read_text(encoding="utf-8"))
    return Draft7Validator(schema, registry=registry, format_checker=Draft7Validator.FORMAT_CHECKER)


def assert_valid(feed: dict[str, Any]) -> None:
    errors = sorted(wzdx_validator().iter_errors(feed), key=lambda e: list(e.absolute_path))
    assert not errors, "\n".join(f"{list(e.absolute_path)}: {e.message}" for e in errors[:10])


def features_by_type(feed: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """The first feature of each device type (the mast's traffic sensor before the upstream
    point sensors')."""
    found: dict[str, dict[str, Any]] = {}
    for feature in feed["features"]:
        found.setdefault(feature["properties"]["core_details"]["device_type"], feature)
    return found


def mast_features(feed: dict[str, Any]) -> list[dict[str, Any]]:
    """The features of the mast and its devices: all but the upstream point sensors'."""
    return [
        f
        for f in feed["features"]
        if not f["properties"]["core_details"]["name"].startswith("Point speed sensor")
    ]


@pytest.fixture
def storage(tmp_path: Path) -> Iterator[Storage]:
    store = open_storage(gateway_settings(tmp_path))
    yield store
    store.close()


def store(storage: Storage, messages: list[Message], received_at: float) -> None:
    storage.ingest(messages, geo=SITE.geo_frame, received_at=received_at)


def traffic_batches() -> list[TrackBatch]:
    """10 cars at 25 m/s in lane 0 (the right lane) and 5 at 20 m/s in lane 1 over 300 s, each
    crossing the detector (967 m, 13 m before the mast) once."""
    batches: list[TrackBatch] = []
    for k in range(10):
        batches += car_batches(100 + k, 900.0, 25.0, 30.0 * k, 40, first_cycle=1000 * k)
    for k in range(5):
        batches += car_batches(
            200 + k, 910.0, 20.0, 30.0 * k + 10.0, 40, offset_m=1.83, first_cycle=1000 * k + 500
        )
    return batches


def traffic_day(storage: Storage) -> None:
    """300 s of traffic (:func:`traffic_batches`), then an empty road at 300 s. Each batch
    arrives when it was captured (T0_UNIX + stamp)."""
    messages: list[Message] = list(traffic_batches())
    messages.sort(key=lambda m: m.stamp)
    for message in messages:
        store(storage, [message], T0_UNIX + message.stamp)
    store(storage, [batch(300.0, [], 99_999)], T0_UNIX + 300.0)


def feed_of(storage: Storage, now: float) -> dict[str, Any]:
    return views.device_feed_of(
        storage,
        SITE,
        now=now,
        publisher="Test DOT",
        stale_after_s=10.0,
        traffic_interval_s=300.0,
        contact_email="ops@example.org",
    )


def test_the_validator_resolves_refs_offline_and_checks_formats() -> None:
    validator = wzdx_validator()
    for example in sorted((SPEC_DIR / "examples").glob("*.geojson")):
        validator.validate(json.loads(example.read_text(encoding="utf-8")))
    assert "date-time" in Draft7Validator.FORMAT_CHECKER.checkers  # rfc3339-validator present
    example = json.loads((SPEC_DIR / "examples" / "camera_error_example.geojson").read_text())
    example["feed_info"]["update_date"] = "yesterday"
    example["features"][0]["properties"]["core_details"]["device_status"] = "fine"
    messages = {e.message for e in validator.iter_errors(example)}
    assert any("date-time" in m for m in messages) and len(messages) >= 2
    # A $ref outside the folder cannot be fetched: the registry has no retriever.
    with pytest.raises(Unresolvable):
        validator.evolve(schema={"$ref": "https://example.org/elsewhere.json"}).validate({})


def test_feed_before_any_data_is_valid_and_unknown(storage: Storage) -> None:
    now = T0_UNIX
    feed = feed_of(storage, now)
    assert_valid(feed)
    devices = features_by_type(feed)
    assert set(devices) == {"traffic-sensor", "camera", "flashing-beacon", "dynamic-message-sign"}
    for feature in feed["features"]:
        assert feature["properties"]["core_details"]["device_status"] == "unknown"
        assert feature["properties"]["core_details"]["status_messages"]
    sensor = devices["traffic-sensor"]["properties"]
    assert "volume_vph" not in sensor and "lane_data" not in sensor
    assert feed["feed_info"]["version"] == "4.2"
    assert feed["feed_info"]["contact_email"] == "ops@example.org"


def test_feed_counts_traffic_per_lane_in_wzdx_units(storage: Storage) -> None:
    traffic_day(storage)
    now = T0_UNIX + 301.0
    for service, hz in (
        ("lidar-detector", {KEYS.raw_lidar("lidar-mast"): 20.0}),
        ("camera-detector", {KEYS.raw_camera("camera-mast"): 10.0}),
        ("alert-service", {KEYS.tracks: 20.0}),
    ):
        store(storage, [service_status(service, 300.0, hz)], now - 1.0)
    store(
        storage,
        [devices_state(250.0, beacon_on=True, sign_text="SLOW DOWN", cause=AlertType.SPEEDING)],
        now - 50.0,
    )
    feed = feed_of(storage, now)
    assert_valid(feed)
    devices = features_by_type(feed)
    for feature in mast_features(feed):  # the point sensors have sent nothing here
        core = feature["properties"]["core_details"]
        assert core["device_status"] == "ok", core
        assert core["road_names"] == ["US-75"] and core["road_direction"] == "northbound"

    sensor = devices["traffic-sensor"]["properties"]
    # The interval is the run's first 300 s of stamps, dated by the newest batch's arrival.
    assert sensor["collection_interval_start_date"] == "2025-06-15T15:06:40Z"
    assert (
        datetime.fromtimestamp(T0_UNIX, UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
        == (sensor["collection_interval_start_date"])
    )
    assert sensor["collection_interval_end_date"] == "2025-06-15T15:11:40Z"
    # Lane 1 (the left, WZDx lane_order 1): 5 cars at 20 m/s; lane 0 (order 2): 10 at 25 m/s.
    # volume = 3600 n / 300 s; occupancy = 100 n (4.5 m + 1.83 m) / v / 300 s.
    left, right = sensor["lane_data"]
    assert left == {
        "lane_order": 1,
        "volume_vph": 60.0,
        "average_speed_kph": 72.0,
        "occupancy_percent": pytest.approx(round(100 * 5 * 6.33 / 20 / 300, 1)),
    }
    assert right == {
        "lane_order": 2,
        "volume_vph": 120.0,
        "average_speed_kph": 90.0,
        "occupancy_percent": pytest.approx(round(100 * 10 * 6.33 / 25 / 300, 1)),
    }
    assert sensor["volume_vph"] == 180.0
    assert sensor["average_speed_kph"] == pytest.approx(round((10 * 90 + 5 * 72) / 15, 1))
    occupancy = (100 * 5 * 6.33 / 20 / 300 + 100 * 10 * 6.33 / 25 / 300) / 2
    assert sensor["occupancy_percent"] == pytest.approx(round(occupancy, 1))

    beacon = devices["flashing-beacon"]["properties"]
    assert beacon["is_flashing"] is True and beacon["function"] == "reduced-speed"
    assert devices["dynamic-message-sign"]["properties"]["message_multi_string"] == "SLOW DOWN"

    # Positions: [longitude, latitude], the mast 980 m north and 7.5 m east of the origin.
    longitude, latitude = devices["traffic-sensor"]["geometry"]["coordinates"]
    assert latitude == pytest.approx(40.75 + 980.0 / 111_035.0, abs=2e-5)
    assert longitude == pytest.approx(-96.688 + 7.5 / 84_400.0, abs=2e-5)
    # Stable ids: the same device has the same id in every feed.
    assert feed_of(storage, now)["features"][0]["id"] == devices["traffic-sensor"]["id"]


def test_a_restarted_simulation_counts_only_its_own_run(storage: Storage) -> None:
    traffic_day(storage)  # run 1: 15 vehicles over stamps 0-300 s
    second = T0_UNIX + 1000.0  # run 2 starts from stamp 0 again, later on the wall clock
    for message in sorted(
        (m for k in range(3) for m in car_batches(300 + k, 900.0, 25.0, 30.0 * k, 40)),
        key=lambda m: m.stamp,
    ):
        store(storage, [message], second + message.stamp)
    store(storage, [batch(120.0, [], 5000)], second + 120.0)
    run_start = storage.latest(SITE.site_id, "run_start")
    assert run_start is not None and run_start.stamp == 0.0
    feed = feed_of(storage, second + 121.0)
    assert_valid(feed)
    sensor = features_by_type(feed)["traffic-sensor"]["properties"]
    left, right = sensor["lane_data"]
    assert (left["volume_vph"], right["volume_vph"]) == (0.0, 90.0)  # 3 cars in 120 s
    assert sensor["collection_interval_start_date"] == wzdx.rfc3339(second)


def test_stale_data_and_silent_services_are_errors(storage: Storage) -> None:
    traffic_day(storage)
    store(
        storage,
        [
            service_status("lidar-detector", 300.0, {}),
            service_status("camera-detector", 300.0, {}),
            service_status("alert-service", 300.0, {}),
        ],
        T0_UNIX + 300.0,
    )
    # Alive but without frames: the camera is in error, the traffic sensor (tracks still
    # arriving) only warns about its LiDAR.
    feed = feed_of(storage, T0_UNIX + 302.0)
    assert_valid(feed)
    devices = features_by_type(feed)
    camera = devices["camera"]["properties"]["core_details"]
    assert camera["device_status"] == "error"
    assert camera["status_messages"] == [
        f"camera-detector receives no frames on {KEYS.raw_camera('camera-mast')}"
    ]
    assert devices["traffic-sensor"]["properties"]["core_details"]["device_status"] == "warning"
    # A minute later nothing has arrived: every device is in error and says for how long.
    feed = feed_of(storage, T0_UNIX + 360.0)
    assert_valid(feed)
    for feature in mast_features(feed):
        core = feature["properties"]["core_details"]
        assert core["device_status"] == "error", core
        assert any("for 60 s" in m for m in core["status_messages"]), core


def test_queue_sign_and_its_beacon(storage: Storage) -> None:
    store(
        storage,
        [
            devices_state(
                5.0, beacon_on=True, sign_text="QUEUE AHEAD 0.3 MI", cause=AlertType.QUEUE
            ),
            service_status("alert-service", 5.0, {}),
        ],
        T0_UNIX,
    )
    feed = feed_of(storage, T0_UNIX + 1.0)
    assert_valid(feed)
    devices = features_by_type(feed)
    assert devices["flashing-beacon"]["properties"]["function"] == "queue-warning"
    sign = devices["dynamic-message-sign"]["properties"]
    assert sign["message_multi_string"] == "QUEUE AHEAD 0.3 MI"
    assert sign["core_details"]["device_status"] == "ok"
    # The sign stands on the right shoulder at its station (500 m), not on the road.
    longitude, latitude = devices["dynamic-message-sign"]["geometry"]["coordinates"]
    x, y, _ = SITE.geo_frame.to_site(latitude, longitude)
    station, offset = SITE.road_frame.to_road(x, y)
    assert float(station) == pytest.approx(500.0, abs=0.05)
    assert float(offset) == pytest.approx(-3.66 - wzdx.SHOULDER_OFFSET_M, abs=0.05)


def test_multi_strings() -> None:
    assert wzdx.multi("MERGE\nRIGHT NOW") == "MERGE[nl]RIGHT NOW"
    assert wzdx.multi("[X]") == "[[X]]"
    assert wzdx.multi("") == ""


def test_a_stalled_alert_service_puts_its_sign_and_beacon_in_error(storage: Storage) -> None:
    """A status that still comes but says the loop stopped going round (issue 26): the
    devices it drives are in error, saying so, not ok."""
    traffic_day(storage)
    stalled = service_status("alert-service", 300.0, {}).model_copy(
        update={"state": ServiceState.STALLED, "loop_age_s": 12.0}
    )
    store(storage, [stalled], T0_UNIX + 300.0)
    feed = feed_of(storage, T0_UNIX + 301.0)
    assert_valid(feed)
    for device_type in ("flashing-beacon", "dynamic-message-sign"):
        core = features_by_type(feed)[device_type]["properties"]["core_details"]
        assert core["device_status"] == "error", core
        assert "alert-service stalled: no work for 12 s" in core["status_messages"], core


def test_the_beacon_relay_not_answering_its_driver_puts_the_beacon_alone_in_error(
    storage: Storage,
) -> None:
    """The device driver reports the sign answering and the beacon's relay module not: the
    beacon's feature is ``error`` with the driver's reason, the sign's stays ``ok``."""
    traffic_day(storage)
    flashing = devices_state(299.0, beacon_on=True, sign_text="SLOW DOWN", cause=AlertType.SPEEDING)
    store(storage, [flashing, service_status("alert-service", 300.0, {})], T0_UNIX + 300.0)
    relay = "tcp 10.0.0.8:502 unit 1 coil 0"
    driver = service_status("device-driver", 300.0, {}).model_copy(
        update={
            "state": ServiceState.DEGRADED,
            "devices": {
                SIGN_DEVICE: DeviceLink(address="udp 10.0.0.9:161", reachable=True),
                BEACON_DEVICE: DeviceLink(
                    address=relay,
                    reachable=False,
                    detail=f"{relay}: timeout, no answer to the read in 2 x 0.4 s",
                    answer_age_s=7.0,
                ),
            },
        }
    )
    store(storage, [driver], T0_UNIX + 300.0)
    feed = feed_of(storage, T0_UNIX + 301.0)
    assert_valid(feed)
    devices = features_by_type(feed)
    beacon = devices[BEACON_DEVICE]["properties"]["core_details"]
    assert beacon["device_status"] == "error", beacon
    assert beacon["status_messages"] == [
        f"flashing-beacon at {relay} not answering: {relay}: timeout, no answer to the read in "
        "2 x 0.4 s (last answer 7 s ago)"
    ]
    assert devices[BEACON_DEVICE]["properties"]["is_flashing"] is True  # what is wanted
    assert devices[SIGN_DEVICE]["properties"]["core_details"]["device_status"] == "ok"

    # Before its first exchange the relay is unknown, not ok.
    waiting = driver.model_copy(
        update={
            "state": ServiceState.RUNNING,
            "devices": {**driver.devices, BEACON_DEVICE: DeviceLink(address=relay)},
        }
    )
    store(storage, [waiting], T0_UNIX + 301.0)
    beacon = features_by_type(feed_of(storage, T0_UNIX + 302.0))[BEACON_DEVICE]
    assert beacon["properties"]["core_details"]["device_status"] == "unknown"


def point_reading(sensor_id: str, stamp: float) -> PointSensorReading:
    """The default site's point sensor ``sensor_id`` over 30 s: 6 cars at 24 m/s in lane 0
    (WZDx lane 2, the right), 3 at 20 m/s in lane 1."""
    station = next(p.station_m for p in SITE.point_sensors if p.sensor_id == sensor_id)
    return PointSensorReading(
        site=SITE.site_id,
        source_id=sensor_id,
        stamp=stamp,
        station_m=station,
        interval_s=30.0,
        lanes=[
            PointLaneReading(
                lane_index=0, vehicle_count=6, mean_speed_mps=24.0, occupancy_percent=4.0
            ),
            PointLaneReading(
                lane_index=1, vehicle_count=3, mean_speed_mps=20.0, occupancy_percent=2.0
            ),
        ],
    )


def test_each_point_sensor_is_a_traffic_sensor_of_its_newest_reading(storage: Storage) -> None:
    """The default site's two upstream point sensors: unknown before a reading, then its
    figures per lane (volume per hour from the interval's count), the station's totals and a
    count-weighted speed; an error once the newest is older than 2.5 intervals."""
    feed = feed_of(storage, T0_UNIX)
    assert_valid(feed)
    points = [
        f for f in feed["features"] if f["properties"]["core_details"]["name"].startswith("Point")
    ]
    assert [f["properties"]["core_details"]["device_status"] for f in points] == ["unknown"] * 2
    store(storage, [point_reading("speed-1", 60.0)], T0_UNIX + 60.0)
    store(storage, [point_reading("speed-2", 30.0)], T0_UNIX + 30.0)
    feed = feed_of(storage, T0_UNIX + 61.0)
    assert_valid(feed)
    by_name = {
        f["properties"]["core_details"]["name"]: f["properties"]
        for f in feed["features"]
        if f["properties"]["core_details"]["device_type"] == "traffic-sensor"
    }
    first = by_name["Point speed sensor speed-1"]
    assert first["core_details"]["device_status"] == "ok"
    assert first["lane_data"] == [
        {"lane_order": 1, "volume_vph": 360.0, "occupancy_percent": 2.0, "average_speed_kph": 72.0},
        {"lane_order": 2, "volume_vph": 720.0, "occupancy_percent": 4.0, "average_speed_kph": 86.4},
    ]
    assert (first["volume_vph"], first["occupancy_percent"]) == (1080.0, 3.0)
    assert first["average_speed_kph"] == pytest.approx((6 * 86.4 + 3 * 72.0) / 9, abs=0.05)
    second = by_name["Point speed sensor speed-2"]
    assert second["core_details"]["device_status"] == "ok"  # 31 s old: one interval
    stale = [
        f["properties"]["core_details"]
        for f in feed_of(storage, T0_UNIX + 30.0 + 76.0)["features"]
        if f["properties"]["core_details"]["name"] == "Point speed sensor speed-2"
    ]
    assert stale[0]["device_status"] == "error"
    assert stale[0]["status_messages"] == ["no reading for 76 s"]
