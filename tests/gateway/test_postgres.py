"""The same data layer on PostgreSQL: a throwaway cluster (initdb, pg_ctl) on a free loopback
port; the server comes from Debian's postgresql package (deploy/host/bootstrap.sh)."""

from __future__ import annotations

import glob
import os
import pwd
import shutil
import subprocess
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import free_port
from tests.gateway.helpers import (
    ADMIN_KEY,
    SITE,
    batch,
    car_batches,
    gateway_settings,
    live_server,
    make_track,
    mint_concurrently,
    open_storage,
    sample_alert,
)
from tests.gateway.test_calibration import CAMERA_STORY
from tests.gateway.tracking import car_tracks, filtered_car, merged_batches
from tests.gateway.webhook_receiver import Receiver, eventually
from wz_gateway import auth, webhooks
from wz_gateway.delivery import WebhookDeliverer
from wz_gateway.key_store import KeyStore
from wz_gateway.metrics import GatewayMetrics
from wz_gateway.storage import Storage
from wz_gateway.store_types import AlertQuery, PointQuery
from wz_gateway.tables import SCHEMA_VERSION
from wz_gateway.track_ends import TrackFinisher
from wz_gateway.track_lives import TrackLifeStore
from wz_gateway.webhook_store import WebhookStore
from wz_shared.messages import SensorCalibration
from wz_shared.motion import ProcessNoise, rts_smooth

NOW = 1_750_000_000.0


def _binaries() -> Path | None:
    found = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"))
    if found:
        return Path(found[-1]).parent
    initdb = shutil.which("initdb")
    return Path(initdb).parent if initdb else None


@pytest.fixture(scope="module")
def postgres_url() -> Iterator[str]:
    bin_dir = _binaries()
    assert bin_dir is not None, (
        "no PostgreSQL server here (deploy/host/bootstrap.sh installs postgresql)"
    )
    as_user: list[str] = []
    home = Path(tempfile.mkdtemp(prefix="wz-pg-"))
    if os.geteuid() == 0:  # initdb refuses root: run the cluster as the postgres user
        try:
            owner = pwd.getpwnam("postgres")
        except KeyError:
            pytest.fail(
                "running as root and there is no postgres user (the postgresql package makes it)"
            )
        os.chown(home, owner.pw_uid, owner.pw_gid)
        as_user = ["runuser", "-u", "postgres", "--"]
    data = home / "data"
    port = free_port()

    def run(*args: str) -> None:
        subprocess.run([*as_user, *args], check=True, capture_output=True, timeout=120)

    run(str(bin_dir / "initdb"), "-D", str(data), "--auth=trust", "-U", "wz", "-E", "UTF8")
    run(
        str(bin_dir / "pg_ctl"),
        "-D",
        str(data),
        "-l",
        str(home / "log"),
        "-w",
        "-o",
        f"-p {port} -k {home} -c listen_addresses=127.0.0.1 -c fsync=off",
        "start",
    )
    try:
        yield f"postgresql+psycopg://wz@127.0.0.1:{port}/postgres"
    finally:
        run(str(bin_dir / "pg_ctl"), "-D", str(data), "-m", "immediate", "stop")
        shutil.rmtree(home, ignore_errors=True)


def test_storage_round_trip_on_postgresql(postgres_url: str) -> None:
    storage = Storage.open(postgres_url)
    assert storage.dialect == "postgresql" and storage.current_schema_version() == SCHEMA_VERSION
    left = car_batches(1, 800.0, 30.0, 0.0, 20)
    right = car_batches(2, 820.0, 20.0, 0.0, 20, offset_m=1.83)
    batches = [
        batch(a.stamp, [*a.tracks, *b.tracks], a.cycle_index)
        for a, b in zip(left, right, strict=True)
    ]
    alert = sample_alert("pg-1", 1.0, track=make_track(1, 830.0, 30.0))
    result = storage.ingest(
        [*batches, alert, alert, *CAMERA_STORY], geo=SITE.geo_frame, received_at=NOW
    )
    assert (result.points, result.alerts, result.duplicate_alerts) == (40, 1, 1)
    assert (result.calibrations, result.calibration_changes) == (len(CAMERA_STORY), 6)
    secret = auth.new_secret()
    info = KeyStore(storage.engine).add("admin", secret, name="pg", origin="api", now=NOW)
    storage.close()

    reopened = Storage.open(postgres_url)  # nothing to migrate, everything still there
    try:
        assert reopened.migrate() == []
        seen, cursor = [], None
        while True:
            page = reopened.points(
                PointQuery(site=SITE.site_id, limit=7, cursor=cursor, min_speed_mps=0.0)
            )
            seen += [(p.track_id, p.stamp) for p in page.items]
            if page.next_cursor is None:
                break
            cursor = page.next_cursor
        assert len(seen) == 40 == len(set(seen))
        assert reopened.alerts(AlertQuery(site=SITE.site_id)).items == [alert]
        assert KeyStore(reopened.engine).find(secret) == info
        changes = reopened.calibration_changes(SITE.site_id, per_sensor=3)
        assert [c.stamp for c in changes["camera-mast"]] == [50.0, 40.0, 30.0]
        newest = reopened.latest_calibrations(SITE.site_id)["camera-mast"]
        assert SensorCalibration.model_validate_json(newest.body) == CAMERA_STORY[-1]
        live = reopened.latest(SITE.site_id, "tracks")
        assert live is not None and live.stamp == pytest.approx(1.9)
        deleted = reopened.purge(
            NOW + 31 * 86400.0, retention_days=30.0, alert_retention_days=365.0
        )
        assert deleted["track_points"] == 40 and deleted["alerts"] == 0
        assert deleted["calibration_changes"] == 6
    finally:
        reopened.close()


