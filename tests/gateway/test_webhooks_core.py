"""The webhooks' pure core: signatures (against the specification's example and the reference
library), event ids and bodies, filters, the backoff schedule, Retry-After, the outcome of an
attempt, expiry, and which addresses are refused (SSRF)."""

from __future__ import annotations

import base64
import datetime
import ipaddress
import json
import random
import statistics
from email.utils import format_datetime

import pytest
from standardwebhooks.webhooks import Webhook, WebhookVerificationError

from tests.gateway.helpers import sample_alert
from tests.purity import top_level_imports
from wz_gateway import webhooks
from wz_gateway.webhooks import (
    AddressPolicy,
    RefusedDestinationError,
    RetryPolicy,
    SubscriptionFilter,
    address_class,
    backoff_ceiling_s,
    backoff_s,
    check_addresses,
    decide,
    parse_destination,
    parse_retry_after,
)
from wz_shared.messages import AlertSeverity, AlertType

NOW = 1_750_000_000.0
POLICY = RetryPolicy(backoff_base_s=1.0, backoff_cap_s=60.0, event_ttl_s=900.0)


def test_the_core_does_no_io() -> None:
    assert not top_level_imports(webhooks) & {
        "httpx",
        "httpcore",
        "socket",
        "sqlalchemy",
        "fastapi",
        "zenoh",
        "requests",
        "urllib3",
    }


# --- signatures ---------------------------------------------------------------------------


def test_signature_matches_the_specifications_example() -> None:
    # The example of the Standard Webhooks / Svix documentation and test suites.
    signature = webhooks.sign(
        "whsec_MfKQ9r8GKYqrTwjUPD8ILPZIo2LaLaSw",
        "msg_p5jXN8AQM9LWM0D4loKWxJek",
        1614265330,
        '{"test": 2432232314}',
    )
    assert signature == "v1,g0hM9SsE+OTPJTGt/tmIKtSyZlE3uFJELVlNIOLJ1OE="


def test_headers_verify_with_the_reference_library_and_fail_when_tampered() -> None:
    secret = webhooks.new_secret()
    assert secret.startswith("whsec_")
    assert len(base64.b64decode(secret.removeprefix("whsec_"))) == webhooks.SECRET_KEY_BYTES
    event = webhooks.alert_event(sample_alert("hdr-1", 3.0), NOW)
    now_s = int(datetime.datetime.now(datetime.UTC).timestamp())
    headers = webhooks.delivery_headers([secret], event.event_id, now_s, event.body)
    assert headers["webhook-id"] == event.event_id
    assert headers["webhook-timestamp"] == str(now_s)
    assert Webhook(secret).verify(event.body, headers)["type"] == "alert.speeding"
    with pytest.raises(WebhookVerificationError):
        Webhook(secret).verify(event.body.replace("speeding", "queue"), headers)
    with pytest.raises(WebhookVerificationError):
        Webhook(webhooks.new_secret()).verify(event.body, headers)
    with pytest.raises(WebhookVerificationError):  # a replayed old timestamp
        old = webhooks.delivery_headers([secret], event.event_id, now_s - 3600, event.body)
        Webhook(secret).verify(event.body, old)


def test_during_a_rotation_each_secret_verifies() -> None:
    old, new = webhooks.new_secret(), webhooks.new_secret()
    now_s = int(datetime.datetime.now(datetime.UTC).timestamp())
    headers = webhooks.delivery_headers([new, old], "msg_1", now_s, "{}")
    assert len(headers["webhook-signature"].split(" ")) == 2
    for secret in (old, new):
        Webhook(secret).verify("{}", headers)


@pytest.mark.parametrize("secret", ["MfKQ9r8GKYqrTwjUPD8ILPZIo2LaLaSw", "whsec_", "whsec_%%%"])
def test_a_secret_that_is_not_whsec_base64_is_refused(secret: str) -> None:
    with pytest.raises(ValueError, match="secret"):
        webhooks.secret_key(secret)


# --- events -------------------------------------------------------------------------------


def test_an_alert_event_has_a_stable_id_and_the_alert_as_data() -> None:
    alert = sample_alert("ep-7-2", 12.5, severity=AlertSeverity.CRITICAL, phase="update")
    event = webhooks.alert_event(alert, NOW)
    again = webhooks.alert_event(alert.model_copy(), NOW + 60.0)  # received again, later
    assert again.event_id == event.event_id
    assert webhooks.alert_event(sample_alert("ep-7-3", 12.5), NOW).event_id != event.event_id
    assert event.event_id.startswith("msg_") and len(event.event_id) <= 64
    body = json.loads(event.body)
    assert body["type"] == event.event_type == "alert.speeding"
    assert body["timestamp"] == "2025-06-15T15:06:40.000Z"
    assert body["data"] == alert.model_dump(mode="json")
    assert body["data"]["site"] == alert.site and body["data"]["phase"] == "update"
    assert event.body.isascii()  # the bytes sent are the string signed


