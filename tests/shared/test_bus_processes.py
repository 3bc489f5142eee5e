"""Two real processes over Zenoh on loopback: exact counts, frames, rings, bad input."""

from __future__ import annotations

import contextlib
import subprocess
import sys
import time
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from tests.shared.samples import json_samples, lidar_frame
from wz_shared.bus import Bus
from wz_shared.messages import JSON_MESSAGES, Alert, CameraFrameMeta, LidarFrameMeta
from wz_shared.settings import BusSettings

ROOT = Path(__file__).resolve().parents[2]
SITE = "test-site"


@pytest.fixture
def bus(listening_bus_settings: BusSettings) -> Iterator[Bus]:
    with Bus.open(listening_bus_settings, site=SITE, service="bus-test") as opened:
        yield opened


def start_peer(port: int, *args: str, stdout: int | None = None) -> subprocess.Popen[bytes]:
    return subprocess.Popen(
        [sys.executable, "-m", "tests.shared.bus_peer", f"tcp/127.0.0.1:{port}", *args],
        cwd=ROOT,
        stdout=stdout,
    )


def finish_peer(bus: Bus, peer: subprocess.Popen[bytes]) -> None:
    """Acknowledge, then require the peer to exit cleanly."""
    ack = bus.publisher(f"{bus.keys.prefix}/test/ack", Alert)
    deadline = time.monotonic() + 20.0
    while peer.poll() is None and time.monotonic() < deadline:
        ack.put_bytes(b"ack")
        with contextlib.suppress(subprocess.TimeoutExpired):
            peer.wait(0.2)
    if peer.poll() is None:
        peer.kill()
    assert peer.wait() == 0


def wait_for(items: list[str], count: int, deadline: float) -> None:
    while len(items) < count and time.monotonic() < deadline:
        time.sleep(0.05)


def ask_for_more(bus: Bus, items: list[str], count: int, deadline: float) -> None:
    """Tell the ``history`` peer to publish its live alerts; wait until ``count`` are in."""
    more = bus.publisher(f"{bus.keys.prefix}/test/more", Alert)
    assert more.wait_for_subscribers(10.0)
    more.put_bytes(b"more")
    wait_for(items, count, deadline)


def test_every_message_type_between_processes(bus: Bus, port: int) -> None:
    count = 25
    subscriptions = {
        kind: bus.subscribe(f"{bus.keys.prefix}/test/{kind}", cls)
        for kind, cls in JSON_MESSAGES.items()
    }
    lidar = bus.subscribe_frames(
        bus.keys.raw_lidar("lidar-mast"), LidarFrameMeta, mode="fifo", capacity=64
    )
    camera = bus.subscribe_frames(
        bus.keys.raw_camera("camera-mast"), CameraFrameMeta, mode="fifo", capacity=64
    )
    peer = start_peer(port, "all", str(count))
    received: Counter[str] = Counter()
    for kind, sub in subscriptions.items():
        for i in range(count):
            message = sub.recv(15.0)
            assert message is not None, f"{kind}: only {i} of {count} arrived"
            assert message == next(m for m in json_samples(i) if m.kind == kind)
            received[kind] += 1
    for i in range(count):
        frame = lidar.recv(15.0)
        assert frame is not None and frame.meta.frame_index == i
        np.testing.assert_array_equal(frame.points(), lidar_frame(i, 256)[1])
        image = camera.recv(15.0)
        assert image is not None and image.meta.frame_index == i
        received["lidar_frame"] += 1
        received["camera_frame"] += 1
    finish_peer(bus, peer)
    # Exactly count of each: nothing extra arrived after the last expected message.
    assert all(sub.recv(0.2) is None for sub in subscriptions.values())
    assert lidar.recv(0.0) is None and camera.recv(0.0) is None
    assert received == Counter(
        {kind: count for kind in [*JSON_MESSAGES, "lidar_frame", "camera_frame"]}
    )
    assert not bus.stats.invalid


def test_2mb_frames_at_20hz_fifo_lossless(bus: Bus, port: int) -> None:
    count, points = 60, 131_072  # 131072 points x 16 bytes = 2 MiB per frame, 3 s at 20 Hz
    frames = bus.subscribe_frames(
        bus.keys.raw_lidar("lidar-mast"), LidarFrameMeta, mode="fifo", capacity=8
    )
    peer = start_peer(port, "frames", str(count), "20", str(points), "1")
    indices = []
    for _ in range(count):
        frame = frames.recv(20.0)
        assert frame is not None, f"only {len(indices)} of {count} frames arrived"
        assert frame.points().shape == (points, 4)
        indices.append(frame.meta.frame_index)
    finish_peer(bus, peer)
    assert indices == list(range(count))
    assert frames.recv(0.2) is None
    assert not bus.stats.dropped