def test_webhook_outbox_on_postgresql(postgres_url: str, tmp_path: Path) -> None:
    """The outbox's SQL on PostgreSQL: enqueue with the alert (once), claim with its lease,
    delivery to a real receiver, the attempt recorded, expiry, unsubscribe."""
    storage = Storage.open(postgres_url)
    store = WebhookStore(storage.engine)
    try:
        with Receiver() as receiver:
            secret = webhooks.new_secret()
            receiver.secrets = [secret]
            store.create(
                subscription_id="wh_00000000000000aa",
                url=receiver.url,
                secret=secret,
                event_types=["alert.speeding"],
                min_severity="warning",
                phases=["start"],
                description="pg",
                now=time.time(),
            )
            wanted, ignored = (
                sample_alert("pg-wh-1", 5.0),
                sample_alert("pg-wh-2", 5.0, phase="clear"),
            )
            now = time.time()
            result = storage.ingest([wanted, ignored, wanted], geo=SITE.geo_frame, received_at=now)
            assert (result.alerts, result.webhook_events) == (2, 1)
            (claimed,) = store.claim(now, lease_until=now + 0.5, limit=8)
            assert store.claim(now, lease_until=now + 0.5, limit=8) == []
            assert claimed.event_id == webhooks.alert_event_id(wanted)
            settings = gateway_settings(
                tmp_path,
                webhook_allowed_networks=["127.0.0.0/8"],
                webhook_poll_interval_s=0.1,
                webhook_timeout_s=0.2,
                webhook_lease_s=0.5,
            )
            deliverer = WebhookDeliverer(store, settings)
            deliverer.start()
            try:
                receiver.wait_until(lambda r: len(r.delivered_ids()) == 1, "the delivery")
                eventually(
                    lambda: [e.state for e in store.events("wh_00000000000000aa")] == ["delivered"],
                    "recorded",
                )
            finally:
                deliverer.close()
            (request,) = receiver.snapshot()
            assert request.verified and request.webhook_id == claimed.event_id
            assert [d["status_code"] for d in store.deliveries(claimed.event_id)] == [204]
            storage.ingest(
                [sample_alert("pg-wh-3", 6.0)], geo=SITE.geo_frame, received_at=now - 3600.0
            )
            assert store.pending_count() == 1
            assert store.expire_overdue(time.time(), ttl_s=900.0) == 1
            assert store.pending_count() == 0
            assert store.delete("wh_00000000000000aa") and store.subscriptions() == []
            assert store.deliveries(claimed.event_id) == []
    finally:
        storage.close()


def test_track_smoothing_on_postgresql(postgres_url: str, tmp_path: Path) -> None:
    """Track lives, the covariances (bytea) and the smoothed points on PostgreSQL: the RTS
    result to the last bits, written once, the unfinished life found again. Another site's
    rows, arrived later than the retention test purges."""
    site = SITE.model_copy(update={"site_id": "pg-smoothing"})
    received_at = NOW + 40 * 86400.0
    settings = gateway_settings(tmp_path)
    storage = Storage.open(postgres_url)
    try:
        finisher = TrackFinisher.of(
            storage, site, settings, GatewayMetrics(), clock=lambda: received_at
        )
        assert finisher.resume() == 0
        car = filtered_car(seed=61, count=60)
        noise = ProcessNoise(1.5, 0.8, 1.0)  # carried by the batches, recorded with the life
        messages = [
            *merged_batches((car.stamps_s, car_tracks(71, car)), process_noise=noise),
            batch(10.0, [make_track(72, 900.0, 20.0)], 500),
        ]
        for message in messages:
            message = message.model_copy(update={"site": site.site_id})
            finisher.before_write([message], received_at)
            storage.ingest([message], geo=site.geo_frame, received_at=received_at)
        (life,) = finisher.pending
        assert life.track_id == 71 and finisher.work() == 1
        assert finisher.finish(life) == 0  # already ended: nothing more
        stored = storage.points(
            PointQuery(site=site.site_id, track_id=71, smoothed=True, limit=100)
        ).items
        x_s, _ = rts_smooth(car.stamps_s, car.x_filt, car.P_filt, noise)
        np.testing.assert_allclose(
            [[p.x_m, p.y_m, p.vx_mps, p.vy_mps] for p in stored], x_s, rtol=0.0, atol=1e-9
        )
        (unfinished,) = TrackLifeStore(storage.engine).unfinished(site.site_id)
        assert unfinished.track_id == 72 and unfinished.process_noise == ProcessNoise()
    finally:
        storage.close()


def test_concurrent_key_creations_never_pass_the_cap_on_postgresql(
    postgres_url: str, tmp_path: Path
) -> None:
    """60 creations at once against a cap of 20: the cap holds under read committed too."""
    settings = gateway_settings(tmp_path, database_url=postgres_url, max_api_keys=20)
    storage = open_storage(settings)
    live_before = KeyStore(storage.engine).count_live()
    assert live_before < 20
    with live_server(settings, storage) as url:
        codes = mint_concurrently(url, {"X-API-Key": ADMIN_KEY}, 60)
    assert sorted(set(codes)) == [201, 409], codes
    assert codes.count(201) == 20 - live_before
    assert KeyStore(storage.engine).count_live() == 20
    storage.close()
