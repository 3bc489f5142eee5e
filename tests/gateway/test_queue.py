"""Each lane's queue at the gateway: stored in a real SQLite file (the newest as the queue now,
every state in the history, purged with the retention, a database of schema 7 upgraded) and
served at ``GET /v1/queue`` and ``GET /v1/queue/history`` over real HTTP (keys, paging by the
Link header, filters, problem+json for bad input)."""

from __future__ import annotations

import sqlite3
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from sqlalchemy import inspect

from tests.gateway.helpers import READ_KEY, SITE, gateway_settings, live_server, open_storage
from tests.gateway.test_wzdx import T0_UNIX
from wz_gateway.settings import GatewaySettings
from wz_gateway.storage import Storage
from wz_gateway.store_types import QueueQuery
from wz_gateway.tables import SCHEMA_VERSION
from wz_shared.messages import LaneQueue, QueueCondition, QueueState

HEADERS = {"X-API-Key": READ_KEY}


def state(stamp: float, back_m: float | None, *, stopped: bool = False) -> QueueState:
    """Lane 0 queued from ``back_m`` to 980 m (free when None), lane 1 free."""
    if back_m is None:
        lane0 = LaneQueue(lane_index=0, condition=QueueCondition.FREE, reach_station_m=780.0)
    else:
        lane0 = LaneQueue(
            lane_index=0,
            condition=QueueCondition.STOPPED if stopped else QueueCondition.SLOW,
            back_station_m=back_m,
            head_station_m=980.0,
            length_m=980.0 - back_m,
            vehicle_count=int((980.0 - back_m) / 8.0) + 1,
            mean_speed_mps=1.0 if stopped else 6.0,
            back_speed_mps=-3.0,
            reach_station_m=780.0,
        )
    lane1 = LaneQueue(lane_index=1, condition=QueueCondition.FREE, reach_station_m=780.0)
    return QueueState(
        site=SITE.site_id, source_id="alert-service", stamp=stamp, lanes=[lane0, lane1]
    )


#: A queue forms at 10 s, grows 3 m/s upstream, stops at 20 s and dissolves at 30 s.
STORY = [
    state(float(t), None if t < 10 or t >= 30 else 950.0 - 3.0 * (t - 10), stopped=t >= 20)
    for t in range(0, 40)
]


@pytest.fixture
def settings(tmp_path: Path) -> GatewaySettings:
    return gateway_settings(tmp_path)


@pytest.fixture
def storage(settings: GatewaySettings) -> Iterator[Storage]:
    store = open_storage(settings)
    yield store
    store.close()


def ingest(storage: Storage, states: list[QueueState], t0: float = T0_UNIX) -> None:
    for one in states:
        storage.ingest([one], geo=SITE.geo_frame, received_at=t0 + one.stamp)


def test_every_state_is_kept_and_the_newest_is_the_queue_now(storage: Storage) -> None:
    ingest(storage, STORY)
    assert storage.count("queue_states") == len(STORY)
    newest = storage.latest(SITE.site_id, "queue")
    assert newest is not None and QueueState.model_validate_json(newest.body) == STORY[-1]
    page = storage.queue_history(QueueQuery(site=SITE.site_id, conditions=("stopped",)))
    assert [s.stamp for s in page.items] == [float(t) for t in range(29, 19, -1)]
    assert page.items[0] == STORY[29]  # lanes back from JSON as they went in
    assert page.items[0].back_station_m == 950.0 - 3.0 * 19


def test_retention_and_an_upgrade_from_schema_7(tmp_path: Path) -> None:
    path = tmp_path / "data" / "gateway.sqlite3"
    first = open_storage(gateway_settings(tmp_path))
    first.close()
    with sqlite3.connect(path) as raw:  # as a gateway before migration 8 left it
        raw.execute("DROP TABLE queue_states")
        raw.execute("DELETE FROM schema_version WHERE version = 8")
    storage = Storage.open(f"sqlite:///{path}")
    try:
        assert storage.current_schema_version() == SCHEMA_VERSION == 8
        assert "queue_states" in inspect(storage.engine).get_table_names()
        ingest(storage, STORY[:20], t0=T0_UNIX)
        ingest(storage, STORY[20:], t0=T0_UNIX + 40 * 86400.0)
        deleted = storage.purge(
            T0_UNIX + 45 * 86400.0, retention_days=30.0, alert_retention_days=365.0
        )
        assert deleted["queue_states"] == 20
        assert storage.count("queue_states") == 20
    finally:
        storage.close()


def test_get_queue_now_and_stale(settings: GatewaySettings, storage: Storage) -> None:
    now = [T0_UNIX]
    with live_server(settings, storage, clock=lambda: now[0]) as url:
        empty = httpx.get(f"{url}/v1/queue", headers=HEADERS)
        assert empty.status_code == 200, empty.text
        assert empty.json() == {
            "site": SITE.site_id,
            "queue": None,
            "received_at": None,
            "age_s": None,
            "stale": False,
        }
        ingest(storage, STORY[:25])
        now[0] = T0_UNIX + 25.0
        body = httpx.get(f"{url}/v1/queue", headers=HEADERS).json()
        assert QueueState.model_validate(body["queue"]) == STORY[24]
        lane0 = body["queue"]["lanes"][0]
        assert lane0["condition"] == "stopped" and lane0["back_station_m"] == 908.0
        assert lane0["back_speed_mps"] == -3.0 and lane0["back_beyond_reach"] is False
        assert body["age_s"] == pytest.approx(1.0) and body["stale"] is False
        now[0] = T0_UNIX + 24.0 + settings.stale_after_s + 1.0
        assert httpx.get(f"{url}/v1/queue", headers=HEADERS).json()["stale"] is True


def test_get_queue_history_pages_and_filters(settings: GatewaySettings, storage: Storage) -> None:
    ingest(storage, STORY)
    with live_server(settings, storage) as url:
        stamps: list[float] = []
        link = f"{url}/v1/queue/history?order=oldest&limit=15&start=5&end=34"
        while link:
            reply = httpx.get(link, headers=HEADERS)
            assert reply.status_code == 200, reply.text
            stamps += [s["stamp"] for s in reply.json()["states"]]
            link = reply.links.get("next", {}).get("url", "")
        assert stamps == [float(t) for t in range(5, 35)]
        slow = httpx.get(
            f"{url}/v1/queue/history", params={"condition": "slow"}, headers=HEADERS
        ).json()
        assert slow["count"] == 10 and slow["states"][0]["stamp"] == 19.0
        # bad input: a clear 422 (problem+json), nothing served
        for params in ({"condition": "jammed"}, {"start": 10, "end": 5}, {"limit": 0}):
            bad = httpx.get(f"{url}/v1/queue/history", params=params, headers=HEADERS)
            assert bad.status_code == 422, (params, bad.text)
            assert bad.headers["content-type"] == "application/problem+json"
        assert httpx.get(f"{url}/v1/queue").status_code == 401
        other = httpx.get(f"{url}/v1/queue", params={"site": "elsewhere"}, headers=HEADERS)
        assert other.status_code == 404
