"""The gateway's /readyz from the work, on the real node process: unready when the tracker's
batches stop coming (a stopped tracker, whose last batch the gateway would otherwise keep
serving as live) and when its own writer loop is blocked (a database another process holds
locked); ready again once each recovers."""

from __future__ import annotations

import sqlite3
import time
from pathlib import Path
from typing import Any

import httpx

from tests.conftest import free_port
from tests.gateway.helpers import SITE, car_batches, eventually, gateway_process
from wz_shared.bus import Bus
from wz_shared.messages import TrackBatch
from wz_shared.settings import BusSettings

STALE_AFTER_S = 3.0


def readiness(http: httpx.Client) -> tuple[int, dict[str, Any]]:
    response = http.get("/readyz")
    return response.status_code, response.json()["checks"]


def unready(http: httpx.Client, check: str, says: str) -> dict[str, Any] | None:
    """The checks when /readyz is 503 with ``check`` saying ``says``, else None."""
    code, checks = readiness(http)
    return checks if code == 503 and says in checks.get(check, "") else None


def test_readyz_is_unready_for_stale_tracks_and_a_blocked_writer_loop(
    port: int, tmp_path: Path
) -> None:
    settings = BusSettings(listen_endpoints=[f"tcp/127.0.0.1:{port}"], connect_endpoints=[])
    http_port = free_port()
    http = httpx.Client(base_url=f"http://127.0.0.1:{http_port}", timeout=15.0)
    batches = car_batches(7, 900.0, 28.0, 0.0, 400)
    with (
        Bus.open(settings, site=SITE.site_id, service="fusion-tracker") as bus,
        gateway_process(port, http_port, tmp_path / "data", stale_after_s=str(STALE_AFTER_S)),
    ):
        tracks = bus.publisher(bus.keys.tracks, TrackBatch)
        assert tracks.wait_for_subscribers(30.0), "the gateway never subscribed to tracks"
        feed = iter(batches)

        def publish_for(seconds: float) -> None:
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                tracks.put(next(feed))
                time.sleep(0.1)

        publish_for(1.0)
        eventually(lambda: readiness(http)[0] == 200 or None, "ready with tracks coming")

        # The tracker stops: unready once its newest batch is older than stale_after_s.
        stopped_at = time.monotonic()
        checks = eventually(lambda: unready(http, "tracks", "tracker"), "unready without tracks")
        assert time.monotonic() - stopped_at <= STALE_AFTER_S + 2.0
        assert "newest track batch" in checks["tracks"] and "tracker" in checks["tracks"]
        publish_for(1.0)
        eventually(lambda: readiness(http)[0] == 200 or None, "ready when tracks come again")

        # Another process holds the database locked: the writer's next transaction waits
        # (its loop does not go round), and /readyz says so within the 5 s stall limit + 1 s.
        database = sqlite3.connect(tmp_path / "data" / "gateway.sqlite3", timeout=0.1)
        database.execute("BEGIN EXCLUSIVE")
        locked_at = time.monotonic()
        try:
            tracks.put(next(feed))
            eventually(
                lambda: unready(http, "writer", "stalled"),
                "unready with the writer loop blocked",
                timeout_s=10.0,
            )
            blocked_s = time.monotonic() - locked_at
        finally:
            database.rollback()
            database.close()
        assert blocked_s <= 10.0, blocked_s
        publish_for(1.0)
        eventually(lambda: readiness(http)[0] == 200 or None, "ready once the lock is gone")
    http.close()