def test_filters_by_type_severity_and_phase() -> None:
    speeding = sample_alert("f1", 1.0)  # warning, start
    queue = sample_alert(
        "f2", 1.0, alert_type=AlertType.QUEUE, severity=AlertSeverity.INFO, phase="clear"
    )
    everything = SubscriptionFilter(("alert.*",))
    assert everything.matches(speeding) and everything.matches(queue)
    assert not SubscriptionFilter(("alert.queue",)).matches(speeding)
    assert SubscriptionFilter(("alert.queue", "alert.speeding")).matches(speeding)
    warning_up = SubscriptionFilter(("alert.*",), min_severity=AlertSeverity.WARNING)
    assert warning_up.matches(speeding) and not warning_up.matches(queue)
    starts = SubscriptionFilter(("alert.*",), phases=("start", "update"))
    assert starts.matches(speeding) and not starts.matches(queue)


def test_event_types_are_checked() -> None:
    assert webhooks.normalize_event_types(["alert.queue", "alert.queue", "alert.*"]) == [
        "alert.queue",
        "alert.*",
    ]
    with pytest.raises(ValueError, match=r"unknown event type 'alert\.speed'"):
        webhooks.normalize_event_types(["alert.speed"])
    with pytest.raises(ValueError, match="at least one"):
        webhooks.normalize_event_types([])


# --- backoff, Retry-After, outcome, expiry -------------------------------------------------


def test_backoff_ceiling_doubles_up_to_the_cap() -> None:
    ceilings = [backoff_ceiling_s(n, POLICY) for n in range(1, 10)]
    assert ceilings == [1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 60.0, 60.0, 60.0]
    assert backoff_ceiling_s(10_000, POLICY) == 60.0  # no overflow


def test_full_jitter_is_uniform_below_the_ceiling_and_seeded() -> None:
    draws = [backoff_s(4, POLICY, random.Random(7)) for _ in range(3)]
    assert draws[0] == draws[1] == draws[2]  # the same seed, the same schedule
    rng = random.Random(11)
    samples = [backoff_s(4, POLICY, rng) for _ in range(20_000)]
    assert min(samples) >= 0.0 and max(samples) <= 8.0
    # Uniform on [0, 8]: mean 4, standard deviation 8 / sqrt(12) = 2.309.
    assert statistics.fmean(samples) == pytest.approx(4.0, abs=0.05)
    assert statistics.pstdev(samples) == pytest.approx(8.0 / 12**0.5, abs=0.05)


@pytest.mark.parametrize(
    ("header", "expected_s"),
    [
        ("120", 120.0),
        (" 0 ", 0.0),
        (
            format_datetime(datetime.datetime.fromtimestamp(NOW + 90.0, datetime.UTC), usegmt=True),
            90.0,
        ),
        ("Sun, 15 Jun 2025 15:04:10 GMT", 0.0),  # in the past: at once
        ("Sun, 15 Jun 2025 15:07:10 -0000", 30.0),
        ("-5", None),
        ("1.5", None),
        ("soon", None),
        ("", None),
        (None, None),
    ],
)
def test_retry_after_in_seconds_or_as_an_http_date(
    header: str | None, expected_s: float | None
) -> None:
    assert parse_retry_after(header, NOW) == expected_s


def _decide(
    status: int | None,
    attempt: int = 1,
    retry_after: str | None = None,
    created_at: float = NOW,
    now: float = NOW,
    seed: int = 3,
) -> webhooks.Outcome:
    return decide(
        attempt=attempt,
        status_code=status,
        retry_after=retry_after,
        created_at=created_at,
        now=now,
        policy=POLICY,
        rng=random.Random(seed),
    )


@pytest.mark.parametrize("status", [200, 201, 202, 204, 299])
def test_2xx_is_delivered(status: int) -> None:
    assert _decide(status).state == "delivered"


def test_410_fails_the_event_and_disables_the_subscription() -> None:
    outcome = _decide(410)
    assert outcome.state == "failed" and outcome.disable_subscription


@pytest.mark.parametrize("status", [None, 301, 400, 404, 429, 500, 502, 503])
def test_other_answers_are_retried_within_the_backoff(status: int | None) -> None:
    for attempt in (1, 3, 8):
        outcome = _decide(status, attempt=attempt)
        ceiling = backoff_ceiling_s(attempt, POLICY)
        expected = NOW + random.Random(3).uniform(0.0, ceiling)
        assert outcome.state == "pending" and not outcome.disable_subscription
        assert outcome.next_attempt_at == pytest.approx(expected, abs=1e-9)


@pytest.mark.parametrize("status", [429, 503])
def test_retry_after_is_honoured_on_429_and_503(status: int) -> None:
    outcome = _decide(status, retry_after="45")
    assert outcome.state == "pending" and outcome.next_attempt_at == NOW + 45.0
    assert outcome.defer_subscription_until == NOW + 45.0
    ignored = _decide(500, retry_after="45")  # only 429 and 503 carry it by the RFC
    assert ignored.next_attempt_at is not None and ignored.next_attempt_at <= NOW + 1.0
    assert ignored.defer_subscription_until is None


