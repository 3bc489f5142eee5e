"""The gateway node as its own process on real Zenoh (two peers on loopback, multicast off):
track batches, an alert and the devices' state in, the same out over HTTP; bad input counted
and the node alive; stopped and started again on the same file, nothing lost."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import httpx
import pytest

from tests.conftest import free_port
from tests.gateway.helpers import (
    ADMIN_KEY,
    READ_KEY,
    SITE,
    car_batches,
    devices_state,
    eventually,
    gateway_process,
    sample_alert,
)
from wz_shared.bus import Bus, Subscription
from wz_shared.messages import Alert, AlertType, RoadsideDeviceState, ServiceStatus, TrackBatch
from wz_shared.settings import BusSettings

READ = {"X-API-Key": READ_KEY}
T = TypeVar("T")


def wait_for(
    subscription: Subscription[T],
    condition: Callable[[T], bool],
    what: str,
    timeout_s: float = 20.0,
) -> T:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        message = subscription.recv(0.5)
        if message is not None and condition(message):
            return message
    pytest.fail(f"timed out after {timeout_s:.0f} s waiting for {what}")


def points_count(http: httpx.Client) -> int:
    """The fused points stored (a track that has ended also has smoothed ones)."""
    return len(
        http.get(
            "/v1/trajectories", headers=READ, params={"limit": 10_000, "smoothed": "false"}
        ).json()["points"]
    )


def test_node_stores_the_bus_serves_it_and_keeps_it_across_restarts(
    port: int, tmp_path: Path
) -> None:
    settings = BusSettings(listen_endpoints=[f"tcp/127.0.0.1:{port}"], connect_endpoints=[])
    http_port = free_port()
    http = httpx.Client(base_url=f"http://127.0.0.1:{http_port}", timeout=5.0)
    batches = car_batches(7, 900.0, 28.0, 0.0, 30)
    alert = sample_alert("proc-1", 1.5, track=batches[15].tracks[0], track_id=7)
    with Bus.open(settings, site=SITE.site_id, service="gateway-test") as bus:
        tracks = bus.publisher(bus.keys.tracks, TrackBatch)
        alerts = bus.publisher(bus.keys.alerts(AlertType.SPEEDING.value), Alert)
        devices = bus.publisher(bus.keys.devices_state, RoadsideDeviceState)
        status = bus.subscribe(bus.keys.status("gateway"), ServiceStatus, mode="ring", capacity=1)
        with gateway_process(port, http_port, tmp_path / "data") as node:
            assert tracks.wait_for_subscribers(30.0), "the gateway never subscribed to tracks"
            assert alerts.wait_for_subscribers(10.0) and devices.wait_for_subscribers(10.0)
            for message in batches:
                tracks.put(message)
            alerts.put(alert)
            devices.put(
                devices_state(1.5, beacon_on=True, sign_text="SLOW DOWN", cause=AlertType.SPEEDING)
            )

            eventually(lambda: points_count(http) == 30 or None, "30 stored track points")
            live = http.get("/v1/tracks/live", headers=READ).json()
            assert live["cycle_index"] == 29 and live["tracks"][0]["track_id"] == 7
            stored = eventually(
                lambda: http.get("/v1/alerts", headers=READ).json()["alerts"] or None,
                "the alert over HTTP",
            )
            assert [Alert.model_validate(a) for a in stored] == [alert]
            feed = http.get("/v1/wzdx/device-feed", headers=READ).json()
            beacon = next(
                f
                for f in feed["features"]
                if f["properties"]["core_details"]["device_type"] == "flashing-beacon"
            )
            assert beacon["properties"]["is_flashing"] is True
            trajectory = http.get("/v1/tracks/7", headers=READ, params={"format": "csv"})
            assert trajectory.text.count("\n") == 31  # header and 30 rows

            # Bad input: counted, dropped, and the node carries on.
            tracks.put_bytes(b"\x00 not a track batch")
            tracks.put(
                TrackBatch(
                    site="elsewhere",
                    source_id="fusion-tracker",
                    stamp=9.0,
                    cycle_index=90,
                    tracks=[],
                )
            )
            key = bus.keys.tracks
            counted = wait_for(
                status,
                lambda s: all(
                    s.invalid_counts.get(f"{key}|{reason}", 0) == 1
                    for reason in ("bad_json", "wrong_site")
                ),
                "bad_json and wrong_site counted",
            )
            assert counted.state.value == "running" and node.poll() is None
            metrics = http.get("/metrics").text
            assert f'wz_gateway_bus_invalid_total{{key="{key}",reason="bad_json"}} 1.0' in metrics
            assert "wz_gateway_ingested_track_points_total 30.0" in metrics
            assert http.get("/readyz").json()["checks"] == {
                "database": "ok",
                "bus": "ok",
                "writer": "ok",
            }
            assert points_count(http) == 30

        # Stopped (SIGTERM, exit 0) and started again on the same file: all of it is there.
        with gateway_process(port, http_port, tmp_path / "data"):
            eventually(lambda: http.get("/readyz").status_code == 200 or None, "ready again")
            assert points_count(http) == 30
            again = http.get("/v1/alerts", headers=READ).json()["alerts"]
            assert [Alert.model_validate(a) for a in again] == [alert]
            keys: list[dict[str, Any]] = http.get(
                "/v1/admin/api-keys", headers={"X-API-Key": ADMIN_KEY}
            ).json()
            assert sorted(k["scope"] for k in keys) == ["admin", "read"]  # not added twice
    http.close()
