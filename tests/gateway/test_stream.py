"""The live stream: the broadcaster on a real event loop (drops, decimation, replay, close), and
``GET /v1/stream`` on a real uvicorn server fed by the node's writer: events as the SSE format
has them, keys and limits, and a client that never reads does not hold up ingestion."""

from __future__ import annotations

import asyncio
import json
import re
import socket
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx
import pytest
import uvicorn
from prometheus_client import CollectorRegistry

from tests.conftest import free_port
from tests.gateway.helpers import (
    READ_KEY,
    SITE,
    car_batches,
    gateway_settings,
    make_track,
    open_storage,
    sample_alert,
)
from wz_gateway.app import create_app
from wz_gateway.live import (
    Broadcaster,
    LiveEvent,
    TooManyClientsError,
    broadcaster_for,
    compact_tracks,
)
from wz_gateway.metrics import GatewayMetrics
from wz_gateway.node import Writer
from wz_gateway.settings import GatewaySettings
from wz_gateway.storage import Storage
from wz_shared.messages import Alert, TrackBatch

READ = {"X-API-Key": READ_KEY}


async def drain(subscription: Any, timeout_s: float = 0.05) -> list[LiveEvent]:
    """Every event the subscription holds now or gets within ``timeout_s``."""
    events: list[LiveEvent] = []
    while True:
        try:
            event = await asyncio.wait_for(subscription.get(), timeout_s)
        except TimeoutError:
            return events
        if event is None:
            return events
        events.append(event)


def payload(event: LiveEvent) -> dict[str, Any]:
    lines = event.sse().splitlines()
    assert lines[0] == f"id: {event.event_id}" and lines[1] == f"event: {event.kind}"
    data: dict[str, Any] = json.loads(lines[2].removeprefix("data: "))
    return data


# --- the broadcaster ------------------------------------------------------------------------


def test_a_slow_client_loses_its_oldest_events_counted_and_keeps_the_newest() -> None:
    registry = CollectorRegistry()
    broadcaster = Broadcaster(queue_capacity=4, registry=registry)
    alerts = [sample_alert(f"a{k}", float(k)) for k in range(10)]

    async def run() -> list[LiveEvent]:
        subscription = broadcaster.subscribe(frozenset({"alert"}))
        for alert in alerts:  # the writer's thread in the node; here the loop's, before it reads
            broadcaster.publish([alert])
        events = await drain(subscription)
        assert subscription.dropped == 6
        return events

    events = asyncio.run(run())
    assert [payload(e)["alert_id"] for e in events] == ["a6", "a7", "a8", "a9"]
    assert Alert.model_validate(payload(events[-1])) == alerts[-1]
    assert broadcaster.dropped == 6
    assert registry.get_sample_value("wz_gateway_stream_dropped_events_total") == 6.0


def test_track_batches_are_decimated_to_the_rate_and_end_on_the_newest() -> None:
    broadcaster = Broadcaster(max_tracks_hz=10.0)
    batches = car_batches(3, 900.0, 25.0, 0.0, 20, period_s=0.01)  # 100 Hz, faster than 10 Hz

    async def run() -> tuple[list[LiveEvent], list[LiveEvent], int]:
        subscription = broadcaster.subscribe(frozenset({"tracks"}))
        started = asyncio.get_running_loop().time()
        for batch in batches:
            broadcaster.publish([batch])
        first = await drain(subscription, 0.05)  # the first goes at once
        later = await drain(subscription, 0.25)  # the newest, 0.1 s after the first
        assert asyncio.get_running_loop().time() - started >= 0.1
        return first, later, subscription.decimated

    first, later, decimated = asyncio.run(run())
    assert [payload(e)["cycle_index"] for e in first] == [0]
    assert [payload(e)["cycle_index"] for e in later] == [19]
    assert decimated == 18


def test_a_new_client_gets_the_newest_batch_and_a_reconnecting_one_the_alerts_it_missed() -> None:
    broadcaster = Broadcaster()
    broadcaster.publish([sample_alert("before", 1.0)])
    broadcaster.publish([*car_batches(3, 900.0, 25.0, 1.0, 3), sample_alert("a1", 1.2)])

    async def run() -> None:
        fresh = broadcaster.subscribe(frozenset({"tracks", "alert"}))
        events = await drain(fresh)
        assert [e.kind for e in events] == ["tracks"]  # the newest state, no history
        assert payload(events[0])["cycle_index"] == 2
        last_seen = f"{broadcaster.boot}-1"  # the first alert's id
        back = broadcaster.subscribe(frozenset({"alert"}), last_event_id=last_seen)
        broadcaster.publish([sample_alert("a2", 2.0), sample_alert("a1", 1.2)])  # a1 again
        assert [payload(e)["alert_id"] for e in await drain(back)] == ["a1", "a2"]
        elsewhere = broadcaster.subscribe(frozenset({"alert"}), last_event_id="0-1")
        assert await drain(elsewhere) == []  # another process's ids: nothing to replay
        broadcaster.close()
        assert [payload(e)["alert_id"] for e in await drain(fresh)] == ["a2"]  # then the end
        assert broadcaster.client_count == 0

    asyncio.run(run())


