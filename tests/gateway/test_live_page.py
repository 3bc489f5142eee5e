"""The live page in a real browser: the gateway as its own process (dev mode) on real Zenoh,
moving track batches published at 10 Hz and one alert; headless Chromium, driven over the
DevTools Protocol, loads ``/`` and must show the tracks, see them move, list the alert and
throw no error. Its screenshot goes to the test's folder, and to ``docs/images/gateway-live.png``
with ``WZ_UPDATE_SCREENSHOTS=1``."""

from __future__ import annotations

import os
import threading
from pathlib import Path

import httpx

from tests.conftest import free_port
from tests.gateway.browser import chromium
from tests.gateway.helpers import SITE, eventually, gateway_process, sample_alert
from wz_shared.bus import Bus
from wz_shared.messages import Alert, AlertSeverity, AlertType, Track, TrackBatch, VehicleClass
from wz_shared.settings import BusSettings

ROOT = Path(__file__).resolve().parents[2]
SCREENSHOT = ROOT / "docs" / "images" / "gateway-live.png"
RATE_HZ = 10.0

#: (track_id, class, station at t = 0 [m], offset [m], speed [m/s], length [m], width [m]):
#: traffic on the default site's approach, the left lane closed from the taper at 1000 m.
VEHICLES = [
    (11, VehicleClass.CAR, 905.0, -1.83, 25.5, 4.7, 1.9),
    (12, VehicleClass.TRUCK, 860.0, -1.9, 23.0, 16.5, 2.6),
    (13, VehicleClass.CAR, 880.0, 1.83, 31.5, 4.5, 1.85),
    (14, VehicleClass.CAR, 830.0, -1.75, 26.5, 4.9, 1.95),
    (15, VehicleClass.MOTORCYCLE, 935.0, 1.7, 27.0, 2.2, 0.8),
]


def traffic(stamp: float, cycle_index: int) -> TrackBatch:
    """The vehicles at ``stamp`` [s], driving at constant speed along the straight approach
    (site x = -offset, y = station); each starts over at 800 m once past 1150 m."""
    tracks = []
    for track_id, vehicle_class, station0, offset, speed, length, width in VEHICLES:
        laps, along = divmod(station0 - 800.0 + speed * stamp, 350.0)
        station = 800.0 + along
        tracks.append(
            Track(
                track_id=track_id + 100 * int(laps),
                x_m=-offset,
                y_m=station,
                vx_mps=0.0,
                vy_mps=speed,
                covariance=[0.0] * 16,
                station_m=station,
                offset_m=offset,
                speed_mps=speed,
                heading_rad=1.5707963267948966,
                lane_index=int(SITE.lane_index_at(offset)),
                object_class=vehicle_class,
                age_s=2.0,
                hits=40,
                confirmed=True,
                sources=["lidar-mast", "camera-mast"],
                length_m=length,
                width_m=width,
            )
        )
    return TrackBatch(
        site=SITE.site_id,
        source_id="fusion-tracker",
        stamp=stamp,
        cycle_index=cycle_index,
        tracks=tracks,
    )


def test_live_page_shows_tracks_moving_and_the_alert_without_errors(
    port: int, tmp_path: Path
) -> None:
    settings = BusSettings(listen_endpoints=[f"tcp/127.0.0.1:{port}"], connect_endpoints=[])
    http_port = free_port()
    base = f"http://127.0.0.1:{http_port}"
    stop = threading.Event()
    with (
        Bus.open(settings, site=SITE.site_id, service="live-page-test") as bus,
        gateway_process(port, http_port, tmp_path / "data", keys=False, dev_mode="true"),
    ):
        tracks = bus.publisher(bus.keys.tracks, TrackBatch)
        alerts = bus.publisher(bus.keys.alerts(AlertType.SPEEDING.value), Alert)
        assert tracks.wait_for_subscribers(30.0), "the gateway never subscribed to tracks"
        assert alerts.wait_for_subscribers(10.0)

        def publish() -> None:  # the tracker's output, at 10 Hz in real time
            cycle = 0
            while not stop.wait(1.0 / RATE_HZ):
                tracks.put(traffic(cycle / RATE_HZ, cycle))
                cycle += 1

        publisher = threading.Thread(target=publish, name="tracks", daemon=True)
        publisher.start()
        try:
            eventually(lambda: httpx.get(f"{base}/readyz").status_code == 200 or None, "ready")
            with chromium(tmp_path / "chromium") as page:
                page.call("Page.navigate", url=f"{base}/")
                page.wait_for(
                    "document.body && Number(document.body.dataset.trackCount) > 0",
                    "tracks on the page",
                )
                assert page.evaluate("location.pathname") == "/live"  # / redirects there
                assert page.evaluate("document.body.dataset.connection") == "live"
                title = page.evaluate("document.getElementById('site-name').textContent")
                assert title == SITE.name

                first = page.evaluate("window.wzLive.tracks")
                first_stamp = page.evaluate("window.wzLive.stamp")
                page.wait_for(f"window.wzLive.stamp >= {first_stamp + 1.0}", "a second later")
                second = page.evaluate("window.wzLive.tracks")
                assert len(first) == len(second) == len(VEHICLES)
                before = {t["track_id"]: t["station_m"] for t in first}
                after = {t["track_id"]: t["station_m"] for t in second}
                moved = [after[i] - before[i] for i in before.keys() & after.keys()]
                assert moved and all(distance > 15.0 for distance in moved), (before, after)
                assert {t["y_m"] for t in second} != {t["y_m"] for t in first}

                alert = sample_alert(
                    "live-page-1",
                    page.evaluate("window.wzLive.stamp"),
                    track_id=13,
                    severity=AlertSeverity.CRITICAL,
                )
                alerts.put(alert)
                selector = f"#alerts li[data-alert-id='{alert.alert_id}']"
                text = page.wait_for(
                    f'document.querySelector("{selector}")?.textContent', "the alert in the list"
                )
                assert "Speeding" in text and "track #13" in text and "critical" in text
                assert page.evaluate("document.body.dataset.alertCount") == "1"
                assert page.evaluate("window.wzLive.alerts") == [alert.alert_id]

                png = page.screenshot(tmp_path / "gateway-live.png")
                assert png.startswith(b"\x89PNG\r\n\x1a\n") and len(png) > 20_000
                if os.environ.get("WZ_UPDATE_SCREENSHOTS") == "1":
                    page.screenshot(SCREENSHOT)
                assert page.errors() == []
        finally:
            stop.set()
            publisher.join(5.0)
