"""Webhook delivery in process, against real HTTP receivers on loopback: signatures checked by
the Standard Webhooks reference library, filters, one event per alert however often it comes,
Retry-After, 410, expiry, a slow receiver beside a fast one, DNS rebinding refused at delivery
time, a claim left by a dead process taken again, and a receiver down for 30 s."""

from __future__ import annotations

import datetime
import json
import random
import secrets
import time
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from email.utils import format_datetime
from pathlib import Path
from typing import Any

import pytest

from tests.gateway.helpers import SITE, gateway_settings, open_storage, sample_alert
from tests.gateway.webhook_receiver import Answer, Receiver, always, eventually
from wz_gateway import webhooks
from wz_gateway.delivery import Resolve, WebhookDeliverer, resolve_host
from wz_gateway.metrics import GatewayMetrics
from wz_gateway.settings import GatewaySettings
from wz_gateway.storage import Storage
from wz_gateway.store_types import IngestResult
from wz_gateway.webhook_store import WebhookStore
from wz_shared.messages import Alert, AlertSeverity, AlertType

LOOPBACK = ["127.0.0.0/8"]


class Gateway:
    """The gateway's storage and delivery, without the bus and the HTTP API."""

    def __init__(self, settings: GatewaySettings, storage: Storage) -> None:
        self.settings = settings
        self.storage = storage
        self.store = WebhookStore(storage.engine)
        self.metrics = GatewayMetrics()

    def subscribe(
        self,
        url: str,
        *,
        event_types: tuple[str, ...] = ("alert.*",),
        min_severity: str | None = None,
        phases: list[str] | None = None,
    ) -> tuple[str, str]:
        """A subscription made straight in the store (the API's checks are tested apart)."""
        subscription_id, secret = f"wh_{secrets.token_hex(8)}", webhooks.new_secret()
        self.store.create(
            subscription_id=subscription_id,
            url=url,
            secret=secret,
            event_types=list(event_types),
            min_severity=min_severity,
            phases=phases,
            description="test",
            now=time.time(),
        )
        return subscription_id, secret

    def ingest(self, *alerts: Alert) -> IngestResult:
        return self.storage.ingest(alerts, geo=SITE.geo_frame, received_at=time.time())

    @contextmanager
    def delivering(
        self, *, resolve: Resolve = resolve_host, settings: GatewaySettings | None = None
    ) -> Iterator[WebhookDeliverer]:
        deliverer = WebhookDeliverer(
            self.store,
            settings or self.settings,
            self.metrics,
            rng=random.Random(1),
            resolve=resolve,
        )
        self.metrics.watch_webhooks(self.store.pending_count)
        deliverer.start()
        try:
            yield deliverer
        finally:
            deliverer.close()

    def count(self, name: str, **labels: str) -> float:
        value = self.metrics.registry.get_sample_value(name, labels)
        return 0.0 if value is None else value

    def states(self, subscription_id: str) -> Counter[str]:
        return Counter(e.state for e in self.store.events(subscription_id, limit=1000))


@pytest.fixture
def make_gateway(tmp_path: Path) -> Iterator[Any]:
    opened: list[Storage] = []

    def make(**overrides: Any) -> Gateway:
        values: dict[str, Any] = {
            "webhook_allowed_networks": LOOPBACK,
            "webhook_poll_interval_s": 0.1,
            **overrides,
        }
        settings = gateway_settings(tmp_path / str(len(opened)), **values)
        storage = open_storage(settings)
        opened.append(storage)
        return Gateway(settings, storage)

    yield make
    for storage in opened:
        storage.close()


