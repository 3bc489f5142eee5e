"""The sensors' self-calibration at the gateway: stored (the newest per sensor, each change of
state in a real SQLite file, kept across a reopen and an upgrade from schema 6, purged with
the retention), served at ``GET /v1/calibration`` over real HTTP (keys, problem+json), and
judged in the WZDx DeviceFeed (a knocked camera, a knocked LiDAR, a sensor that does not
learn), the feed valid against the vendored schema."""

from __future__ import annotations

import sqlite3
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from sqlalchemy import inspect

from tests.gateway.helpers import (
    READ_KEY,
    SITE,
    car_batches,
    gateway_settings,
    live_server,
    open_storage,
    service_status,
)
from tests.gateway.test_wzdx import T0_UNIX, assert_valid, features_by_type, store
from wz_gateway import views
from wz_gateway.settings import GatewaySettings
from wz_gateway.storage import Storage
from wz_gateway.tables import SCHEMA_VERSION
from wz_gateway.wzdx import CalibrationRules, calibration_health
from wz_shared.keys import Keys
from wz_shared.messages import CalibrationState, Message, PoseCorrection, SensorCalibration

KEYS = Keys(SITE.site_id)
LIDAR, CAMERA, RADAR = "lidar-mast", "camera-mast", "radar-mast"
_KINDS = {LIDAR: "lidar", CAMERA: "camera", RADAR: "radar"}


def calibration(
    sensor_id: str,
    stamp: float,
    state: CalibrationState,
    since_s: float,
    *,
    yaw_deg: float = 0.0,
    pitch_deg: float = 0.0,
    clock_offset_s: float = 0.0,
    detail: str = "",
    samples: int = 0,
) -> SensorCalibration:
    return SensorCalibration(
        site=SITE.site_id,
        source_id=sensor_id,
        stamp=stamp,
        sensor_kind=_KINDS[sensor_id],  # type: ignore[arg-type]
        state=state,
        state_since_s=since_s,
        correction=PoseCorrection(
            yaw_deg=yaw_deg, pitch_deg=pitch_deg, yaw_std_deg=0.05, pitch_std_deg=0.04
        ),
        clock_offset_s=clock_offset_s,
        clock_offset_std_s=0.004 if clock_offset_s else None,
        samples=samples,
        detail=detail,
    )


P, L, C, B = (
    CalibrationState.PRIOR,
    CalibrationState.LEARNING,
    CalibrationState.CALIBRATED,
    CalibrationState.BUMPED,
)

#: A camera's story, one message every 5 s of its time: nothing learned, learning, calibrated,
#: knocked at 30 s, knocked again at 40 s (the new vote stands off again), learned at 50 s.
CAMERA_STORY = [
    calibration(CAMERA, 0.0, P, 0.0),
    calibration(CAMERA, 5.0, L, 3.0, yaw_deg=0.4, samples=10),
    calibration(CAMERA, 10.0, L, 3.0, yaw_deg=0.7, samples=30),
    calibration(CAMERA, 15.0, C, 14.0, yaw_deg=0.81, clock_offset_s=0.085, samples=80),
    calibration(CAMERA, 20.0, C, 14.0, yaw_deg=0.8, clock_offset_s=0.085, samples=120),
    calibration(CAMERA, 30.0, B, 29.0, yaw_deg=0.8, detail="yaw moved 2.1 deg within 4 s"),
    calibration(CAMERA, 35.0, B, 29.0, yaw_deg=1.9, detail="yaw moved 2.1 deg within 4 s"),
    calibration(CAMERA, 40.0, B, 39.0, yaw_deg=2.6, detail="the new vote stands 0.7 deg off"),
    calibration(CAMERA, 50.0, C, 48.0, yaw_deg=2.9, clock_offset_s=0.085, samples=60),
]


@pytest.fixture
def settings(tmp_path: Path) -> GatewaySettings:
    return gateway_settings(tmp_path)


