"""The gateway node as its own process on real Zenoh (two peers on loopback, multicast off):
a track that ends is smoothed and served over HTTP (JSON and Parquet); a track still going when
the node stops is smoothed by the next start (once the tracker has been silent long enough),
and nothing is smoothed twice."""

from __future__ import annotations

import io
from pathlib import Path

import httpx
import pyarrow.parquet as pq

from tests.conftest import free_port
from tests.gateway.helpers import READ_KEY, SITE, eventually, gateway_process
from tests.gateway.tracking import car_tracks, filtered_car, merged_batches
from wz_shared.bus import Bus
from wz_shared.messages import TrackBatch
from wz_shared.settings import BusSettings

READ = {"X-API-Key": READ_KEY}


def count(http: httpx.Client, track_id: int, smoothed: bool) -> int:
    response = http.get(
        f"/v1/tracks/{track_id}",
        headers=READ,
        params={"smoothed": str(smoothed).lower(), "limit": 10_000},
    )
    if response.status_code == 404:
        return 0
    n: int = response.json()["count"]
    return n


def test_ended_tracks_are_smoothed_once_across_a_restart(port: int, tmp_path: Path) -> None:
    settings = BusSettings(listen_endpoints=[f"tcp/127.0.0.1:{port}"], connect_endpoints=[])
    http_port = free_port()
    http = httpx.Client(base_url=f"http://127.0.0.1:{http_port}", timeout=5.0)
    # car 7 for 5 s, car 8 for 9 s: car 7 has ended (missing > 3 s) by car 8's last batches
    car7 = filtered_car(seed=51, count=100, station0_m=800.0)
    car8 = filtered_car(seed=52, count=180, station0_m=700.0, offset_m=1.83)
    batches = merged_batches(
        (car7.stamps_s, car_tracks(7, car7)), (car8.stamps_s, car_tracks(8, car8))
    )
    with Bus.open(settings, site=SITE.site_id, service="gateway-test") as bus:
        tracks = bus.publisher(bus.keys.tracks, TrackBatch)
        with gateway_process(port, http_port, tmp_path / "data"):
            assert tracks.wait_for_subscribers(30.0), "the gateway never subscribed to tracks"
            for message in batches:
                tracks.put(message)
            eventually(lambda: count(http, 7, smoothed=True) == 100 or None, "car 7 smoothed")
            assert count(http, 8, smoothed=False) == 180
            assert count(http, 8, smoothed=True) == 0  # still going
            export = http.get(
                "/v1/tracks/7", headers=READ, params={"smoothed": "true", "format": "parquet"}
            )
            table = pq.read_table(io.BytesIO(export.content))
            assert table.num_rows == 100 and all(table.column("smoothed").to_pylist())
            assert "wz_gateway_smoothed_tracks_total 1.0" in http.get("/metrics").text

        # Started again with a 1 s silence: car 8's tracker has been silent for longer, so the
        # new process smooths it at start; car 7 is not smoothed again.
        with gateway_process(port, http_port, tmp_path / "data", track_end_silence_s="1.0"):
            eventually(
                lambda: count(http, 8, smoothed=True) == 180 or None, "car 8 smoothed at start"
            )
            assert count(http, 7, smoothed=True) == 100
            assert count(http, 7, smoothed=False) == 100
            assert "wz_gateway_smoothed_tracks_total 1.0" in http.get("/metrics").text
    http.close()
