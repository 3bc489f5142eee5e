"""A gateway that serves several sites (the central one): storage, the writer, the API.

The processes over a router mesh are in tests/deploy/test_multisite.py; here the parts.
"""

from __future__ import annotations

import sqlite3
from pathlib import Path

import httpx
import pytest
import yaml
from sqlalchemy import create_engine, insert

from tests.gateway.helpers import (
    ADMIN_KEY,
    SITE,
    car_batches,
    devices_state,
    gateway_settings,
    live_server,
    open_storage,
    sample_alert,
)
from tests.gateway.test_calibration import calibration
from wz_gateway import wzdx
from wz_gateway.metrics import GatewayMetrics
from wz_gateway.node import Writer
from wz_gateway.sites import Sites, load_sites
from wz_gateway.storage import Storage
from wz_gateway.store_types import AlertQuery, PointQuery
from wz_gateway.tables import MIGRATIONS, SCHEMA_VERSION, alerts, schema_version
from wz_gateway.track_ends import SiteFinishers
from wz_gateway.track_lives import TrackLifeStore
from wz_shared.messages import Alert, CalibrationState, TrackBatch
from wz_shared.site import SiteFileError

NOW = 1_750_000_000.0
#: A second trailer, 40 km away (another origin: its tracks land elsewhere on the map).
OTHER = SITE.model_copy(
    update={
        "site_id": "i80-york",
        "name": "I-80 near York",
        "origin": SITE.origin.model_copy(update={"latitude_deg": SITE.origin.latitude_deg + 0.36}),
    }
)
BOTH = Sites([SITE, OTHER])


def of_site(message: TrackBatch | Alert, site_id: str) -> TrackBatch | Alert:
    return message.model_copy(update={"site": site_id})


def test_sites_from_files_and_folders(tmp_path: Path) -> None:
    source = yaml.safe_load(
        (Path(__file__).parents[2] / "deploy/sites/us75-lincoln.yaml").read_text()
    )
    folder = tmp_path / "sites"
    folder.mkdir()
    for site_id in ("b-site", "a-site"):
        (folder / f"{site_id}.yaml").write_text(yaml.safe_dump({**source, "site_id": site_id}))
    sites = load_sites([folder])
    assert sites.ids == ["a-site", "b-site"] and sites.default.site_id == "a-site"
    assert sites.key("tracks") == "wz/*/tracks"
    assert Sites([SITE]).key("alerts/*") == f"wz/{SITE.site_id}/alerts/*"
    with pytest.raises(SiteFileError, match="a-site is given twice"):
        load_sites([folder, folder / "a-site.yaml"])
    (tmp_path / "empty").mkdir()
    with pytest.raises(SiteFileError, match="no site file"):
        load_sites([folder / "a-site.yaml", tmp_path / "empty"])
    with pytest.raises(SiteFileError, match="cannot read"):
        load_sites([tmp_path / "missing.yaml"])
    settings = gateway_settings(tmp_path, site_files=f"{folder / 'b-site.yaml'},{folder}")
    with pytest.raises(SiteFileError, match="b-site is given twice"):
        load_sites(settings.site_entries)