def test_an_event_expires_rather_than_being_retried_after_its_time_to_live() -> None:
    created = NOW - 890.0  # 10 s left of 900
    assert _decide(500, retry_after="5", created_at=created).state == "pending"
    assert _decide(429, retry_after="11", created_at=created).state == "expired"
    late = _decide(500, attempt=30, created_at=created)  # a draw from [0, 60] s
    assert late.state == ("expired" if random.Random(3).uniform(0, 60) >= 10.0 else "pending")
    assert _decide(204, created_at=NOW - 10_000.0).state == "delivered"  # an answer is an answer
    assert not webhooks.is_expired(NOW, NOW + 899.9, POLICY)
    assert webhooks.is_expired(NOW, NOW + 900.0, POLICY)


# --- addresses (SSRF) ---------------------------------------------------------------------


@pytest.mark.parametrize(
    ("address", "kind"),
    [
        ("127.0.0.1", "loopback"),
        ("127.255.0.9", "loopback"),
        ("::1", "loopback"),
        ("10.1.2.3", "private"),
        ("172.16.0.1", "private"),
        ("192.168.1.10", "private"),
        ("fc00::1", "private"),
        ("fd12:3456::1", "private"),
        ("169.254.169.254", "link-local"),  # cloud metadata
        ("fe80::1", "link-local"),
        ("224.0.0.1", "multicast"),
        ("ff02::1", "multicast"),
        ("0.0.0.0", "unspecified"),
        ("::", "unspecified"),
        ("240.0.0.1", "reserved"),
        ("100.64.0.1", "not globally routable"),  # carrier-grade NAT
        ("::ffff:127.0.0.1", "loopback"),  # IPv4-mapped
        ("::ffff:10.0.0.1", "private"),
        ("::ffff:169.254.169.254", "link-local"),
        ("2002:7f00:1::", "loopback"),  # 6to4 of 127.0.0.1
        ("64:ff9b::a00:1", "private"),  # NAT64 of 10.0.0.1
        ("8.8.8.8", None),
        ("93.184.215.14", None),
        ("2606:4700:4700::1111", None),
        ("::ffff:8.8.8.8", None),
        ("64:ff9b::808:808", None),  # NAT64 of 8.8.8.8 (DNS64 on an IPv6-only network)
        ("255.255.255.255", "reserved"),
    ],
)
def test_address_classes(address: str, kind: str | None) -> None:
    assert address_class(ipaddress.ip_address(address)) == kind


def test_the_policy_allows_networks_loopback_or_every_unicast_address() -> None:
    strict = AddressPolicy()
    ip = ipaddress.ip_address
    assert strict.refusal(ip("8.8.8.8")) is None
    assert strict.refusal(ip("10.20.1.5")) == "10.20.1.5 is a private address"
    site_lan = AddressPolicy(allowed_networks=(ipaddress.ip_network("10.20.0.0/16"),))
    assert site_lan.refusal(ip("10.20.1.5")) is None
    assert site_lan.refusal(ip("::ffff:10.20.1.5")) is None  # the same host, IPv4-mapped
    assert site_lan.refusal(ip("10.21.0.1")) is not None
    dev = AddressPolicy(allow_loopback=True)
    assert dev.refusal(ip("127.0.0.1")) is None and dev.refusal(ip("::1")) is None
    assert dev.refusal(ip("192.168.0.2")) is not None
    closed = AddressPolicy(allow_private=True)
    assert closed.refusal(ip("192.168.0.2")) is None and closed.refusal(ip("127.0.0.1")) is None
    assert closed.refusal(ip("224.0.0.1")) is not None and closed.refusal(ip("0.0.0.0")) is not None


def test_every_address_a_host_resolves_to_must_be_allowed() -> None:
    check_addresses("hooks.example.com", ["93.184.215.14", "2606:2800:21f::1"], AddressPolicy())
    with pytest.raises(RefusedDestinationError, match=r"resolves to 10\.0\.0\.7 is a private"):
        check_addresses("rebind.example.com", ["93.184.215.14", "10.0.0.7"], AddressPolicy())
    with pytest.raises(RefusedDestinationError, match="no address"):
        check_addresses("nothing.example.com", [], AddressPolicy())


@pytest.mark.parametrize(
    ("url", "message"),
    [
        ("ftp://hooks.example.com/x", "http:// or https://, not ftp"),
        ("file:///etc/passwd", "http:// or https://, not file"),
        ("javascript:alert(1)", "http:// or https://, not javascript"),
        ("hooks.example.com/x", "http:// or https://, not none"),
        ("http:///x", "no host"),
        ("https://user:pw@hooks.example.com/x", "no user or password"),
        ("http://hooks.example.com:99999/x", "not a valid URL"),
    ],
)
def test_urls_other_than_plain_http_or_https_are_refused(url: str, message: str) -> None:
    with pytest.raises(RefusedDestinationError, match=message):
        parse_destination(url)


def test_destinations_get_their_default_ports() -> None:
    assert parse_destination("https://Hooks.Example.com/a?b=1") == webhooks.Destination(
        "https", "hooks.example.com", 443
    )
    assert parse_destination("http://[2606:4700::1111]:8080/") == webhooks.Destination(
        "http", "2606:4700::1111", 8080
    )