def test_close_ends_every_stream_and_the_client_limit_holds() -> None:
    broadcaster = Broadcaster(max_clients=2)

    async def run() -> None:
        clients = [broadcaster.subscribe(frozenset({"tracks"})) for _ in range(2)]
        with pytest.raises(TooManyClientsError):
            broadcaster.subscribe(frozenset({"tracks"}))
        broadcaster.unsubscribe(clients[0])
        clients.append(broadcaster.subscribe(frozenset({"alert"})))
        broadcaster.close()
        for client in clients[1:]:
            assert await asyncio.wait_for(client.get(), 1.0) is None
        late = broadcaster.subscribe(frozenset({"tracks"}))
        assert await asyncio.wait_for(late.get(), 1.0) is None

    asyncio.run(run())


def test_compact_tracks_keeps_what_a_view_draws_rounded() -> None:
    track = make_track(7, 912.3456, 27.123456, offset_m=1.834567, length_m=4.56789)
    batch = TrackBatch(
        site=SITE.site_id, source_id="fusion-tracker", stamp=12.5, cycle_index=250, tracks=[track]
    )
    data = compact_tracks(batch, received_at=1_750_000_000.12345)
    assert data == {
        "site": SITE.site_id,
        "stamp": 12.5,
        "cycle_index": 250,
        "received_at": 1_750_000_000.123,
        "tracks": [
            {
                "track_id": 7,
                "x_m": -1.83,
                "y_m": 912.35,
                "station_m": 912.35,
                "offset_m": 1.83,
                "speed_mps": 27.12,
                "heading_rad": 1.571,
                "lane_index": 1,
                "object_class": "unknown",
                "status": "confirmed",
                "length_m": 4.57,
                "width_m": None,
            }
        ],
    }


# --- GET /v1/stream on a real server ---------------------------------------------------------


@contextmanager
def serving(settings: GatewaySettings, storage: Storage) -> Iterator[tuple[str, Writer]]:
    """The app on uvicorn in a thread and the node's writer feeding its broadcaster."""
    metrics = GatewayMetrics()
    live = broadcaster_for(settings, metrics.registry)
    writer = Writer(storage, SITE, settings, metrics, report=lambda *_: None, live=live)
    app = create_app(settings, storage, site=SITE, metrics=metrics, live=live)
    port = free_port()
    server = uvicorn.Server(
        uvicorn.Config(
            app, host="127.0.0.1", port=port, log_config=None, access_log=False, lifespan="off"
        )
    )
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 10.0
    while not server.started:
        assert time.monotonic() < deadline and thread.is_alive(), "uvicorn did not start"
        time.sleep(0.01)
    try:
        yield f"http://127.0.0.1:{port}", writer
    finally:
        live.close()  # the streams end, so the server can
        server.should_exit = True
        thread.join(10.0)
        assert not thread.is_alive()


def read_events(lines: Iterator[str], count: int, kinds: set[str]) -> list[dict[str, str]]:
    """The next ``count`` events of the given kinds, each as its fields."""
    events: list[dict[str, str]] = []
    block: dict[str, str] = {}
    for line in lines:
        if line.startswith(":"):
            continue
        if line:
            field, _, value = line.partition(": ")
            block[field] = value
        elif block:
            if block.get("event") in kinds:
                events.append(block)
                if len(events) == count:
                    break
            block = {}
    return events


@pytest.fixture
def storage(tmp_path: Path) -> Iterator[Storage]:
    storage = open_storage(gateway_settings(tmp_path))
    yield storage
    storage.close()


def test_stream_sends_stored_tracks_and_alerts_as_server_sent_events(
    tmp_path: Path, storage: Storage
) -> None:
    settings = gateway_settings(tmp_path, stream_heartbeat_s=0.2)
    batches = car_batches(5, 900.0, 25.0, 0.0, 10)
    alert = sample_alert("sse-1", 0.5, track_id=5)
    with (
        serving(settings, storage) as (base, writer),
        httpx.Client(base_url=base, timeout=10.0) as http,
    ):
        with http.stream("GET", "/v1/stream", headers=READ) as response:
            assert response.status_code == 200
            assert response.headers["content-type"].startswith("text/event-stream")
            assert response.headers["cache-control"] == "no-cache"
            lines = response.iter_lines()
            assert next(lines) == "retry: 2000"
            assert writer.write([batches[0]])
            (first,) = read_events(lines, 1, {"tracks"})
            data = json.loads(first["data"])
            assert data == compact_tracks(batches[0], data["received_at"])
            assert re.fullmatch(r"[0-9a-f]+-1", first["id"])
            for line in lines:  # nothing happens for a while: heartbeats
                if line == ": keep-alive":
                    break
            assert writer.write([*batches[1:], alert])
            (sent,) = read_events(lines, 1, {"alert"})
            assert Alert.model_validate_json(sent["data"]) == alert
            assert sent["id"].endswith("-3")  # after the first batch and the group's newest
        with http.stream(
            "GET", "/v1/stream", headers=READ, params={"event": "alert"}
        ) as alerts_only:
            lines = alerts_only.iter_lines()
            assert writer.write([*car_batches(5, 1150.0, 25.0, 1.0, 3), sample_alert("sse-2", 1.1)])
            (event,) = read_events(lines, 1, {"alert", "tracks"})
            assert event["event"] == "alert" and json.loads(event["data"])["alert_id"] == "sse-2"
        stored = http.get("/v1/alerts", headers=READ).json()["alerts"]
        assert [a["alert_id"] for a in stored] == ["sse-2", "sse-1"]