def test_two_sites_stored_apart_same_alert_ids_and_foreign_sites_refused(
    tmp_path: Path,
) -> None:
    """Both trailers' alert services name their first episode alike: each is stored once per
    site; a repeat is a duplicate; a site not served, or a message under another site's key,
    is refused and reported."""
    settings = gateway_settings(tmp_path)
    storage = open_storage(settings)
    reports: list[tuple[str, str]] = []
    finishers = SiteFinishers.of(storage, BOTH, settings, GatewayMetrics(), clock=lambda: NOW)
    writer = Writer(
        storage,
        BOTH,
        settings,
        GatewayMetrics(),
        finisher=finishers,
        report=lambda key, reason, _: reports.append((key, reason)),
        clock=lambda: NOW,
    )
    try:
        for site in (SITE, OTHER):
            for message in car_batches(1, 600.0, 25.0, 0.0, 30):
                writer.offer(f"wz/{site.site_id}/tracks", of_site(message, site.site_id))
            for alert_id in ("ep-1-0", "ep-1-1"):
                writer.offer(
                    f"wz/{site.site_id}/alerts/speeding",
                    of_site(sample_alert(alert_id, 1.0), site.site_id),
                )
        writer.offer("wz/us75-lincoln/alerts/speeding", sample_alert("ep-1-0", 1.0))  # again
        writer.offer("wz/elsewhere/alerts/speeding", of_site(sample_alert("x", 1.0), "elsewhere"))
        writer.offer("wz/i80-york/alerts/speeding", sample_alert("spoof", 1.0))  # site: lincoln
        assert reports == [
            ("wz/elsewhere/alerts/speeding", "wrong_site"),
            ("wz/i80-york/alerts/speeding", "wrong_site"),
        ]
        writer.stop.set()
        writer.run()
        assert writer.written == 2 * 32 + 1
        for site in (SITE, OTHER):
            page = storage.alerts(AlertQuery(site=site.site_id))
            assert sorted(a.alert_id for a in page.items) == ["ep-1-0", "ep-1-1"]
            points = storage.points(PointQuery(site=site.site_id, limit=100)).items
            assert len(points) == 30
        lincoln = storage.points(PointQuery(site=SITE.site_id, limit=1)).items[0]
        york = storage.points(PointQuery(site=OTHER.site_id, limit=1)).items[0]
        assert york.latitude_deg - lincoln.latitude_deg == pytest.approx(0.36, abs=1e-3)
        assert len(storage.alerts(AlertQuery(site=None)).items) == 4
        assert TrackLifeStore(storage.engine).unfinished(
            OTHER.site_id
        )  # each site's lives recorded
    finally:
        storage.close()


def test_api_serves_each_site_with_a_site_parameter(tmp_path: Path) -> None:
    settings = gateway_settings(tmp_path)
    storage = open_storage(settings)
    try:
        for site, speed, state in (
            (SITE, 25.0, CalibrationState.BUMPED),
            (OTHER, 31.0, CalibrationState.CALIBRATED),
        ):
            messages = [of_site(m, site.site_id) for m in car_batches(4, 600.0, speed, 0.0, 5)]
            messages.append(
                calibration("camera-mast", 0.4, state, 0.1).model_copy(
                    update={"site": site.site_id}
                )
            )
            messages.append(of_site(sample_alert("ep-7-0", 0.2), site.site_id))
            messages.append(
                devices_state(0.3, beacon_on=True, sign_text="SLOW DOWN", cause=None).model_copy(
                    update={"site": site.site_id}
                )
            )
            storage.ingest(messages, geo=site.geo_frame, received_at=NOW)
        with (
            live_server(settings, storage, site=BOTH, clock=lambda: NOW + 1.0) as url,
            httpx.Client(base_url=url, headers={"X-API-Key": ADMIN_KEY}) as http,
        ):
            assert http.get("/v1/sites").json() == [
                {"site_id": SITE.site_id, "name": SITE.name, "default": True},
                {"site_id": OTHER.site_id, "name": OTHER.name, "default": False},
            ]
            assert http.get("/v1/site").json()["site_id"] == SITE.site_id
            assert http.get("/v1/site", params={"site": OTHER.site_id}).json()["name"] == OTHER.name
            unknown = http.get("/v1/trajectories", params={"site": "nowhere"})
            assert unknown.status_code == 404 and "serves us75-lincoln, i80-york" in unknown.text
            speeds = {
                site: {
                    p["speed_mps"]
                    for p in http.get("/v1/trajectories", params={"site": site}).json()["points"]
                }
                for site in BOTH.ids
            }
            assert speeds == {SITE.site_id: {25.0}, OTHER.site_id: {31.0}}
            live = http.get("/v1/tracks/live", params={"site": OTHER.site_id}).json()
            assert live["site"] == OTHER.site_id and live["tracks"][0]["speed_mps"] == 31.0
            track = http.get("/v1/tracks/4", params={"site": OTHER.site_id}).json()
            assert track["site"] == OTHER.site_id and track["count"] == 5
            assert http.get("/v1/alerts").json()["count"] == 1
            every = http.get("/v1/alerts", params={"site": "*"}).json()
            assert every["site"] == "*" and sorted(a["site"] for a in every["alerts"]) == sorted(
                BOTH.ids
            )
            feed = http.get("/v1/wzdx/device-feed").json()
            sources = {s["data_source_id"] for s in feed["feed_info"]["data_sources"]}
            assert len(sources) == 2
            assert {
                f["properties"]["core_details"]["data_source_id"] for f in feed["features"]
            } == sources
            one = http.get("/v1/wzdx/device-feed", params={"site": OTHER.site_id}).json()
            assert len(one["features"]) * 2 == len(feed["features"])
            # Each site's sensors' calibration, and its camera's status in the feed.
            for site_id, state in ((SITE.site_id, "bumped"), (OTHER.site_id, "calibrated")):
                sensors = http.get("/v1/calibration", params={"site": site_id}).json()["sensors"]
                camera = next(s for s in sensors if s["sensor_id"] == "camera-mast")
                assert camera["calibration"]["state"] == state
                assert camera["calibration"]["site"] == site_id
            cameras = {
                f["properties"]["core_details"]["data_source_id"]: f["properties"]["core_details"]
                for f in feed["features"]
                if f["properties"]["core_details"]["device_type"] == "camera"
            }
            moved = {
                source
                for source, core in cameras.items()
                if any("moved" in m for m in core.get("status_messages", []))
            }
            assert len(cameras) == 2 and moved == {wzdx.data_source_id(SITE)}
    finally:
        storage.close()