def test_slow_consumer_on_ring_gets_newest_frame(bus: Bus, port: int) -> None:
    count = 40
    ring = bus.subscribe_frames(
        bus.keys.raw_lidar("lidar-mast"), LidarFrameMeta, mode="ring", capacity=1
    )
    peer = start_peer(port, "frames", str(count), "50", "4096", "0")
    seen: list[int] = []
    while not seen or seen[-1] < count - 1:
        frame = ring.recv(20.0)
        assert frame is not None, f"ring stalled after {seen}"
        seen.append(frame.meta.frame_index)
        time.sleep(0.1)  # the consumer is 5x slower than the 50 Hz producer
    finish_peer(bus, peer)
    assert seen == sorted(seen)
    assert seen[-1] == count - 1  # the newest frame, not a backlog
    assert len(seen) < count / 2
    key = bus.keys.raw_lidar("lidar-mast")
    assert bus.stats.dropped[key] + len(seen) == bus.stats.received[key] == count


def test_malformed_payloads_counted_and_dropped(bus: Bus, port: int) -> None:
    alerts = bus.subscribe(bus.keys.alerts_all, Alert)
    frames = bus.subscribe_frames(
        bus.keys.raw_lidar("lidar-mast"), LidarFrameMeta, mode="fifo", capacity=16
    )
    peer = start_peer(port, "malformed")
    good_alerts = [alerts.recv(15.0), alerts.recv(15.0)]
    good_frames = [frames.recv(15.0), frames.recv(15.0)]
    finish_peer(bus, peer)
    assert all(isinstance(a, Alert) for a in good_alerts)
    assert [f.meta.frame_index for f in good_frames if f is not None] == [7, 7]
    invalid = {reason: n for (_, reason), n in bus.stats.invalid.items()}
    assert invalid == {
        "bad_json": 1,
        "schema_version": 1,
        "invalid": 1,
        "oversize": 1,
        "truncated": 2,
    }
    # And the subscriber keeps receiving after them.
    assert alerts.recv(0.2) is None


def test_a_late_subscriber_with_recovery_gets_the_history_then_the_live_samples(
    bus: Bus, port: int
) -> None:
    """Alerts published before anyone subscribed reach a ``recover=True`` subscription from the
    publisher's history (store and forward), once each; a plain one sees only the live ones."""
    peer = start_peer(port, "history", "40", stdout=subprocess.PIPE)
    assert peer.stdout is not None
    assert peer.stdout.readline().strip() == b"published"
    recovered: list[str] = []
    plain: list[str] = []
    bus.on(bus.keys.alerts_all, Alert, lambda _, a: recovered.append(a.alert_id), recover=True)
    bus.on(bus.keys.alerts_all, Alert, lambda _, a: plain.append(a.alert_id))
    deadline = time.monotonic() + 15.0
    wait_for(recovered, 40, deadline)
    assert recovered == [f"early-{i}" for i in range(40)]
    ask_for_more(bus, recovered, 80, deadline)
    finish_peer(bus, peer)
    assert recovered == [f"early-{i}" for i in range(40)] + [f"live-{i}" for i in range(40)]
    assert plain == [f"live-{i}" for i in range(40)]
    assert not bus.stats.invalid and not bus.stats.gaps


def test_a_gap_zenoh_gave_up_on_is_filled_from_the_publishers_cache(bus: Bus, port: int) -> None:
    """Zenoh's recovery reports a gap it gave up on (its query ended without the samples: a
    race after a link cut that no loopback test provokes at will, so the report is made here
    by hand, as Zenoh makes it). The subscription fetches the named publisher's whole cache:
    every alert reaches the callback again, the gap is counted, and nothing is counted
    invalid; a gap named after a publisher that does not exist fetches nothing."""
    peer = start_peer(port, "history", "40", stdout=subprocess.PIPE)
    assert peer.stdout is not None
    assert peer.stdout.readline().strip() == b"published"
    received: list[str] = []
    subscription = bus.on(
        bus.keys.alerts_all, Alert, lambda _, a: received.append(a.alert_id), recover=True
    )
    early = [f"early-{i}" for i in range(40)]
    deadline = time.monotonic() + 15.0
    wait_for(received, 40, deadline)
    assert received == early
    # the publisher as Zenoh names it in a miss: its session's id and its entity id, read
    # from the liveliness token it declares (zenoh-ext: <key>/@adv/pub/<zid>/<eid>/...)
    (token,) = [
        str(reply.ok.key_expr)
        for reply in bus.session.liveliness().get(
            f"{bus.keys.prefix}/alerts/*/@adv/pub/**", timeout=5.0
        )
        if reply.ok is not None
    ]
    zid, eid = token.split("/@adv/pub/")[1].split("/")[:2]
    stranger = SimpleNamespace(zid="0" * 32, eid=int(eid))
    subscription._on_miss(SimpleNamespace(nb=3, source=stranger))  # no such publisher
    subscription._on_miss(SimpleNamespace(nb=3, source=SimpleNamespace(zid=zid, eid=int(eid))))
    wait_for(received, 80, deadline)
    time.sleep(0.5)  # nothing more comes
    assert received == early + early
    assert bus.stats.gaps == {bus.keys.alerts_all: 2}
    ask_for_more(bus, received, 120, deadline)
    finish_peer(bus, peer)
    assert received[80:] == [f"live-{i}" for i in range(40)]
    assert not bus.stats.invalid