@pytest.fixture
def storage(settings: GatewaySettings) -> Iterator[Storage]:
    store = open_storage(settings)
    yield store
    store.close()


def ingest_one_by_one(storage: Storage, messages: list[Message], t0: float = T0_UNIX) -> None:
    """Each message in its own transaction, received at ``t0`` + its stamp."""
    for message in messages:
        storage.ingest([message], geo=SITE.geo_frame, received_at=t0 + message.stamp)


def test_the_newest_message_is_kept_and_each_change_of_state_once(storage: Storage) -> None:
    ingest_one_by_one(storage, list(CAMERA_STORY))
    latest = storage.latest_calibrations(SITE.site_id)
    assert set(latest) == {CAMERA}
    assert SensorCalibration.model_validate_json(latest[CAMERA].body) == CAMERA_STORY[-1]
    assert latest[CAMERA].received_at == T0_UNIX + 50.0
    changes = storage.calibration_changes(SITE.site_id, per_sensor=100)[CAMERA]
    # Newest first; the repeated states (5 -> 10, 15 -> 20, 30 -> 35) are not changes, a
    # second knock while knocked (entered again at 39 s) is.
    assert [(c.stamp, c.state, c.previous_state) for c in changes] == [
        (50.0, C, B),
        (40.0, B, B),
        (30.0, B, C),
        (15.0, C, L),
        (5.0, L, P),
        (0.0, P, None),
    ]
    assert changes[1].detail == "the new vote stands 0.7 deg off"
    assert changes[2].state_since_s == 29.0 and changes[2].received_at == T0_UNIX + 30.0
    assert storage.count("calibration_changes") == 6
    assert [c.stamp for c in storage.calibration_changes(SITE.site_id, per_sensor=2)[CAMERA]] == [
        50.0,
        40.0,
    ]
    assert storage.calibration_changes(SITE.site_id, per_sensor=0) == {}


def test_one_transaction_of_several_sensors_and_repeats(storage: Storage) -> None:
    """A group stored at once (the writer's) counts each change against the one before it in
    the same group; sensors do not mix; another site's sensors are not this site's."""
    group: list[Message] = [
        calibration(LIDAR, 1.0, L, 0.5),
        calibration(CAMERA, 1.0, P, 0.0),
        calibration(LIDAR, 2.0, L, 0.5),
        calibration(LIDAR, 3.0, C, 2.5, yaw_deg=-0.3),
        calibration(RADAR, 3.0, L, 1.0, clock_offset_s=0.02),
    ]
    result = storage.ingest(group, geo=SITE.geo_frame, received_at=T0_UNIX)
    assert (result.calibrations, result.calibration_changes) == (5, 4)
    changes = storage.calibration_changes(SITE.site_id, per_sensor=10)
    assert {sensor: [c.state for c in found] for sensor, found in changes.items()} == {
        LIDAR: [C, L],
        CAMERA: [P],
        RADAR: [L],
    }
    assert storage.calibration_changes(SITE.site_id, per_sensor=10, sensor_id=RADAR).keys() == {
        RADAR
    }
    assert storage.latest_calibrations("another-site") == {}
    assert storage.calibration_changes("another-site", per_sensor=10) == {}


def test_a_database_of_schema_6_is_upgraded_and_the_history_kept_across_a_reopen(
    tmp_path: Path,
) -> None:
    path = tmp_path / "data" / "gateway.sqlite3"
    first = open_storage(gateway_settings(tmp_path))
    first.close()
    with sqlite3.connect(path) as raw:  # as a gateway before migration 7 left it
        raw.execute("DROP TABLE calibration_changes")
        raw.execute("DELETE FROM schema_version WHERE version = 7")
    storage = Storage.open(f"sqlite:///{path}")
    try:
        assert storage.current_schema_version() == SCHEMA_VERSION
        assert "calibration_changes" in inspect(storage.engine).get_table_names()
        ingest_one_by_one(storage, CAMERA_STORY[:6])
    finally:
        storage.close()
    reopened = Storage.open(f"sqlite:///{path}")
    try:
        assert reopened.migrate() == []
        ingest_one_by_one(reopened, CAMERA_STORY[6:])  # the newest stored one is compared
        states = [
            c.state for c in reopened.calibration_changes(SITE.site_id, per_sensor=10)[CAMERA]
        ]
        assert states == [C, B, B, C, L, P]
    finally:
        reopened.close()