def test_migration_4_keeps_the_alerts_and_makes_ids_unique_per_site(tmp_path: Path) -> None:
    """A database at schema 3 (alert_id unique overall) with alerts in it: they stay, and the
    same id from another site can be stored afterwards."""
    path = tmp_path / "gateway.sqlite3"
    engine = create_engine(f"sqlite:///{path}")
    with engine.begin() as connection:
        schema_version.create(connection)
        for migration in MIGRATIONS[:3]:
            migration.apply(connection)
            connection.execute(
                insert(schema_version).values(
                    version=migration.version, description=migration.description, applied_at=NOW
                )
            )
        for k in range(3):
            alert = sample_alert(f"ep-{k}", float(k))
            connection.execute(
                insert(alerts).values(
                    alert_id=alert.alert_id,
                    site=alert.site,
                    source_id=alert.source_id,
                    episode_id=alert.episode_id,
                    phase=alert.phase,
                    alert_type="speeding",
                    severity="warning",
                    stamp=alert.stamp,
                    onset_stamp=None,
                    track_id=1,
                    station_m=700.0,
                    offset_m=-1.8,
                    speed_mps=29.0,
                    measured_value=29.0,
                    threshold_value=26.8,
                    value_unit="m/s",
                    description="d",
                    evidence={},
                    track=None,
                    received_at=NOW,
                )
            )
    engine.dispose()
    storage = Storage.open(f"sqlite:///{path}")
    try:
        assert storage.current_schema_version() == SCHEMA_VERSION
        assert [a.alert_id for a in storage.alerts(AlertQuery(site=SITE.site_id)).items] == [
            "ep-2",
            "ep-1",
            "ep-0",
        ]
        result = storage.ingest(
            [of_site(sample_alert("ep-1", 5.0), OTHER.site_id), sample_alert("ep-1", 5.0)],
            geo=BOTH.default.geo_frame,
            received_at=NOW,
        )
        assert (result.alerts, result.duplicate_alerts) == (1, 1)
    finally:
        storage.close()
    with sqlite3.connect(path) as raw:
        names = {
            row[0]
            for row in raw.execute(
                "SELECT name FROM sqlite_master WHERE tbl_name = 'alerts' AND type = 'index'"
            )
        }
        assert {
            "ux_alerts_site_alert",
            "ix_alerts_site_stamp",
            "ix_alerts_episode",
            "ix_alerts_received_at",
        } <= names
        assert raw.execute("SELECT count(*) FROM alerts").fetchone() == (4,)
