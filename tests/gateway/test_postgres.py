"""The same data layer on PostgreSQL: a throwaway cluster (initdb, pg_ctl) on a free loopback
port, where the server is installed (Debian: apt-get install postgresql); skipped elsewhere."""

from __future__ import annotations

import glob
import os
import pwd
import shutil
import subprocess
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.conftest import free_port
from tests.gateway.helpers import SITE, batch, car_batches, make_track, sample_alert
from wz_gateway import auth
from wz_gateway.storage import AlertQuery, PointQuery, Storage
from wz_gateway.tables import SCHEMA_VERSION

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
    if bin_dir is None:
        pytest.skip("no PostgreSQL server here (apt-get install postgresql)")
    as_user: list[str] = []
    home = Path(tempfile.mkdtemp(prefix="wz-pg-"))
    if os.geteuid() == 0:  # initdb refuses root: run the cluster as the postgres user
        try:
            owner = pwd.getpwnam("postgres")
        except KeyError:
            pytest.skip("running as root and there is no postgres user")
        os.chown(home, owner.pw_uid, owner.pw_gid)
        as_user = ["runuser", "-u", "postgres", "--"]
    data = home / "data"
    port = free_port()

    def run(*args: str) -> None:
        subprocess.run([*as_user, *args], check=True, capture_output=True, timeout=120)

    run(str(bin_dir / "initdb"), "-D", str(data), "--auth=trust", "-U", "wz", "-E", "UTF8")
    run(str(bin_dir / "pg_ctl"), "-D", str(data), "-l", str(home / "log"), "-w", "-o",
        f"-p {port} -k {home} -c listen_addresses=127.0.0.1 -c fsync=off", "start")  # fmt: skip
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
    batches = [batch(a.stamp, [*a.tracks, *b.tracks], a.cycle_index)
               for a, b in zip(left, right, strict=True)]  # fmt: skip
    alert = sample_alert("pg-1", 1.0, track=make_track(1, 830.0, 30.0))
    result = storage.ingest([*batches, alert, alert], geo=SITE.geo_frame, received_at=NOW)
    assert (result.points, result.alerts, result.duplicate_alerts) == (40, 1, 1)
    secret = auth.new_secret()
    info = storage.add_api_key("admin", secret, name="pg", origin="api", now=NOW)
    storage.close()

    reopened = Storage.open(postgres_url)  # nothing to migrate, everything still there
    try:
        assert reopened.migrate() == []
        seen, cursor = [], None
        while True:
            page = reopened.points(PointQuery(site=SITE.site_id, limit=7, cursor=cursor,
                                              min_speed_mps=0.0))  # fmt: skip
            seen += [(p.track_id, p.stamp) for p in page.items]
            if page.next_cursor is None:
                break
            cursor = page.next_cursor
        assert len(seen) == 40 == len(set(seen))
        assert reopened.alerts(AlertQuery(site=SITE.site_id)).items == [alert]
        assert reopened.find_api_key(secret) == info
        live = reopened.latest(SITE.site_id, "tracks")
        assert live is not None and live.stamp == pytest.approx(1.9)
        deleted = reopened.purge(NOW + 31 * 86400.0, retention_days=30.0,
                                 alert_retention_days=365.0)  # fmt: skip
        assert deleted["track_points"] == 40 and deleted["alerts"] == 0
    finally:
        reopened.close()