def test_alerts_arrive_signed_filtered_and_once(make_gateway: Any) -> None:
    gateway = make_gateway()
    with Receiver() as receiver:
        everything, secret_all = gateway.subscribe(receiver.url_for("/all"))
        critical, secret_critical = gateway.subscribe(
            receiver.url_for("/critical-starts"),
            event_types=("alert.hard_braking", "alert.speeding"),
            min_severity="critical",
            phases=["start"],
        )
        receiver.secrets = [secret_all, secret_critical]
        alerts = [
            sample_alert("sig-1", 1.0),  # speeding, warning, start
            sample_alert(
                "sig-2", 1.5, alert_type=AlertType.HARD_BRAKING, severity=AlertSeverity.CRITICAL
            ),
            sample_alert("sig-3", 2.0, severity=AlertSeverity.CRITICAL, phase="clear"),
            sample_alert(
                "sig-4",
                2.5,
                alert_type=AlertType.QUEUE,
                severity=AlertSeverity.CRITICAL,
                track_id=None,
            ),
        ]
        with gateway.delivering():
            assert gateway.ingest(*alerts).webhook_events == 4 + 1
            again = gateway.ingest(alerts[0], alerts[1])  # the bus delivered them twice
            assert again.duplicate_alerts == 2 and again.webhook_events == 0
            receiver.wait_until(lambda r: len(r.requests) == 5, "five deliveries")
            eventually(lambda: gateway.count("wz_gateway_webhook_pending") == 0, "none pending")
        got = receiver.snapshot()
    assert all(r.verified for r in got), "a signature the reference library refused"
    assert all(r.status == 204 for r in got)
    by_path = {path: [r for r in got if r.path == path] for path in ("/all", "/critical-starts")}
    sent = sorted((json.loads(r.body)["data"]["alert_id"], r.webhook_id) for r in by_path["/all"])
    assert sent == [(a.alert_id, webhooks.alert_event_id(a)) for a in alerts]
    (only,) = by_path["/critical-starts"]
    assert json.loads(only.body)["data"] == alerts[1].model_dump(mode="json")
    assert only.webhook_id == webhooks.alert_event_id(alerts[1])  # one id per event
    assert only.headers["content-type"] == "application/json"
    for request in got:
        body = json.loads(request.body)
        assert body["type"] == f"alert.{body['data']['alert_type']}"
        assert abs(int(request.headers["webhook-timestamp"]) - time.time()) < 60
    assert gateway.states(everything) == {"delivered": 4}
    assert gateway.states(critical) == {"delivered": 1}
    log = gateway.store.deliveries(webhooks.alert_event_id(alerts[1]))
    assert [(d["attempt"], d["status_code"], d["error"]) for d in log] == [(1, 204, None)] * 2
    assert all(d["duration_ms"] > 0.0 for d in log)
    assert gateway.count("wz_gateway_webhook_events_total", state="delivered") == 5
    assert gateway.count("wz_gateway_webhook_attempts_total", result="2xx") == 5


@pytest.mark.parametrize("status", [429, 503])
def test_retry_after_is_honoured_and_the_retry_carries_the_same_id(
    make_gateway: Any, status: int
) -> None:
    gateway = make_gateway(webhook_backoff_base_s=0.05, webhook_backoff_cap_s=0.1)

    def answer(_id: str, seen: int) -> Answer:
        if seen:
            return Answer(200)
        if status == 429:
            return Answer(429, {"Retry-After": "2"})
        # An HTTP date 3 s ahead; at one-second resolution, 2 to 3 s from now.
        when = datetime.datetime.now(datetime.UTC) + datetime.timedelta(seconds=3)
        return Answer(503, {"Retry-After": format_datetime(when, usegmt=True)})

    with Receiver(answer) as receiver:
        subscription_id, secret = gateway.subscribe(receiver.url)
        receiver.secrets = [secret]
        with gateway.delivering():
            gateway.ingest(sample_alert("ra-1", 1.0))
            receiver.wait_until(lambda r: len(r.requests) == 2, "the retry")
        first, second = receiver.snapshot()
    assert first.webhook_id == second.webhook_id
    assert first.verified and second.verified
    assert 2.0 <= second.at - first.at < 3.0 + 2.0  # not before Retry-After; then soon
    (event,) = gateway.store.events(subscription_id)
    assert (event.state, event.attempts, event.last_status_code) == ("delivered", 2, 200)
    log = gateway.store.deliveries(first.webhook_id)
    assert [d["status_code"] for d in log] == [status, 200]
    assert log[0]["error"].startswith(f"HTTP {status}")


def test_410_gone_disables_the_subscription_and_fails_its_events(make_gateway: Any) -> None:
    gateway = make_gateway()
    with Receiver(always(410)) as receiver:
        subscription_id, secret = gateway.subscribe(receiver.url)
        receiver.secrets = [secret]
        with gateway.delivering():
            assert (
                gateway.ingest(
                    sample_alert("g-1", 1.0), sample_alert("g-2", 1.1), sample_alert("g-3", 1.2)
                ).webhook_events
                == 3
            )
            eventually(lambda: gateway.states(subscription_id) == {"failed": 3}, "all failed")
            assert gateway.ingest(sample_alert("g-4", 2.0)).webhook_events == 0
        assert len(receiver.snapshot()) == 1  # one in flight at a time: the first said 410
    info = gateway.store.get(subscription_id)
    assert info is not None and info.disabled_at is not None
    assert info.disabled_reason is not None and "410" in info.disabled_reason
    errors = sorted(str(e.last_error) for e in gateway.store.events(subscription_id))
    assert errors == ['HTTP 410: {"ok": false}'] + ["subscription disabled"] * 2
    assert gateway.count("wz_gateway_webhook_events_total", state="failed") == 3