def test_retention_deletes_old_changes_and_keeps_the_newest_message(storage: Storage) -> None:
    ingest_one_by_one(storage, CAMERA_STORY[:5], t0=T0_UNIX)
    ingest_one_by_one(storage, CAMERA_STORY[5:], t0=T0_UNIX + 40 * 86400.0)
    deleted = storage.purge(T0_UNIX + 45 * 86400.0, retention_days=30.0, alert_retention_days=365)
    assert deleted["calibration_changes"] == 3  # prior, learning, calibrated of 40 days ago
    assert [c.state for c in storage.calibration_changes(SITE.site_id, per_sensor=10)[CAMERA]] == [
        C,
        B,
        B,
    ]
    assert set(storage.latest_calibrations(SITE.site_id)) == {CAMERA}


# --- the API -------------------------------------------------------------------------------


def test_get_calibration_lists_every_sensor_of_the_site_with_its_changes(
    settings: GatewaySettings, storage: Storage
) -> None:
    ingest_one_by_one(storage, list(CAMERA_STORY))
    ingest_one_by_one(storage, [calibration(LIDAR, 55.0, C, 20.0, yaw_deg=-0.25, samples=900)])
    now = T0_UNIX + 60.0
    with live_server(settings, storage, clock=lambda: now) as url:
        reply = httpx.get(f"{url}/v1/calibration", headers={"X-API-Key": READ_KEY})
        assert reply.status_code == 200, reply.text
        body = reply.json()
        assert body["site"] == SITE.site_id
        sensors = {s["sensor_id"]: s for s in body["sensors"]}
        assert [s["sensor_id"] for s in body["sensors"]] == [LIDAR, CAMERA, RADAR]  # site order
        camera = sensors[CAMERA]
        assert camera["sensor_kind"] == "camera" and camera["received_at"] == T0_UNIX + 50.0
        assert camera["age_s"] == pytest.approx(10.0) and camera["stale"] is False
        assert SensorCalibration.model_validate(camera["calibration"]) == CAMERA_STORY[-1]
        states = [c["state"] for c in camera["changes"]]
        assert states == ["calibrated", "bumped", "bumped", "calibrated", "learning", "prior"]
        assert camera["changes"][0]["previous_state"] == "bumped"
        lidar = sensors[LIDAR]
        assert lidar["calibration"]["correction"]["yaw_deg"] == -0.25
        assert lidar["changes"] == [
            {
                "state": "calibrated",
                "previous_state": None,
                "stamp": 55.0,
                "state_since_s": 20.0,
                "detail": "",
                "received_at": T0_UNIX + 55.0,
            }
        ]
        # Never heard from: listed, without a message.
        assert sensors[RADAR] == {
            "sensor_id": RADAR,
            "sensor_kind": "radar",
            "calibration": None,
            "received_at": None,
            "age_s": None,
            "stale": False,
            "changes": [],
        }
        few = httpx.get(
            f"{url}/v1/calibration",
            params={"changes": 1, "site": SITE.site_id},
            headers={"Authorization": f"Bearer {READ_KEY}"},
        ).json()
        assert [len(s["changes"]) for s in few["sensors"]] == [1, 1, 0]


