"""The sensors' self-calibration through the real thing: the gateway as its own process (dev
mode) on real Zenoh, the detectors' calibration messages published on
``wz/<site>/calibration/<sensor>``; out over HTTP (``/v1/calibration``, the WZDx feed, the live
stream) and on the live page in headless Chromium: the knocked camera flagged in the warning
colour, then learned again. A message whose ``source_id`` is not the sensor its key names is
refused and counted (``wrong_source``), never stored."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import httpx

from tests.conftest import free_port
from tests.gateway.browser import chromium
from tests.gateway.helpers import SITE, eventually, gateway_process
from tests.gateway.test_calibration import B, C, L, calibration
from tests.gateway.test_node_process import wait_for
from wz_shared.bus import Bus
from wz_shared.messages import SensorCalibration, ServiceStatus
from wz_shared.settings import BusSettings

LIDAR, CAMERA, RADAR = "lidar-mast", "camera-mast", "radar-mast"


def sensors_of(http: httpx.Client) -> dict[str, dict[str, Any]]:
    body = http.get("/v1/calibration").json()
    return {sensor["sensor_id"]: sensor for sensor in body["sensors"]}


def camera_state(http: httpx.Client) -> str | None:
    message = sensors_of(http)[CAMERA]["calibration"]
    return None if message is None else str(message["state"])


def calibration_events(base: str, count: int) -> list[dict[str, Any]]:
    """The first ``count`` events of a new client of ``/v1/stream?event=calibration``."""
    events: list[dict[str, Any]] = []
    with httpx.stream(
        "GET", f"{base}/v1/stream", params={"event": "calibration"}, timeout=10.0
    ) as reply:
        assert reply.status_code == 200
        kind = None
        for line in reply.iter_lines():
            if line.startswith("event: "):
                kind = line.removeprefix("event: ")
            elif line.startswith("data: ") and kind == "calibration":
                events.append(json.loads(line.removeprefix("data: ")))
                if len(events) == count:
                    break
    return events


def test_calibrations_over_the_bus_to_http_the_feed_the_stream_and_the_page(
    port: int, tmp_path: Path
) -> None:
    settings = BusSettings(listen_endpoints=[f"tcp/127.0.0.1:{port}"], connect_endpoints=[])
    http_port = free_port()
    base = f"http://127.0.0.1:{http_port}"
    http = httpx.Client(base_url=base, timeout=5.0)
    with (
        Bus.open(settings, site=SITE.site_id, service="calibration-test") as bus,
        gateway_process(port, http_port, tmp_path / "data", keys=False, dev_mode="true") as node,
    ):
        lidar = bus.publisher(bus.keys.calibration(LIDAR), SensorCalibration)
        camera = bus.publisher(bus.keys.calibration(CAMERA), SensorCalibration)
        status = bus.subscribe(bus.keys.status("gateway"), ServiceStatus, mode="ring", capacity=1)
        assert lidar.wait_for_subscribers(30.0), "the gateway never subscribed to calibration/*"
        assert camera.wait_for_subscribers(10.0)
        eventually(lambda: http.get("/readyz").status_code == 200 or None, "ready")

        lidar.put(calibration(LIDAR, 100.0, C, 40.0, yaw_deg=-0.31, pitch_deg=0.12, samples=900))
        camera.put(calibration(CAMERA, 100.0, L, 60.0, yaw_deg=0.5, clock_offset_s=0.085))
        camera.put(
            calibration(
                CAMERA,
                105.0,
                B,
                104.0,
                yaw_deg=0.8,
                pitch_deg=-0.2,
                clock_offset_s=0.085,
                detail="its boxes stand 2.1 deg off the LiDAR's",
            )
        )
        # From the LiDAR on the camera's key: refused, counted, not stored.
        camera.put(calibration(LIDAR, 106.0, C, 1.0, yaw_deg=5.0))
        key = bus.keys.calibration_all  # counted under the subscription's key
        counted = wait_for(
            status,
            lambda s: s.invalid_counts.get(f"{key}|wrong_source", 0) == 1,
            "the wrong source counted",
        )
        assert counted.state.value == "running" and node.poll() is None

        eventually(lambda: camera_state(http) == "bumped" or None, "the camera knocked")
        sensors = sensors_of(http)
        assert list(sensors) == [LIDAR, CAMERA, RADAR]
        assert sensors[CAMERA]["calibration"]["correction"]["yaw_deg"] == 0.8  # not 5.0
        assert [c["state"] for c in sensors[CAMERA]["changes"]] == ["bumped", "learning"]
        assert sensors[LIDAR]["calibration"]["samples"] == 900
        assert sensors[RADAR]["calibration"] is None
        assert (
            'wz_gateway_ingested_messages_total{kind="sensor_calibration"} 3.0'
            in http.get("/metrics").text
        )

        feed = http.get("/v1/wzdx/device-feed").json()
        cores = {
            f["properties"]["core_details"]["device_type"]: f["properties"]["core_details"]
            for f in feed["features"]
        }
        assert cores["camera"]["device_status"] in ("warning", "error")  # error: no frames
        assert (
            "camera camera-mast moved 1 s ago (its boxes stand 2.1 deg off the LiDAR's): its "
            "pose is being re-learned; its detections are down-weighted"
        ) in cores["camera"]["status_messages"]

        # A new client of the stream gets each sensor's newest at once.
        events = calibration_events(base, 2)
        assert [(e["source_id"], e["state"]) for e in events] == [
            (LIDAR, "calibrated"),
            (CAMERA, "bumped"),
        ]

        with chromium(tmp_path / "chromium") as page:
            page.call("Page.navigate", url=f"{base}/live")
            page.wait_for(
                "document.body && document.body.dataset.calibrationBumped === '1'",
                "the knocked camera on the page",
            )
            # The silent radar's row comes with the site's sensor list, a fetch of its own
            # that may land after the stream's first events.
            page.wait_for(
                "document.querySelectorAll('#calibration-rows tr').length === 3",
                "a row for each of the site's sensors",
            )
            shown = page.evaluate("window.wzLive.calibration")
            assert shown[CAMERA] == {
                "kind": "camera",
                "state": "bumped",
                "yaw_deg": 0.8,
                "pitch_deg": -0.2,
                "clock_offset_ms": 85.0,
                "stale": False,
            }
            assert shown[LIDAR]["state"] == "calibrated" and RADAR not in shown
            rows = page.evaluate(
                "[...document.querySelectorAll('#calibration-rows tr')].map((r) => "
                "[r.dataset.sensorId, r.className, [...r.cells].map((c) => c.textContent)])"
            )
            assert rows == [
                [
                    LIDAR,
                    "calibrated",
                    [LIDAR, "lidar", "calibrated", "-0.31°", "+0.12°", "0 ms", "60 s"],
                ],
                [
                    CAMERA,
                    "bumped",
                    [CAMERA, "camera", "bumped", "+0.80°", "-0.20°", "+85 ms", "1 s"],
                ],
                [RADAR, "silent", [RADAR, "radar", "not heard", "--", "--", "--", "--"]],
            ]
            # The knocked row stands out in the warning colour (--warn: #f5b82e).
            colour = page.evaluate(
                'getComputedStyle(document.querySelector("#calibration-rows '
                "tr[data-sensor-id='camera-mast'] td.state\")).color"
            )
            assert colour == "rgb(245, 184, 46)"
            summary = page.evaluate("document.getElementById('calibration-summary').textContent")
            assert summary == "1 sensor moved: pose being learned again"
            page.screenshot(tmp_path / "calibration-bumped.png")

            # Learned again: the flag goes, live from the stream.
            camera.put(calibration(CAMERA, 130.0, C, 128.0, yaw_deg=2.9, clock_offset_s=0.085))
            page.wait_for(
                "window.wzLive.calibration['camera-mast'].state === 'calibrated'",
                "the camera calibrated again",
            )
            assert page.evaluate("document.body.dataset.calibrationBumped") == "0"
            assert page.evaluate("document.getElementById('calibration-summary').textContent") == ""
            page.screenshot(tmp_path / "calibration-learned.png")
            assert page.errors() == []
        assert [c["state"] for c in sensors_of(http)[CAMERA]["changes"]] == [
            "calibrated",
            "bumped",
            "learning",
        ]
    http.close()