def test_an_event_not_delivered_within_its_time_to_live_expires(make_gateway: Any) -> None:
    gateway = make_gateway(
        webhook_event_ttl_s=2.0, webhook_backoff_base_s=0.1, webhook_backoff_cap_s=0.3
    )
    with Receiver(always(500)) as receiver:
        subscription_id, secret = gateway.subscribe(receiver.url)
        receiver.secrets = [secret]
        with gateway.delivering():
            created = time.monotonic()
            gateway.ingest(sample_alert("ttl-1", 1.0))
            eventually(
                lambda: gateway.states(subscription_id) == {"expired": 1}, "expiry", timeout_s=10.0
            )
            got = receiver.snapshot()
    assert len(got) >= 3 and all(r.verified for r in got)
    # None sent after its time to live (the last one may arrive a moment after sending).
    assert all(r.at - created < 2.0 + 0.05 for r in got)
    assert len({r.webhook_id for r in got}) == 1
    (event,) = gateway.store.events(subscription_id)
    assert event.attempts == len(got) and event.finished_at is not None
    assert gateway.count("wz_gateway_webhook_events_total", state="expired") == 1
    assert gateway.count("wz_gateway_webhook_attempts_total", result="5xx") == len(got)


def test_a_slow_receiver_does_not_hold_up_another(make_gateway: Any) -> None:
    gateway = make_gateway()
    slow_policy = always(204)
    with Receiver(lambda i, s: Answer(204, hold=True)) as slow, Receiver() as fast:
        slow_id, slow_secret = gateway.subscribe(slow.url)
        fast_id, fast_secret = gateway.subscribe(fast.url)
        slow.secrets, fast.secrets = [slow_secret], [fast_secret]
        alerts = [sample_alert(f"slow-{k}", float(k)) for k in range(5)]
        with gateway.delivering():
            gateway.ingest(*alerts)
            fast.wait_until(lambda r: len(r.delivered_ids()) == 5, "the fast receiver's five")
            assert len(slow.held()) == 1  # one request at a time to a receiver, still held
            assert gateway.states(slow_id) == {"pending": 5}
            slow.policy = slow_policy
            slow.release()
            slow.wait_until(lambda r: len(r.delivered_ids()) == 5, "the slow receiver's five")
            eventually(lambda: gateway.states(slow_id) == {"delivered": 5}, "all recorded")
    assert gateway.states(fast_id) == {"delivered": 5}
    assert (
        slow.delivered_ids()
        == fast.delivered_ids()
        == Counter(webhooks.alert_event_id(a) for a in alerts)
    )


def test_a_name_that_now_resolves_to_a_refused_address_is_not_called(make_gateway: Any) -> None:
    """DNS rebinding: the name was public when subscribed; at delivery it says loopback."""
    gateway = make_gateway(webhook_allowed_networks=[])

    def rebinding(host: str, port: int) -> list[str]:
        return ["127.0.0.1"] if host == "hooks.example.test" else resolve_host(host, port)

    with Receiver() as receiver:
        subscription_id, secret = gateway.subscribe(
            f"http://hooks.example.test:{receiver.port}/hooks/wz"
        )
        receiver.secrets = [secret]
        with gateway.delivering(resolve=rebinding):
            gateway.ingest(sample_alert("dns-1", 1.0))
            (event,) = eventually(
                lambda: [e for e in gateway.store.events(subscription_id) if e.attempts >= 1],
                "a refused attempt",
            )
        assert receiver.snapshot() == []
        assert event.state == "pending" and event.last_status_code is None
        assert "address refused" in str(event.last_error)
        assert "127.0.0.1 is a loopback address" in str(event.last_error)
        assert gateway.count("wz_gateway_webhook_attempts_total", result="error") >= 1

        # Allowed, the connection goes to the address checked; the request keeps the name.
        allowing = gateway.settings.model_copy(update={"webhook_allowed_networks": LOOPBACK})
        with gateway.delivering(resolve=rebinding, settings=allowing):
            receiver.wait_until(lambda r: len(r.delivered_ids()) == 1, "the delivery")
        (request,) = receiver.snapshot()
    assert request.headers["host"] == f"hooks.example.test:{receiver.port}" and request.verified


def test_an_event_claimed_by_a_process_that_died_is_sent_after_its_lease(make_gateway: Any) -> None:
    gateway = make_gateway(webhook_timeout_s=0.5, webhook_lease_s=1.5)
    with Receiver() as receiver:
        subscription_id, secret = gateway.subscribe(receiver.url)
        receiver.secrets = [secret]
        gateway.ingest(sample_alert("lease-1", 1.0))
        now, claimed_at = time.time(), time.monotonic()
        (claimed,) = gateway.store.claim(now, lease_until=now + 1.5, limit=4)  # then it "died"
        assert gateway.store.claim(now, lease_until=now + 1.5, limit=4) == []  # leased
        with gateway.delivering():
            receiver.wait_until(lambda r: len(r.requests) == 1, "the delivery after the lease")
            eventually(lambda: gateway.states(subscription_id) == {"delivered": 1}, "recorded")
        (request,) = receiver.snapshot()
    assert request.webhook_id == claimed.event_id and request.verified
    assert request.at >= claimed_at + 1.5 - 0.01  # not before the lease ran out


