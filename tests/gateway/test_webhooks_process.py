"""The gateway node as its own process on real Zenoh, killed with SIGKILL while a webhook is in
flight (the receiver holds the request), then started again on the same SQLite file: every
alert reaches the receiver, answered 2xx once per webhook-id, and nothing stored is lost."""

from __future__ import annotations

import signal
from pathlib import Path
from typing import Any

import httpx

from tests.conftest import free_port
from tests.gateway.helpers import (
    ADMIN_KEY,
    READ_KEY,
    SITE,
    car_batches,
    eventually,
    gateway_process,
    sample_alert,
)
from tests.gateway.test_node_process import points_count
from tests.gateway.webhook_receiver import Answer, Receiver
from wz_gateway import webhooks
from wz_shared.bus import Bus
from wz_shared.messages import Alert, AlertType, TrackBatch
from wz_shared.settings import BusSettings

ROOT = Path(__file__).resolve().parents[2]
ADMIN = {"X-API-Key": ADMIN_KEY}
READ = {"X-API-Key": READ_KEY}
TIMEOUT_S = 5.0
LEASE_S = 6.0
#: Short timeouts and backoff so that the test takes seconds.
NODE_SETTINGS = {
    "webhook_allowed_networks": "127.0.0.1/32",
    "webhook_timeout_s": str(TIMEOUT_S),
    "webhook_lease_s": str(LEASE_S),
    "webhook_backoff_base_s": "0.2",
    "webhook_backoff_cap_s": "1.0",
    "webhook_poll_interval_s": "0.2",
}


def stored_alerts(http: httpx.Client) -> int:
    return len(http.get("/v1/alerts", headers=READ, params={"limit": 1000}).json()["alerts"])


def delivered_events(http: httpx.Client, subscription_id: str) -> list[dict[str, Any]] | None:
    events: list[dict[str, Any]] = http.get(
        f"/v1/webhooks/{subscription_id}/events", headers=ADMIN
    ).json()
    return events if len(events) == 5 and all(e["state"] == "delivered" for e in events) else None


def test_a_node_killed_mid_delivery_delivers_everything_after_a_restart(
    port: int, tmp_path: Path
) -> None:
    bus_settings = BusSettings(listen_endpoints=[f"tcp/127.0.0.1:{port}"], connect_endpoints=[])
    http_port = free_port()
    http = httpx.Client(base_url=f"http://127.0.0.1:{http_port}", timeout=5.0)
    batches = car_batches(7, 900.0, 28.0, 0.0, 30)
    alerts = [sample_alert(f"kill-{k}", 0.5 + 0.1 * k, track_id=7) for k in range(5)]
    expected = {webhooks.alert_event_id(a) for a in alerts}
    # Until the kill, the receiver holds every request: the first event stays in flight.
    receiver = Receiver(lambda _id, _seen: Answer(503, hold=True)).start()
    try:
        with Bus.open(bus_settings, site=SITE.site_id, service="gateway-test") as bus:
            tracks = bus.publisher(bus.keys.tracks, TrackBatch)
            publish = bus.publisher(bus.keys.alerts(AlertType.SPEEDING.value), Alert)
            with gateway_process(port, http_port, tmp_path / "data", **NODE_SETTINGS) as node:
                made = eventually(
                    lambda: http.post("/v1/webhooks", headers=ADMIN, json={"url": receiver.url}),
                    "the API",
                )
                assert made.status_code == 201, made.text
                receiver.secrets = [made.json()["secret"]]
                assert tracks.wait_for_subscribers(30.0) and publish.wait_for_subscribers(10.0)
                for message in batches:
                    tracks.put(message)
                for alert in alerts:
                    publish.put(alert)
                eventually(lambda: points_count(http) == 30 or None, "30 stored points")
                eventually(lambda: stored_alerts(http) == 5 or None, "5 stored alerts")
                receiver.wait_until(lambda r: len(r.held()) == 1, "a request in flight")
                points_before, alerts_before = points_count(http), stored_alerts(http)
                assert "wz_gateway_webhook_pending 5.0" in http.get("/metrics").text

                node.send_signal(signal.SIGKILL)  # mid-delivery: the receiver has not answered
                assert node.wait(10.0) == -signal.SIGKILL
                (in_flight,) = receiver.held()
                receiver.policy = lambda _id, _seen: Answer(204)
                receiver.release()  # its 503 goes to a dead connection

            with gateway_process(port, http_port, tmp_path / "data", **NODE_SETTINGS):
                receiver.wait_until(
                    lambda r: set(r.delivered_ids()) == expected,
                    "every alert delivered after the restart",
                    timeout_s=40.0,
                )
                assert points_count(http) == points_before == 30
                assert stored_alerts(http) == alerts_before == 5
                subscription_id = made.json()["subscription_id"]
                events = eventually(
                    lambda: delivered_events(http, subscription_id),
                    "all five recorded as delivered",
                )
                # The attempt the kill cut short was never recorded: at least once, not twice.
                assert [e["attempts"] for e in events] == [1] * 5
                metrics = http.get("/metrics").text
                assert 'wz_gateway_webhook_events_total{state="delivered"} 5.0' in metrics
                assert "wz_gateway_webhook_pending 0.0" in metrics
        got = receiver.snapshot()
    finally:
        receiver.stop()
        http.close()
    assert receiver.delivered_ids() == {i: 1 for i in expected}  # exactly once per id
    assert all(r.verified for r in got)
    requests = [r for r in got if r.webhook_id == in_flight]
    assert [r.ok for r in requests] == [False, True]  # the one in flight, sent again
    # Not before its lease ran out (taken at most a few ms before the receiver saw it).
    assert requests[1].at - requests[0].at >= LEASE_S - 0.5
    assert len(got) == 5 + 1