def test_a_calibration_not_heard_for_long_is_stale(
    settings: GatewaySettings, storage: Storage
) -> None:
    ingest_one_by_one(storage, [calibration(LIDAR, 5.0, C, 1.0)])
    now = T0_UNIX + 5.0 + settings.calibration_stale_after_s + 1.0
    with live_server(settings, storage, clock=lambda: now) as url:
        body = httpx.get(f"{url}/v1/calibration", headers={"X-API-Key": READ_KEY}).json()
    lidar = next(s for s in body["sensors"] if s["sensor_id"] == LIDAR)
    assert lidar["stale"] is True and lidar["age_s"] == pytest.approx(31.0)


def problem(reply: httpx.Response) -> dict[str, Any]:
    assert reply.headers["content-type"] == "application/problem+json", reply.text
    body: dict[str, Any] = reply.json()
    assert body["status"] == reply.status_code and body["detail"]
    return body


def test_get_calibration_refusals_are_problems(settings: GatewaySettings, storage: Storage) -> None:
    with live_server(settings, storage) as url:
        missing = httpx.get(f"{url}/v1/calibration")
        assert missing.status_code == 401 and "API key" in problem(missing)["detail"]
        wrong = httpx.get(f"{url}/v1/calibration", headers={"X-API-Key": "rk-not-a-key-at-all-0"})
        assert wrong.status_code == 401
        headers = {"X-API-Key": READ_KEY}
        other = httpx.get(f"{url}/v1/calibration", params={"site": "elsewhere"}, headers=headers)
        assert other.status_code == 404 and SITE.site_id in problem(other)["detail"]
        too_many = httpx.get(f"{url}/v1/calibration", params={"changes": 101}, headers=headers)
        assert too_many.status_code == 422
        assert [e["location"] for e in problem(too_many)["errors"]] == ["query.changes"]


# --- the WZDx device feed -------------------------------------------------------------------


def feed_of(storage: Storage, now: float, rules: CalibrationRules | None = None) -> dict[str, Any]:
    return views.device_feed_of(
        storage,
        SITE,
        now=now,
        publisher="Test DOT",
        stale_after_s=10.0,
        traffic_interval_s=300.0,
        calibration_rules=rules,
    )


def healthy_site(storage: Storage, stamp: float) -> None:
    """Tracks, the detectors' statuses with frames, and the alert service, all fresh at
    ``stamp`` (received at T0_UNIX + stamp): every device ok."""
    store(storage, car_batches(1, 900.0, 25.0, stamp - 1.0, 11), T0_UNIX + stamp)
    store(
        storage,
        [
            service_status("lidar-detector", stamp, {KEYS.raw_lidar(LIDAR): 10.0}),
            service_status("camera-detector", stamp, {KEYS.raw_camera(CAMERA): 15.0}),
            service_status("alert-service", stamp, {}),
        ],
        T0_UNIX + stamp,
    )


def core(feed: dict[str, Any], device_type: str) -> dict[str, Any]:
    details: dict[str, Any] = features_by_type(feed)[device_type]["properties"]["core_details"]
    return details


def test_a_knocked_camera_warns_on_its_device_and_a_learned_one_is_ok(storage: Storage) -> None:
    healthy_site(storage, 100.0)
    ingest_one_by_one(
        storage,
        [
            calibration(LIDAR, 100.0, C, 10.0),
            calibration(CAMERA, 100.0, B, 60.0, detail="yaw moved 2.1 deg within 4 s"),
        ],
    )
    feed = feed_of(storage, T0_UNIX + 101.0)
    assert_valid(feed)
    camera = core(feed, "camera")
    assert camera["device_status"] == "warning"
    assert camera["status_messages"] == [
        "camera camera-mast moved 40 s ago (yaw moved 2.1 deg within 4 s): its pose is being "
        "re-learned; its detections are down-weighted"
    ]
    assert core(feed, "traffic-sensor")["device_status"] == "ok"  # the LiDAR is calibrated
    assert "status_messages" not in core(feed, "traffic-sensor")
    # Learned again: ok, no message.
    healthy_site(storage, 110.0)
    ingest_one_by_one(storage, [calibration(CAMERA, 110.0, C, 108.0)])
    feed = feed_of(storage, T0_UNIX + 111.0)
    assert_valid(feed)
    assert core(feed, "camera")["device_status"] == "ok"
    assert "status_messages" not in core(feed, "camera")


