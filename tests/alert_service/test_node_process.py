"""The alert service node as its own process on real Zenoh (two peers on loopback, multicast
off): a speeding car's track batches in, exactly one speeding start and then its clear out, the
beacon on and off again, the open episodes on query, bad input counted and the node alive."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

import pytest

from tests.alert_service.helpers import SITE, batch, make_track
from tests.alert_service.test_queues import reading
from wz_shared.bus import Bus, Subscription
from wz_shared.messages import (
    ActiveAlerts,
    Alert,
    AlertType,
    PointSensorReading,
    QueueState,
    RoadsideDeviceState,
    ServiceStatus,
    TrackBatch,
)
from wz_shared.settings import BusSettings
from wz_shared.site import MPH_TO_MPS

ROOT = Path(__file__).resolve().parents[2]
FAST_MPS = 55.0 * MPH_TO_MPS + 10.0 * MPH_TO_MPS  # 65 mph in the 55 mph zone: a warning
PERIOD_S = 0.1
T = TypeVar("T")


def wait_for(
    subscription: Subscription[T],
    condition: Callable[[T], bool],
    what: str,
    seen: list[T] | None = None,
    timeout_s: float = 20.0,
) -> T:
    """The first message that meets ``condition``; every message received is kept in ``seen``."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        message = subscription.recv(0.5)
        if message is None:
            continue
        if seen is not None:
            seen.append(message)
        if condition(message):
            return message
    pytest.fail(f"timed out after {timeout_s:.0f} s waiting for {what}")


