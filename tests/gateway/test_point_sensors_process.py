"""The upstream point speed sensors through the real thing: the gateway as its own process (dev
mode) on real Zenoh, a reading published on ``wz/<site>/points/<sensor>``, out over HTTP as
that sensor's WZDx traffic sensor; a reading whose ``source_id`` is not the sensor its key
names is refused and counted (``wrong_source``), never stored."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import httpx

from tests.conftest import free_port
from tests.gateway.helpers import SITE, eventually, gateway_process
from tests.gateway.test_node_process import wait_for
from tests.gateway.test_wzdx import point_reading
from wz_shared.bus import Bus
from wz_shared.messages import PointSensorReading, ServiceStatus
from wz_shared.settings import BusSettings


def point_sensor(http: httpx.Client, sensor_id: str) -> dict[str, Any]:
    feed = http.get("/v1/wzdx/device-feed").json()
    (feature,) = [
        f
        for f in feed["features"]
        if f["properties"]["core_details"]["name"] == f"Point speed sensor {sensor_id}"
    ]
    properties: dict[str, Any] = feature["properties"]
    return properties


def test_a_point_sensors_reading_over_the_bus_to_the_wzdx_feed(port: int, tmp_path: Path) -> None:
    settings = BusSettings(listen_endpoints=[f"tcp/127.0.0.1:{port}"], connect_endpoints=[])
    http_port = free_port()
    http = httpx.Client(base_url=f"http://127.0.0.1:{http_port}", timeout=5.0)
    with (
        Bus.open(settings, site=SITE.site_id, service="points-test") as bus,
        gateway_process(port, http_port, tmp_path / "data", keys=False, dev_mode="true") as node,
    ):
        first = bus.publisher(bus.keys.point_sensor("speed-1"), PointSensorReading)
        status = bus.subscribe(bus.keys.status("gateway"), ServiceStatus, mode="ring", capacity=1)
        assert first.wait_for_subscribers(30.0), "the gateway never subscribed to points/*"
        eventually(lambda: http.get("/readyz").status_code == 200 or None, "ready")
        assert point_sensor(http, "speed-1")["core_details"]["device_status"] == "unknown"

        first.put(point_reading("speed-1", 60.0))
        # speed-2's reading on speed-1's key: refused, counted, not stored
        first.put(point_reading("speed-2", 61.0))
        key = bus.keys.point_sensors_all  # counted under the subscription's key
        counted = wait_for(
            status,
            lambda s: s.invalid_counts.get(f"{key}|wrong_source", 0) == 1,
            "the wrong source counted",
        )
        assert counted.state.value == "running" and node.poll() is None
        eventually(
            lambda: "lane_data" in point_sensor(http, "speed-1") or None, "speed-1's reading"
        )
        sensor = point_sensor(http, "speed-1")
        assert sensor["core_details"]["device_status"] == "ok"
        assert [lane["volume_vph"] for lane in sensor["lane_data"]] == [360.0, 720.0]
        assert "lane_data" not in point_sensor(http, "speed-2")
        assert (
            'wz_gateway_ingested_messages_total{kind="point_reading"} 1.0'
            in http.get("/metrics").text
        )