def test_a_knocked_lidar_or_radar_warns_on_the_traffic_sensor(storage: Storage) -> None:
    healthy_site(storage, 100.0)
    ingest_one_by_one(
        storage,
        [
            calibration(LIDAR, 100.0, B, 98.0),
            calibration(RADAR, 100.0, B, 99.0, detail="bearings 0.7 deg off twice"),
            calibration(CAMERA, 100.0, C, 50.0),
        ],
    )
    feed = feed_of(storage, T0_UNIX + 101.0)
    assert_valid(feed)
    traffic = core(feed, "traffic-sensor")
    assert traffic["device_status"] == "warning"
    assert traffic["status_messages"] == [
        "lidar lidar-mast moved 2 s ago: its pose is being re-learned; its detections are "
        "down-weighted",
        "radar radar-mast moved 1 s ago (bearings 0.7 deg off twice): its pose is being "
        "re-learned; its detections are down-weighted",
    ]
    assert core(feed, "camera")["device_status"] == "ok"
    # A knock does not hide an error: the camera's frames stopped, it is in error, and says
    # both.
    ingest_one_by_one(storage, [calibration(CAMERA, 101.0, B, 100.5)])
    feed = feed_of(storage, T0_UNIX + 130.0)
    assert_valid(feed)
    camera = core(feed, "camera")
    assert camera["device_status"] == "error"
    assert any("moved" in m for m in camera["status_messages"])
    assert any("for 30 s" in m for m in camera["status_messages"])


def test_a_sensor_that_does_not_learn_for_long_warns(storage: Storage) -> None:
    rules = CalibrationRules(stale_after_s=30.0, learning_warning_s=600.0)
    healthy_site(storage, 1000.0)
    ingest_one_by_one(
        storage,
        [
            calibration(LIDAR, 1000.0, L, 300.0, detail="14 vehicles on the lanes of 40"),
            calibration(CAMERA, 1000.0, L, 500.0),  # learning for 500 s: not yet a warning
            calibration(RADAR, 1000.0, P, 0.0),
        ],
    )
    feed = feed_of(storage, T0_UNIX + 1001.0, rules)
    assert_valid(feed)
    assert core(feed, "camera")["device_status"] == "ok"
    traffic = core(feed, "traffic-sensor")
    assert traffic["device_status"] == "warning"
    assert traffic["status_messages"] == [
        "lidar lidar-mast still learning its pose after 12 min (14 vehicles on the lanes of "
        "40): its detections are down-weighted until it is calibrated",
        "radar radar-mast has learned nothing of its pose in 17 min: the site file's pose is used",
    ]


def test_an_old_calibration_is_not_judged() -> None:
    rules = CalibrationRules(stale_after_s=30.0, learning_warning_s=600.0)
    knocked = calibration(CAMERA, 100.0, B, 90.0)
    assert calibration_health(CAMERA, (knocked, T0_UNIX), T0_UNIX + 30.0, rules) is not None
    assert calibration_health(CAMERA, (knocked, T0_UNIX), T0_UNIX + 31.0, rules) is None
    assert calibration_health(CAMERA, None, T0_UNIX, rules) is None
    learning = calibration(CAMERA, 700.0, L, 100.0)
    assert calibration_health(CAMERA, (learning, T0_UNIX), T0_UNIX, rules) is None  # 600 s
    later = calibration(CAMERA, 700.5, L, 100.0)
    health = calibration_health(CAMERA, (later, T0_UNIX), T0_UNIX, rules)
    assert health is not None and health.status == "warning" and health.updated_at == T0_UNIX