def test_a_client_that_never_reads_does_not_hold_up_ingestion(
    tmp_path: Path, storage: Storage
) -> None:
    """A client whose socket takes 4 KiB and never reads, beside one that reads: 3000 alerts of
    2 KiB (6 MiB, more than the sockets hold) are stored at the writer's own pace; the slow
    client's oldest events are dropped, the reading client gets the newest."""
    settings = gateway_settings(tmp_path, stream_queue_capacity=256)
    evidence = {f"evidence_value_{k:02d}_m": float(k) for k in range(40)}
    alerts = [
        sample_alert(f"slow-{k:04d}", k * 0.01).model_copy(
            update={"evidence": evidence, "description": "d" * 400}
        )
        for k in range(3000)
    ]
    with serving(settings, storage) as (base, writer):
        live = writer.live
        assert live is not None
        port = int(base.rsplit(":", 1)[1])
        slow = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        slow.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        slow.connect(("127.0.0.1", port))
        slow.sendall(
            f"GET /v1/stream?event=alert HTTP/1.1\r\nHost: gateway\r\n"
            f"X-API-Key: {READ_KEY}\r\n\r\n".encode()
        )
        received: list[str] = []

        def read_fast() -> None:
            with (
                httpx.Client(base_url=base, timeout=30.0) as http,
                http.stream(
                    "GET", "/v1/stream", headers=READ, params={"event": "alert"}
                ) as response,
            ):
                for line in response.iter_lines():
                    if line.startswith("data: "):
                        received.append(json.loads(line[6:])["alert_id"])
                        if received[-1] == alerts[-1].alert_id:
                            return

        reader = threading.Thread(target=read_fast, daemon=True)
        reader.start()
        deadline = time.monotonic() + 10.0
        while live.client_count < 2:
            assert time.monotonic() < deadline, "the two clients never connected"
            time.sleep(0.01)
        for first in range(0, len(alerts), 100):
            assert writer.write(alerts[first : first + 100])
        reader.join(30.0)
        slow.close()
        assert writer.written == len(alerts)
        assert received and received[-1] == alerts[-1].alert_id and received == sorted(received)
        assert live.dropped > 0, "the slow client never fell behind: make the alerts bigger"


def test_keys_limits_and_the_page_routes(tmp_path: Path, storage: Storage) -> None:
    settings = gateway_settings(tmp_path, stream_max_clients=1)
    with serving(settings, storage) as (base, _), httpx.Client(base_url=base, timeout=10.0) as http:
        refused = http.get("/v1/stream")
        assert refused.status_code == 401
        assert refused.headers["content-type"] == "application/problem+json"
        bad = http.get("/v1/stream", headers=READ, params={"event": "everything"})
        assert bad.status_code == 422 and bad.json()["errors"][0]["location"] == "query.event.0"
        with http.stream("GET", "/v1/stream", headers=READ) as first:
            assert first.status_code == 200
            full = http.get("/v1/stream", headers=READ)
            assert full.status_code == 503 and full.headers["retry-after"] == "10"
            assert full.json()["detail"].startswith("the live stream already has the most")

        root = http.get("/")
        assert root.status_code == 307 and root.headers["location"] == "/live"
        page = http.get("/live")  # no key: the page holds no data
        assert page.status_code == 200 and page.headers["content-type"].startswith("text/html")
        assert "default-src 'self'" in page.headers["content-security-policy"]
        for name, kind in [
            ("live.js", "javascript"),
            ("live.css", "text/css"),
            ("favicon.svg", "image/svg+xml"),
        ]:
            asset = http.get(f"/static/{name}")
            assert asset.status_code == 200 and kind in asset.headers["content-type"], name
            assert f"/static/{name}" in page.text
        assert http.get("/static/missing.js").status_code == 404
        assert "/v1/stream" in http.get("/openapi.json").json()["paths"]
        assert "/live" not in http.get("/openapi.json").json()["paths"]


def test_dev_mode_streams_without_a_key(tmp_path: Path, storage: Storage) -> None:
    settings = GatewaySettings(data_dir=tmp_path / "data", dev_mode=True, port=0)
    with (
        serving(settings, storage) as (base, writer),
        httpx.stream("GET", f"{base}/v1/stream", params={"event": "tracks"}) as response,
    ):
        assert response.status_code == 200
        assert writer.write(car_batches(2, 950.0, 20.0, 0.0, 1))
        (event,) = read_events(response.iter_lines(), 1, {"tracks"})
        assert json.loads(event["data"])["tracks"][0]["track_id"] == 2