def test_a_receiver_down_for_30_s_gets_every_alert_exactly_once(make_gateway: Any) -> None:
    """The receiver's port refuses connections for 30 s while alerts keep coming; then it
    listens. Every alert arrives, answered 2xx exactly once per webhook-id; an id comes again
    only where the receiver answered it with an error (here: the first try of every fifth)."""
    gateway = make_gateway(webhook_backoff_base_s=0.5, webhook_backoff_cap_s=2.0)
    picky = {webhooks.alert_event_id(sample_alert(f"down-{k}", 0.0)) for k in range(0, 40, 5)}

    def answer(webhook_id: str, seen: int) -> Answer:
        return Answer(500) if webhook_id in picky and seen == 0 else Answer(200)

    receiver = Receiver(answer)  # not started: its port refuses connections
    subscription_id, secret = gateway.subscribe(receiver.url)
    receiver.secrets = [secret]
    alerts = [sample_alert(f"down-{k}", 0.5 * k) for k in range(40)]
    with gateway.delivering():
        down_at = time.monotonic()
        for k, alert in enumerate(alerts):  # over the outage: one alert each 0.7 s
            gateway.ingest(alert)
            time.sleep(max(0.0, down_at + 0.7 * (k + 1) - time.monotonic()))
        refused = gateway.count("wz_gateway_webhook_attempts_total", result="error")
        assert refused >= 40  # each alert was tried (and refused) at least once
        time.sleep(max(0.0, down_at + 30.0 - time.monotonic()))
        assert gateway.states(subscription_id) == {"pending": 40}
        with receiver:
            up_at = time.monotonic()
            receiver.wait_until(lambda r: len(r.delivered_ids()) == 40, "all 40 delivered")
            eventually(lambda: gateway.states(subscription_id) == {"delivered": 40}, "all recorded")
            got = receiver.snapshot()
    assert up_at - down_at >= 30.0
    expected = {webhooks.alert_event_id(a) for a in alerts}
    assert set(receiver.delivered_ids()) == expected
    assert all(n == 1 for n in receiver.delivered_ids().values())  # exactly once per id
    requests_per_id = Counter(r.webhook_id for r in got)
    errors_per_id = Counter(r.webhook_id for r in got if not r.ok)
    assert set(errors_per_id) == picky
    assert all(requests_per_id[i] == 1 + errors_per_id[i] for i in expected)
    assert all(r.verified for r in got)
    assert max(r.at for r in got) - up_at < 10.0  # backoff capped at 2 s: soon after it is up
    assert gateway.count("wz_gateway_webhook_events_total", state="delivered") == 40


def test_a_claim_takes_each_subscriptions_oldest_due_event_one_in_flight(make_gateway: Any) -> None:
    gateway = make_gateway()
    backlogged, _ = gateway.subscribe("http://127.0.0.1:9/a", event_types=("alert.speeding",))
    quiet, _ = gateway.subscribe("http://127.0.0.1:9/b", event_types=("alert.queue",))
    backlog = [sample_alert(f"backlog-{k}", float(k)) for k in range(100)]
    gateway.ingest(*backlog)
    gateway.ingest(sample_alert("quiet-1", 200.0, alert_type=AlertType.QUEUE, track_id=None))
    now = time.time()
    claimed = gateway.store.claim(now, lease_until=now + 30.0, limit=8)
    assert sorted(c.subscription_id for c in claimed) == sorted([backlogged, quiet])
    first = next(c for c in claimed if c.subscription_id == backlogged)
    assert first.event_id == webhooks.alert_event_id(backlog[0]) and first.attempts == 0
    # Both have a request in flight: nothing more until an attempt is recorded.
    assert gateway.store.claim(now, lease_until=now + 30.0, limit=8) == []
    delivered = webhooks.Outcome("delivered")
    gateway.store.record_attempt(
        first,
        attempt=1,
        attempted_at=now,
        status_code=204,
        error=None,
        duration_ms=1.0,
        outcome=delivered,
        now=now,
    )
    (second,) = gateway.store.claim(now, lease_until=now + 30.0, limit=8)
    assert second.event_id == webhooks.alert_event_id(backlog[1])
    assert (
        gateway.store.claim(now, lease_until=now + 30.0, limit=8, busy={second.subscription_row})
        == []
    )
    # A lease run out (its process died) frees the subscription and the row itself.
    later = now + 31.0
    again = gateway.store.claim(later, lease_until=later + 30.0, limit=8)
    assert sorted(c.event_id for c in again) == sorted(
        [second.event_id, webhooks.alert_event_id(sample_alert("quiet-1", 200.0))]
    )
