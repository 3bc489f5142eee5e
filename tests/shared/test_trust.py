"""wz_shared.trust: which source a key carries, and consumers that refuse the others.

The routers' side (access control by role, refused forgeries) is tested on network hosts in
tests/deploy/test_bus_trust.py; here, each consumer's own check, on real sessions.
"""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest

from tests.shared.samples import json_samples
from wz_shared.bus import Bus
from wz_shared.messages import Alert, TrackBatch
from wz_shared.settings import BusSettings
from wz_shared.trust import (
    ROLES,
    edge_access_control,
    expected_source,
    identity,
    parse_identity,
    regional_access_control,
    site_problem,
    source_problem,
)


@pytest.mark.parametrize(
    ("key", "source"),
    [
        ("wz/s/tracks", "fusion-tracker"),
        ("wz/s/alerts/speeding", "alert-service"),
        ("wz/s/devices/state", "alert-service"),
        ("wz/s/detections/lidar-mast", "lidar-mast"),
        ("wz/s/raw/camera/cam-1", "cam-1"),
        ("wz/s/points/speed-1", "speed-1"),
        ("wz/s/status/gateway", "gateway"),
        ("wz/s/tracks/latest", None),
        ("wz/s/alerts/active", "alert-service"),
        ("other/s/tracks", None),
    ],
)
def test_each_key_names_its_source(key: str, source: str | None) -> None:
    assert expected_source(key) == source


def test_a_message_from_another_source_is_a_problem() -> None:
    assert source_problem("wz/s/tracks", "fusion-tracker") is None
    assert "fusion-tracker" in str(source_problem("wz/s/tracks", "laptop"))
    assert source_problem("wz/s/detections/lidar-mast", "camera-mast") is not None
    assert source_problem("wz/s/tracks/latest", "anyone") is None


def test_every_role_gives_its_own_status_and_only_the_tracker_tracks() -> None:
    acl = edge_access_control("s", 1)
    gives = {rule["id"]: set(rule["key_exprs"]) for rule in acl["rules"]}
    for role in ROLES:
        assert f"wz/s/status/{role}" in gives[f"{role}: gives"]
    assert [r for r in ROLES if "wz/s/tracks" in gives[f"{r}: gives"]] == ["fusion-tracker"]
    assert [r for r in ROLES if "wz/s/alerts/*" in gives[f"{r}: gives"]] == ["alert-service"]


def test_a_certificate_names_its_role_site_and_generation() -> None:
    assert identity("alert-service", "us75-lincoln", 2) == "alert-service@us75-lincoln#2"
    assert parse_identity("alert-service@us75-lincoln#2") == ("alert-service", "us75-lincoln", 2)
    for other in ("alert-service", "regional-router", "a@b", "a@b#0", "a@b#x", "a@b/c#1"):
        assert parse_identity(other) is None, other
    with pytest.raises(ValueError, match="counts from 1"):
        identity("gateway", "s", 0)


def test_a_site_access_control_names_its_own_identities_and_keys_only() -> None:
    """Site s's router: every subject is an identity of s's current generation (or the
    regional router), every key is under wz/s/ (or the router's admin space)."""
    acl = edge_access_control("s", 3)
    names = [name for subject in acl["subjects"] for name in subject["cert_common_names"]]
    assert "regional-router" in names
    for name in names:
        if name != "regional-router":
            parsed = parse_identity(name)
            assert parsed is not None and parsed[1:] == ("s", 3), name
    assert "alert-service@t#3" not in names and "alert-service@s#2" not in names
    for rule in acl["rules"]:
        for key in rule["key_exprs"]:
            # Only interest (subscriptions, queries) may name any site.
            interest = rule["id"] in ("take: interest", "take: others' interest")
            assert key.startswith("wz/s/") or key == "@/**" or interest, key
    regional = regional_access_control({"s": 3, "t": 1})
    trailers = {s["id"]: s["cert_common_names"] for s in regional["subjects"]}
    assert trailers["trailer s"] == ["router@s#3"] and trailers["trailer t"] == ["router@t#1"]
    gives = {rule["id"]: rule["key_exprs"] for rule in regional["rules"]}
    assert all(k.startswith("wz/t/") for k in gives["trailer t: gives"])


def test_a_message_naming_another_site_than_its_key_is_a_problem() -> None:
    assert site_problem("wz/a/alerts/speeding", "a") is None
    assert "site a's, not b's" in str(site_problem("wz/a/alerts/speeding", "b"))
    assert site_problem("other/a/x", "b") is None


@pytest.fixture
def pair(listening_bus_settings: BusSettings, port: int) -> Iterator[tuple[Bus, Bus]]:
    with (
        Bus.open(listening_bus_settings, site="test-site", service="consumer") as consumer,
        Bus.open(
            BusSettings(connect_endpoints=[f"tcp/127.0.0.1:{port}"], listen_endpoints=[]),
            site="test-site",
            service="producer",
        ) as producer,
    ):
        yield consumer, producer


def test_consumers_refuse_a_track_batch_or_alert_from_another_source(
    pair: tuple[Bus, Bus],
) -> None:
    consumer, producer = pair
    batches = consumer.subscribe(consumer.keys.tracks, TrackBatch)
    called: list[Alert] = []
    consumer.on(consumer.keys.alerts_all, Alert, lambda _key, alert: called.append(alert))
    tracks = producer.publisher(producer.keys.tracks, TrackBatch)
    alerts = producer.publisher(producer.keys.alerts("speeding"), Alert)
    assert tracks.wait_for_subscribers(10.0) and alerts.wait_for_subscribers(10.0)
    batch = next(m for m in json_samples() if isinstance(m, TrackBatch))
    alert = next(m for m in json_samples() if isinstance(m, Alert))
    tracks.put(batch.model_copy(update={"source_id": "laptop"}))
    tracks.put(batch)
    alerts.put(alert.model_copy(update={"source_id": "fusion-tracker"}))
    alerts.put(alert)
    received = batches.recv(10.0)
    deadline = time.monotonic() + 10.0
    while not called and time.monotonic() < deadline:
        time.sleep(0.05)
    assert received is not None and received.source_id == "fusion-tracker"
    assert batches.recv(0.5) is None
    assert [a.source_id for a in called] == ["alert-service"]
    # Right source, wrong site: a batch of site "elsewhere" on this site's key.
    tracks.put(batch.model_copy(update={"site": "elsewhere"}))
    tracks.put(batch)
    assert batches.recv(10.0) is not None
    assert batches.recv(0.5) is None
    assert dict(consumer.stats.invalid) == {
        (consumer.keys.tracks, "wrong_source"): 1,
        (consumer.keys.alerts_all, "wrong_source"): 1,
        (consumer.keys.tracks, "wrong_site"): 1,
    }