def node_env(port: int, **extra: str) -> dict[str, str]:
    """The node's environment: this one's without any ``WZ_`` setting, connected to the test's
    bus on ``port``, its status every 0.2 s, and ``extra``."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("WZ_")}
    env.update(
        WZ_BUS_CONNECT_ENDPOINTS=f"tcp/127.0.0.1:{port}",
        WZ_BUS_LISTEN_ENDPOINTS="",
        WZ_STATUS_PERIOD_S="0.2",
        **extra,
    )
    return env


def speeder_batches(
    track_id: int, start_s: float, duration_s: float, first_cycle: int
) -> list[TrackBatch]:
    """A car at 65 mph from station 450 m, one batch every 0.1 s."""
    count = round(duration_s / PERIOD_S)
    return [
        batch(
            start_s + k * PERIOD_S,
            [make_track(track_id, 450.0 + FAST_MPS * k * PERIOD_S, FAST_MPS)],
            first_cycle + k,
        )
        for k in range(count)
    ]


def test_node_process_alerts_once_drives_the_beacon_and_survives_bad_input(port: int) -> None:
    settings = BusSettings(listen_endpoints=[f"tcp/127.0.0.1:{port}"], connect_endpoints=[])
    env = node_env(port, WZ_LOG_FORMAT="json", WZ_ALERT_EPISODE_ID_PREFIX="proc")
    with Bus.open(settings, site=SITE.site_id, service="node-test") as bus:
        tracks = bus.publisher(bus.keys.tracks, TrackBatch)
        alerts = bus.subscribe(bus.keys.alerts_all, Alert)
        devices = bus.subscribe(bus.keys.devices_state, RoadsideDeviceState)
        status = bus.subscribe(
            bus.keys.status("alert-service"), ServiceStatus, mode="ring", capacity=1
        )
        node = subprocess.Popen([sys.executable, "-m", "wz_alert_service.node"], cwd=ROOT, env=env)
        try:
            assert tracks.wait_for_subscribers(30.0), "the node never subscribed to the tracks"
            received: list[Alert] = []

            def speeding(phase: str, track_id: int) -> Callable[[Alert], bool]:
                return lambda a: (
                    a.alert_type is AlertType.SPEEDING
                    and a.phase == phase
                    and a.track_id == track_id
                )

            # 2 s of a speeder: the start comes after the 1 s hold, at the batch of 1.0 s.
            for message in speeder_batches(1, 0.0, 2.0, 0):
                tracks.put(message)
            start = wait_for(alerts, speeding("start", 1), "the speeding start", received)
            assert start.stamp == pytest.approx(1.0) and start.onset_stamp == pytest.approx(0.0)
            assert start.severity.value == "warning" and start.episode_id is not None
            assert start.episode_id.startswith("proc-speeding-1-")
            assert start.speed_mps == pytest.approx(FAST_MPS)
            off = wait_for(devices, lambda d: True, "the devices' first state")
            assert (off.beacon_on, off.sign_text, off.stamp) == (False, "", 0.0)
            on = wait_for(devices, lambda d: True, "the beacon on")
            assert (on.beacon_on, on.sign_text, on.cause) == (True, "SLOW DOWN", AlertType.SPEEDING)
            assert on.stamp == pytest.approx(1.0)

            # Late joiners ask: the open episodes as of the last batch (1.9 s).
            def asked() -> ActiveAlerts | None:
                replies = bus.query(bus.keys.alerts_active, ActiveAlerts, timeout_s=5.0)
                return replies[0] if replies and replies[0].stamp >= 1.9 - 1e-9 else None

            deadline = time.monotonic() + 10.0
            active = asked()
            while active is None and time.monotonic() < deadline:
                active = asked()
            assert active is not None, "no answer on alerts/active as of the last batch"
            assert start in active.alerts and active.devices.beacon_on

            # The car leaves (empty batches): its episodes clear at once, the beacon goes off.
            for k in range(20, 25):
                tracks.put(batch(k * PERIOD_S, [], k))
            clear = wait_for(alerts, speeding("clear", 1), "the speeding clear", received)
            assert clear.episode_id == start.episode_id and clear.stamp == pytest.approx(2.0)
            dark = wait_for(devices, lambda d: True, "the beacon off")
            assert (dark.beacon_on, dark.sign_text, dark.stamp) == (False, "", pytest.approx(2.0))

            # Bad input: counted in the status, dropped, and the node carries on.
            tracks.put_bytes(b"\x00\x01 not a track batch")
            tracks.put(
                TrackBatch(
                    site="elsewhere",
                    source_id="fusion-tracker",
                    stamp=3.0,
                    cycle_index=30,
                    tracks=[],
                )
            )
            tracks.put(batch(0.5, [make_track(9, 500.0, FAST_MPS)], 31))  # from the past
            name = f"{bus.keys.tracks}|"
            counted = wait_for(
                status,
                lambda s: all(
                    s.invalid_counts.get(name + reason, 0) == 1
                    for reason in ("bad_json", "wrong_site", "out_of_order")
                ),
                "bad_json, wrong_site and out_of_order each counted once",
            )
            assert counted.state.value == "running"

            # Still alerting: a second speeder opens its own episode.
            for message in speeder_batches(2, 3.0, 1.5, 40):
                tracks.put(message)
            second = wait_for(alerts, speeding("start", 2), "the second speeder's start", received)
            assert second.episode_id != start.episode_id and second.stamp == pytest.approx(4.0)
            assert node.poll() is None

            # Exactly one start and one clear for the first car, nothing else on speeding.
            speeding_events = [
                (a.phase, a.track_id) for a in received if a.alert_type is AlertType.SPEEDING
            ]
            assert speeding_events == [("start", 1), ("clear", 1), ("start", 2)]
            assert len({a.alert_id for a in received}) == len(received)
        finally:
            node.send_signal(signal.SIGTERM)
            assert node.wait(15.0) == 0


def test_node_process_bounds_a_back_beyond_the_reach_with_the_point_sensors(port: int) -> None:
    """The default site's point sensors over the bus: speed-1 (600 m) reads the open lane
    crawling, speed-2 (350 m) free; a queue the tracks see to the reach (782 m) then has its
    back between them on ``wz/<site>/queue``. A reading from a sensor the site file does not
    list is counted and dropped."""
    settings = BusSettings(listen_endpoints=[f"tcp/127.0.0.1:{port}"], connect_endpoints=[])
    env = node_env(port)
    with Bus.open(settings, site=SITE.site_id, service="node-test") as bus:
        tracks = bus.publisher(bus.keys.tracks, TrackBatch)
        points = {
            name: bus.publisher(bus.keys.point_sensor(name), PointSensorReading)
            for name in ("speed-1", "speed-2", "speed-9")
        }
        queue = bus.subscribe(bus.keys.queue, QueueState)
        status = bus.subscribe(
            bus.keys.status("alert-service"), ServiceStatus, mode="ring", capacity=1
        )
        node = subprocess.Popen([sys.executable, "-m", "wz_alert_service.node"], cwd=ROOT, env=env)
        try:
            assert tracks.wait_for_subscribers(30.0), "the node never subscribed to the tracks"
            assert points["speed-1"].wait_for_subscribers(10.0), "no subscriber to the points"
            points["speed-1"].put(reading("speed-1", 30.0, 3.0))
            points["speed-2"].put(reading("speed-2", 30.0, 24.0))
            forged = reading("speed-2", 30.0, 24.0).model_copy(update={"source_id": "speed-9"})
            points["speed-9"].put(forged)
            time.sleep(0.5)  # the readings are taken before the next batch
            queued = [make_track(1 + i, 786.0 + 9.0 * i, 1.0) for i in range(5)]
            for k in range(5):
                tracks.put(batch(31.0 + k * PERIOD_S, queued, k))
            state = wait_for(
                queue,
                lambda s: s.lanes[0].back_beyond_reach,
                "the open lane's back beyond the reach",
            )
            lane = state.lanes[0]
            # 5 m/s for the 30 s interval and the 1 s since: 155 m either way
            assert lane.back_downstream_bound_m == pytest.approx(755.0, abs=1.0)
            assert lane.back_upstream_bound_m == pytest.approx(195.0, abs=1.0)
            name = f"{bus.keys.point_sensors_all}|unknown_sensor"
            wait_for(status, lambda s: s.invalid_counts.get(name, 0) == 1, "speed-9 refused")
            assert node.poll() is None
        finally:
            node.send_signal(signal.SIGTERM)
            assert node.wait(15.0) == 0
