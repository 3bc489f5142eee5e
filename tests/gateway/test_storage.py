"""The data layer on a real SQLite file: migrations from empty, everything read back after the
file is closed and reopened, keyset pages that never skip or repeat, filters, duplicates,
retention, hashed keys; and the schema and upserts compile for PostgreSQL."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest
from sqlalchemy import inspect
from sqlalchemy.dialects import postgresql
from sqlalchemy.schema import CreateIndex, CreateTable

from tests.gateway.helpers import (
    SITE,
    batch,
    car_batches,
    devices_state,
    make_track,
    sample_alert,
    service_status,
)
from wz_gateway import auth
from wz_gateway.key_store import KeyStore
from wz_gateway.storage import Storage, StorageError
from wz_gateway.store_types import AlertQuery, CursorError, PointQuery, decode_cursor, encode_cursor
from wz_gateway.tables import MIGRATIONS, SCHEMA_VERSION, metadata
from wz_shared.messages import AlertSeverity, AlertType, DetectionBatch, RoadsideDeviceState

NOW = 1_750_000_000.0
DAY_S = 86400.0


def url_of(path: Path) -> str:
    return f"sqlite:///{path}"


def fill(storage: Storage, received_at: float = NOW) -> None:
    """Two cars for 5 s (50 batches, two points each at the same stamps), three alerts."""
    left = car_batches(1, 800.0, 30.0, 0.0, 50)
    right = car_batches(2, 820.0, 20.0, 0.0, 50, offset_m=1.83)
    batches = [
        batch(a.stamp, [*a.tracks, *b.tracks], a.cycle_index)
        for a, b in zip(left, right, strict=True)
    ]
    storage.ingest(batches, geo=SITE.geo_frame, received_at=received_at)
    alerts = [
        sample_alert("a1", 1.0, track=make_track(1, 830.0, 30.0)),
        sample_alert(
            "a2",
            2.0,
            alert_type=AlertType.HARD_BRAKING,
            severity=AlertSeverity.CRITICAL,
            track_id=2,
        ),
        sample_alert("a3", 3.0, phase="clear"),
    ]
    storage.ingest(alerts, geo=SITE.geo_frame, received_at=received_at)


def all_points(storage: Storage, **filters: object) -> list[tuple[int, float]]:
    page = storage.points(PointQuery(site=SITE.site_id, limit=100_000, **filters))  # type: ignore[arg-type]
    return [(p.track_id, p.stamp) for p in page.items]


def test_migration_from_empty_then_reopen_keeps_everything(tmp_path: Path) -> None:
    path = tmp_path / "sub" / "gateway.sqlite3"  # the folder does not exist yet
    storage = Storage.open(url_of(path))
    assert storage.current_schema_version() == SCHEMA_VERSION
    names = set(inspect(storage.engine).get_table_names())
    assert names == {t.name for t in metadata.sorted_tables}
    fill(storage)
    storage.ingest(
        [
            devices_state(4.0, beacon_on=True, sign_text="SLOW DOWN", cause=AlertType.SPEEDING),
            service_status("alert-service", 4.0, {"k": 1.0}),
        ],
        geo=SITE.geo_frame,
        received_at=NOW,
    )
    before_points = storage.points(PointQuery(site=SITE.site_id, limit=1000)).items
    before_alerts = storage.alerts(AlertQuery(site=SITE.site_id)).items
    storage.close()

    with sqlite3.connect(path) as raw:
        assert raw.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        assert raw.execute("SELECT version FROM schema_version ORDER BY version").fetchall() == [
            (m.version,) for m in MIGRATIONS
        ]

    reopened = Storage.open(url_of(path))
    try:
        assert reopened.migrate() == []  # nothing left to apply
        assert reopened.points(PointQuery(site=SITE.site_id, limit=1000)).items == before_points
        assert len(before_points) == 100
        assert reopened.alerts(AlertQuery(site=SITE.site_id)).items == before_alerts
        first = before_alerts[-1]  # newest first: a1 is last
        assert first.alert_id == "a1" and first == sample_alert(
            "a1", 1.0, track=make_track(1, 830.0, 30.0)
        )
        devices = reopened.latest(SITE.site_id, "devices")
        assert devices is not None
        assert RoadsideDeviceState.model_validate_json(devices.body).sign_text == "SLOW DOWN"
        assert set(reopened.latest_statuses(SITE.site_id)) == {"alert-service"}
        with reopened.engine.connect() as connection:
            assert connection.exec_driver_sql("PRAGMA foreign_keys").scalar() == 1
    finally:
        reopened.close()


def test_a_newer_database_is_refused_untouched(tmp_path: Path) -> None:
    path = tmp_path / "gateway.sqlite3"
    storage = Storage.open(url_of(path))
    fill(storage)
    storage.close()
    with sqlite3.connect(path) as raw:
        raw.execute(
            "INSERT INTO schema_version VALUES (?, 'from the future', 0)", (SCHEMA_VERSION + 1,)
        )
    with pytest.raises(StorageError, match=f"schema version {SCHEMA_VERSION + 1}.*nothing was"):
        Storage.open(url_of(path))
    with sqlite3.connect(path) as raw:
        assert raw.execute("SELECT count(*) FROM track_points").fetchone() == (100,)


@pytest.mark.parametrize(
    ("url", "message"),
    [
        ("sqlite://", "in-memory"),
        ("sqlite:///:memory:", "in-memory"),
        ("mysql://u:p@host/db", "not supported"),
        ("not a url", "not a valid"),
    ],
)
def test_unusable_urls_are_refused_with_a_reason(url: str, message: str) -> None:
    with pytest.raises(StorageError, match=message):
        Storage.open(url)


def test_pages_never_skip_or_repeat_and_survive_new_rows(tmp_path: Path) -> None:
    storage = Storage.open(url_of(tmp_path / "g.sqlite3"))
    fill(storage)
    everything = all_points(storage)
    assert len(everything) == 100 and everything == sorted(everything, key=lambda p: p[1])
    seen: list[tuple[int, float]] = []
    cursor = None
    pages = 0
    while True:
        page = storage.points(PointQuery(site=SITE.site_id, limit=7, cursor=cursor))
        seen += [(p.track_id, p.stamp) for p in page.items]
        pages += 1
        if pages == 3:  # rows arriving mid-walk come after what was read, at the end
            storage.ingest(
                [batch(9.0, [make_track(5, 900.0, 10.0)], 90)], geo=SITE.geo_frame, received_at=NOW
            )
        if page.next_cursor is None:
            break
        cursor = page.next_cursor
    assert seen == [*everything, (5, 9.0)]
    assert pages == 15  # 101 points, 7 a page
    storage.close()


def test_point_filters(tmp_path: Path) -> None:
    storage = Storage.open(url_of(tmp_path / "g.sqlite3"))
    fill(storage)
    assert {t for t, _ in all_points(storage, track_id=2)} == {2}
    assert all(1.0 <= s <= 2.0 for _, s in all_points(storage, start_stamp=1.0, end_stamp=2.0))
    assert len(all_points(storage, start_stamp=1.0, end_stamp=2.0)) == 2 * 11
    assert {t for t, _ in all_points(storage, lane_index=1)} == {2}
    assert {t for t, _ in all_points(storage, min_speed_mps=25.0)} == {1}
    assert {t for t, _ in all_points(storage, max_speed_mps=25.0)} == {2}
    # Car 1 covers 800-947 m at 30 m/s: 800-850 m is its first 17 points (to 1.6 s).
    assert len(all_points(storage, track_id=1, station_min_m=800.0, station_max_m=850.0)) == 17
    # A box around the first 50 m of car 1's lane (x = 1.83 m) only.
    lat0, lon0, _ = SITE.geo_frame.to_wgs84(1.0, 799.0)
    lat1, lon1, _ = SITE.geo_frame.to_wgs84(2.5, 850.0)
    box = (float(lon0), float(lat0), float(lon1), float(lat1))
    assert all_points(storage, bbox_deg=box) == all_points(storage, track_id=1, station_max_m=850.0)
    assert all_points(storage, smoothed=True) == []
    assert all_points(storage, smoothed=False) == all_points(storage)
    storage.close()


def test_alerts_filters_order_duplicates(tmp_path: Path) -> None:
    storage = Storage.open(url_of(tmp_path / "g.sqlite3"))
    fill(storage)
    result = storage.ingest([sample_alert("a1", 1.0)], geo=SITE.geo_frame, received_at=NOW)
    assert (result.alerts, result.duplicate_alerts) == (0, 1)
    site = SITE.site_id

    def ids(**filters: object) -> list[str]:
        page = storage.alerts(AlertQuery(site=site, **filters))  # type: ignore[arg-type]
        return [a.alert_id for a in page.items]

    assert ids() == ["a3", "a2", "a1"]
    assert ids(newest_first=False) == ["a1", "a2", "a3"]
    assert ids(alert_types=("hard_braking",)) == ["a2"]
    assert ids(severities=("warning",), phases=("start",)) == ["a1"]
    assert ids(start_stamp=1.5, end_stamp=3.0) == ["a3", "a2"]
    assert ids(track_id=2) == ["a2"] and ids(episode_id="ep-a3") == ["a3"]
    first = storage.alerts(AlertQuery(site=site, limit=2))
    assert [a.alert_id for a in first.items] == ["a3", "a2"] and first.next_cursor
    rest = storage.alerts(AlertQuery(site=site, limit=2, cursor=first.next_cursor))
    assert [a.alert_id for a in rest.items] == ["a1"] and rest.next_cursor is None
    assert ids(alert_types=("queue",)) == []
    assert storage.alerts(AlertQuery(site="elsewhere")).items == []
    storage.close()


def test_ingest_refuses_unknown_messages_before_writing(tmp_path: Path) -> None:
    storage = Storage.open(url_of(tmp_path / "g.sqlite3"))
    stray = DetectionBatch(
        site=SITE.site_id, source_id="lidar", stamp=0.0, frame_index=0, detections=[]
    )
    with pytest.raises(TypeError, match="DetectionBatch"):
        storage.ingest(
            [batch(0.0, [make_track(1, 900.0, 10.0)]), stray], geo=SITE.geo_frame, received_at=NOW
        )
    assert storage.count("track_points") == 0 and storage.latest(SITE.site_id, "tracks") is None
    storage.close()


def test_retention_deletes_only_what_is_older(tmp_path: Path) -> None:
    storage = Storage.open(url_of(tmp_path / "g.sqlite3"))
    fill(storage, received_at=NOW - 40 * DAY_S)  # 40 days old
    storage.ingest(
        [batch(10.0, [make_track(9, 900.0, 10.0)], 100), sample_alert("new", 10.0)],
        geo=SITE.geo_frame,
        received_at=NOW,
    )
    deleted = storage.purge(NOW, retention_days=30.0, alert_retention_days=365.0)
    assert deleted["track_points"] == 100 and deleted["alerts"] == 0
    assert all_points(storage) == [(9, 10.0)]
    deleted = storage.purge(NOW + 400 * DAY_S, retention_days=30.0, alert_retention_days=365.0)
    assert deleted["alerts"] == 4 and storage.count("alerts") == 0
    storage.close()


def test_keys_are_stored_hashed_found_and_revoked(tmp_path: Path) -> None:
    path = tmp_path / "g.sqlite3"
    storage = Storage.open(url_of(path))
    keys = KeyStore(storage.engine)
    secret = auth.new_secret()
    info = keys.add("read", secret, name="dashboard", origin="api", now=NOW)
    found = keys.find(secret)
    assert found == info and found.scope == "read"
    assert keys.find(secret + "x") is None
    assert keys.find(auth.new_secret()) is None
    configured = [("admin", "configured-admin-secret-0123456789")]
    assert keys.sync_configured(configured, NOW) == (1, 0)  # type: ignore[arg-type]
    assert keys.sync_configured(configured, NOW) == (0, 0)  # type: ignore[arg-type]
    replaced = [("admin", "another-admin-secret-9876543210")]
    assert keys.sync_configured(replaced, NOW) == (1, 1)  # type: ignore[arg-type]
    assert keys.find(configured[0][1]) is None
    assert keys.revoke(info.key_id, NOW) and keys.find(secret) is None
    assert not keys.revoke(info.key_id, NOW)  # already revoked
    assert [k.name for k in keys.all()] == ["settings key 1"]
    assert len(keys.all(include_revoked=True)) == 3
    storage.close()
    raw = b"".join(p.read_bytes() for p in tmp_path.glob("g.sqlite3*"))
    for plain in (secret, configured[0][1], replaced[0][1]):
        assert plain.encode() not in raw  # only hashes reach the disk


def test_cursors_round_trip_and_refuse_forgeries() -> None:
    assert decode_cursor(encode_cursor(12.5, 7)) == (12.5, 7)
    for bad in ("", "zzz", encode_cursor(1.0, 2)[:-2] + "!!", "WyJhIiwxXQ", "WzEuMCwtMV0"):
        with pytest.raises(CursorError, match="not a cursor"):
            decode_cursor(bad)


def test_schema_and_upserts_compile_for_postgresql(tmp_path: Path) -> None:
    dialect = postgresql.dialect()  # type: ignore[no-untyped-call]
    for table in metadata.sorted_tables:
        ddl = str(CreateTable(table).compile(dialect=dialect))
        assert "CREATE TABLE" in ddl
        for index in table.indexes:
            str(CreateIndex(index).compile(dialect=dialect))
    ddl = str(CreateTable(metadata.tables["track_points"]).compile(dialect=dialect))
    assert "id BIGSERIAL" in ddl and "DOUBLE PRECISION" in ddl
    storage = Storage.open(url_of(tmp_path / "g.sqlite3"))
    storage.dialect = "postgresql"  # build the PostgreSQL statements with the same code
    stmt = storage._insert(metadata.tables["latest"]).values(
        site="s", name="n", stamp=0.0, received_at=0.0, body="{}"
    )
    upsert = stmt.on_conflict_do_update(  # type: ignore[attr-defined]
        index_elements=["site", "name"],
        set_={"body": stmt.excluded.body},  # type: ignore[attr-defined]
    )
    assert "ON CONFLICT (site, name) DO UPDATE" in str(upsert.compile(dialect=dialect))
    storage.close()
