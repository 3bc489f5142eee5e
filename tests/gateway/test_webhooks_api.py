"""The webhook subscriptions over HTTP (a real uvicorn server): make, list, get, test, rotate,
delete; private addresses, other schemes and missing admin keys refused; the secret of the
answer verifies what is delivered, before and after a rotation."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx
import pytest

from tests.gateway.helpers import ADMIN_KEY, READ_KEY, gateway_settings, live_server, open_storage
from tests.gateway.webhook_receiver import Receiver
from wz_gateway.delivery import WebhookDeliverer
from wz_gateway.settings import GatewaySettings
from wz_gateway.storage import Storage
from wz_gateway.webhook_store import WebhookStore

ADMIN = {"X-API-Key": ADMIN_KEY}
READ = {"X-API-Key": READ_KEY}
PROBLEM = "application/problem+json"
PUBLIC_URL = "http://93.184.215.14/hooks"  # an address literal: no DNS needed


@pytest.fixture(scope="module")
def http(tmp_path_factory: pytest.TempPathFactory) -> Iterator[httpx.Client]:
    """One gateway for the tests that only ask and are refused."""
    with gateway(tmp_path_factory.mktemp("webhooks-api")) as (http, _, _settings):
        yield http


@contextmanager
def gateway(
    tmp_path: Path, **overrides: Any
) -> Iterator[tuple[httpx.Client, Storage, GatewaySettings]]:
    settings = gateway_settings(tmp_path, **overrides)
    storage = open_storage(settings)
    try:
        with (
            live_server(settings, storage) as base_url,
            httpx.Client(base_url=base_url, timeout=10.0) as http,
        ):
            yield http, storage, settings
    finally:
        storage.close()


def test_a_subscription_is_made_listed_tested_rotated_and_deleted(tmp_path: Path) -> None:
    with gateway(tmp_path) as (http, _, settings):
        made = http.post(
            "/v1/webhooks",
            headers=ADMIN,
            json={
                "url": PUBLIC_URL,
                "event_types": ["alert.speeding", "alert.queue"],
                "min_severity": "warning",
                "phases": ["start", "update"],
                "description": "traffic management centre",
            },
        )
        assert made.status_code == 201, made.text
        created = made.json()
        subscription_id, secret = created.pop("subscription_id"), created.pop("secret")
        assert secret.startswith("whsec_") and subscription_id.startswith("wh_")
        assert created == {
            "url": PUBLIC_URL,
            "event_types": ["alert.speeding", "alert.queue"],
            "min_severity": "warning",
            "phases": ["start", "update"],
            "description": "traffic management centre",
            "created_at": pytest.approx(time.time(), abs=30),
            "disabled_at": None,
            "disabled_reason": None,
            "previous_secret_until": None,
        }

        listed = http.get("/v1/webhooks", headers=ADMIN).json()
        assert [w["subscription_id"] for w in listed] == [subscription_id]
        one = http.get(f"/v1/webhooks/{subscription_id}", headers=ADMIN).json()
        assert one == listed[0] and "secret" not in one and secret not in json.dumps(listed)
        default = http.post("/v1/webhooks", headers=ADMIN, json={"url": PUBLIC_URL}).json()
        assert default["event_types"] == ["alert.*"] and default["phases"] is None

        queued = http.post(f"/v1/webhooks/{subscription_id}/test", headers=ADMIN)
        assert queued.status_code == 202
        test_event = queued.json()
        assert test_event["event_type"] == "webhook.test"
        events = http.get(f"/v1/webhooks/{subscription_id}/events", headers=ADMIN).json()
        assert [(e["event_id"], e["state"], e["attempts"]) for e in events] == [
            (test_event["event_id"], "pending", 0)
        ]

        rotated = http.post(f"/v1/webhooks/{subscription_id}/rotate-secret", headers=ADMIN)
        assert rotated.status_code == 200
        new_secret = rotated.json()["secret"]
        assert new_secret.startswith("whsec_") and new_secret != secret
        until = rotated.json()["previous_secret_until"]
        assert until == pytest.approx(time.time() + settings.webhook_secret_grace_s, abs=30)

        assert http.delete(f"/v1/webhooks/{subscription_id}", headers=ADMIN).status_code == 204
        for method, path in [
            ("GET", ""),
            ("DELETE", ""),
            ("POST", "/test"),
            ("POST", "/rotate-secret"),
            ("GET", "/events"),
        ]:
            gone = http.request(method, f"/v1/webhooks/{subscription_id}{path}", headers=ADMIN)
            assert gone.status_code == 404 and gone.headers["content-type"] == PROBLEM
            assert gone.json()["detail"] == f"no webhook subscription {subscription_id}"
        bad_id = http.get("/v1/webhooks/not-an-id", headers=ADMIN)
        assert bad_id.status_code == 422 and bad_id.json()["errors"][0]["location"] == (
            "path.subscription_id"
        )


@pytest.mark.parametrize(
    ("url", "reason"),
    [
        ("http://10.0.0.5/hook", "10.0.0.5 is a private address"),
        ("https://192.168.1.20:8443/hook", "192.168.1.20 is a private address"),
        ("http://169.254.169.254/latest/meta-data/", "169.254.169.254 is a link-local"),
        ("http://127.0.0.1:8000/v1/admin/api-keys", "127.0.0.1 is a loopback address"),
        ("http://localhost:8000/", "is a loopback address"),
        ("http://[::1]:8000/", "::1 is a loopback address"),
        ("http://[::ffff:127.0.0.1]/", "is a loopback address"),
        ("http://[fd00::5]/", "fd00::5 is a private address"),
        ("http://0.0.0.0:8000/", "0.0.0.0 is the unspecified address"),
        ("http://224.0.0.251/", "224.0.0.251 is a multicast address"),
    ],
)
def test_private_and_internal_addresses_are_refused(
    http: httpx.Client, url: str, reason: str
) -> None:
    answer = http.post("/v1/webhooks", headers=ADMIN, json={"url": url})
    assert answer.status_code == 422 and answer.headers["content-type"] == PROBLEM
    problem = answer.json()
    assert problem["errors"][0]["location"] == "body.url"
    assert reason in problem["detail"] and problem["detail"].startswith("body field 'url'")
    assert "WZ_GATEWAY_WEBHOOK_ALLOWED_NETWORKS" in problem["detail"]
    assert http.get("/v1/webhooks", headers=ADMIN).json() == []


@pytest.mark.parametrize(
    ("url", "reason"),
    [
        ("ftp://93.184.215.14/hook", "must be http:// or https://, not ftp"),
        ("file:///etc/passwd", "must be http:// or https://, not file"),
        ("gopher://93.184.215.14:70/_", "must be http:// or https://, not gopher"),
        ("93.184.215.14/hook", "must be http:// or https://"),
        ("https://admin:hunter2@93.184.215.14/hook", "no user or password"),
        ("http://no-such-host.invalid/hook", "does not resolve"),
        ("https://93.184.215.14/a hook", "should match pattern"),  # what OpenAPI states
        ("https://93.184.215.14/\x01", "should match pattern"),
        ("HTTP://\u0080", "should match pattern"),  # was a 500: getaddrinfo's idna codec
        ("http://" + "a" * 64 + ".example/hook", "does not resolve"),  # idna: label too long
        ("https://93.184.215.14/" + "h" * 2000, "at most 2000 characters"),
    ],
)
def test_other_schemes_credentials_and_unknown_hosts_are_refused(
    http: httpx.Client, url: str, reason: str
) -> None:
    answer = http.post("/v1/webhooks", headers=ADMIN, json={"url": url})
    assert answer.status_code == 422 and reason in answer.json()["detail"], answer.text


def test_unknown_event_types_and_filters_are_refused(http: httpx.Client) -> None:
    for body, location in [
        ({"url": PUBLIC_URL, "event_types": ["alert.speed"]}, "body.event_types"),
        ({"url": PUBLIC_URL, "event_types": []}, "body.event_types"),
        ({"url": PUBLIC_URL, "min_severity": "severe"}, "body.min_severity"),
        ({"url": PUBLIC_URL, "phases": ["begin"]}, "body.phases.0"),
        ({"url": PUBLIC_URL, "secret": "whsec_AAAA"}, "body.secret"),  # never chosen
    ]:
        answer = http.post("/v1/webhooks", headers=ADMIN, json=body)
        assert answer.status_code == 422, body
        assert answer.json()["errors"][0]["location"] == location


def test_every_webhook_route_needs_an_admin_key(tmp_path: Path) -> None:
    with gateway(tmp_path, dev_mode=True) as (http, _, _settings):  # dev mode: reads keyless
        made = http.post("/v1/webhooks", headers=ADMIN, json={"url": PUBLIC_URL}).json()
        routes = [
            ("POST", "/v1/webhooks"),
            ("GET", "/v1/webhooks"),
            ("GET", f"/v1/webhooks/{made['subscription_id']}"),
            ("DELETE", f"/v1/webhooks/{made['subscription_id']}"),
            ("POST", f"/v1/webhooks/{made['subscription_id']}/test"),
            ("POST", f"/v1/webhooks/{made['subscription_id']}/rotate-secret"),
            ("GET", f"/v1/webhooks/{made['subscription_id']}/events"),
        ]
        for method, path in routes:
            body = {"url": PUBLIC_URL} if method == "POST" and path == "/v1/webhooks" else None
            missing = http.request(method, path, json=body)
            assert missing.status_code == 401 and missing.headers["content-type"] == PROBLEM
            assert "an API key is needed" in missing.json()["detail"]
            read_only = http.request(method, path, json=body, headers=READ)
            assert read_only.status_code == 403, (method, path)
        assert [w["subscription_id"] for w in http.get("/v1/webhooks", headers=ADMIN).json()] == [
            made["subscription_id"]
        ]


def test_dev_mode_and_the_allowed_networks_let_local_receivers_in(tmp_path: Path) -> None:
    with gateway(tmp_path / "dev", dev_mode=True) as (http, _, _settings):
        assert (
            http.post(
                "/v1/webhooks", headers=ADMIN, json={"url": "http://127.0.0.1:9000/hook"}
            ).status_code
            == 201
        )
        assert (
            http.post(
                "/v1/webhooks", headers=ADMIN, json={"url": "http://10.0.0.5/hook"}
            ).status_code
            == 422
        )
    with gateway(tmp_path / "lan", webhook_allowed_networks=["10.20.0.0/16"]) as (http, _, _s):
        assert (
            http.post(
                "/v1/webhooks", headers=ADMIN, json={"url": "http://10.20.3.4:8080/hook"}
            ).status_code
            == 201
        )
        assert (
            http.post(
                "/v1/webhooks", headers=ADMIN, json={"url": "http://10.21.3.4/hook"}
            ).status_code
            == 422
        )
    with gateway(tmp_path / "closed", webhook_allow_private=True) as (http, _, _s):
        assert (
            http.post(
                "/v1/webhooks", headers=ADMIN, json={"url": "http://192.168.7.7/hook"}
            ).status_code
            == 201
        )


def test_the_secret_shown_once_verifies_deliveries_and_a_rotation_keeps_both(
    tmp_path: Path,
) -> None:
    with (
        Receiver() as receiver,
        gateway(
            tmp_path, webhook_allowed_networks=["127.0.0.0/8"], webhook_poll_interval_s=0.1
        ) as (http, storage, settings),
    ):
        made = http.post("/v1/webhooks", headers=ADMIN, json={"url": receiver.url}).json()
        subscription_id, first_secret = made["subscription_id"], made["secret"]
        deliverer = WebhookDeliverer(WebhookStore(storage.engine), settings)
        deliverer.start()
        try:
            receiver.secrets = [first_secret]
            http.post(f"/v1/webhooks/{subscription_id}/test", headers=ADMIN)
            receiver.wait_until(lambda r: len(r.requests) == 1, "the test event")
            second_secret = http.post(
                f"/v1/webhooks/{subscription_id}/rotate-secret", headers=ADMIN
            ).json()["secret"]
            http.post(f"/v1/webhooks/{subscription_id}/test", headers=ADMIN)
            receiver.wait_until(lambda r: len(r.requests) == 2, "the second test event")
            # The deliverer records a delivery after the receiver's answer: wait for that.
            deadline = time.monotonic() + 10.0
            events = http.get(f"/v1/webhooks/{subscription_id}/events", headers=ADMIN).json()
            while any(e["state"] == "pending" for e in events) and time.monotonic() < deadline:
                time.sleep(0.05)
                events = http.get(f"/v1/webhooks/{subscription_id}/events", headers=ADMIN).json()
        finally:
            deliverer.close()
        first, second = receiver.snapshot()
    assert [(e["state"], e["attempts"], e["last_status_code"]) for e in events] == [
        ("delivered", 1, 204)
    ] * 2
    assert first.verified and json.loads(first.body)["type"] == "webhook.test"
    assert json.loads(first.body)["data"]["subscription_id"] == subscription_id
    assert len(first.headers["webhook-signature"].split(" ")) == 1
    assert len(second.headers["webhook-signature"].split(" ")) == 2  # new and old secret
    for known in (first_secret, second_secret):  # a receiver that knows one of them
        one_secret = Receiver()
        one_secret.secrets = [known]
        assert one_secret.verifies(second.body, second.headers)
