"""A flood of track batches on the bus, from its own process (``alert_flood`` and its test).

Usage: ``python -m benchmarks.flood_peer ENDPOINT SITE RATE_HZ DURATION_S [TRACKS]``

Connects as a client to ENDPOINT (``WZ_BUS_*`` apart from that) and, once a subscriber of
``wz/<SITE>/tracks`` matches, puts one-track :class:`TrackBatch` payloads (encoded once
beforehand, ~600 bytes) at RATE_HZ for DURATION_S: a burst every 5 ms, paced on the wall
clock, blocking congestion control as the tracker's publisher. Prints one JSON line when it
starts (``{"event": "flooding"}``) and one when done, with the rate it reached.
"""

from __future__ import annotations

import sys
import time

from benchmarks.peer import report
from wz_shared.bus import Bus
from wz_shared.codec import encode_json
from wz_shared.messages import Track, TrackBatch
from wz_shared.settings import BusSettings

BURST_S = 0.005


def payload(site: str, count: int = 1) -> bytes:
    """One batch of ``count`` tracks (a queue's batch holds 10-30), encoded."""
    tracks = [lane_track(n, 600.0 - 10.0 * n, 25.0) for n in range(1, count + 1)]
    batch = TrackBatch(
        site=site, source_id="fusion-tracker", stamp=1.0, cycle_index=1, tracks=tracks
    )
    return encode_json(batch)


def lane_track(track_id: int, station_m: float, speed_mps: float) -> Track:
    """A confirmed track in the default site's open lane (offset -1.83 m) on its straight
    part (x = -offset, y = station), heading north at ``speed_mps``."""
    return Track(
        track_id=track_id,
        x_m=1.83,
        y_m=station_m,
        vx_mps=0.0,
        vy_mps=speed_mps,
        covariance=[0.25, 0, 0, 0, 0, 0.25, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0],
        station_m=station_m,
        offset_m=-1.83,
        speed_mps=speed_mps,
        heading_rad=1.5707963,
        lane_index=0,
        age_s=1.0,
        hits=10,
        confirmed=True,
        sources=["lidar-mast"],
    )


def main() -> None:
    endpoint, site, rate_hz, duration_s = (
        sys.argv[1],
        sys.argv[2],
        float(sys.argv[3]),
        float(sys.argv[4]),
    )
    count = int(sys.argv[5]) if len(sys.argv) > 5 else 1
    settings = BusSettings(mode="client", connect_endpoints=[endpoint], listen_endpoints=[])
    with Bus.open(settings, site=site, service="fusion-tracker") as bus:
        tracks = bus.publisher(bus.keys.tracks, TrackBatch)
        if not tracks.wait_for_subscribers(30.0):
            raise SystemExit("nobody subscribes to the tracks")
        body = payload(site, count)
        per_burst = max(1, round(rate_hz * BURST_S))
        report("flooding")
        started = time.perf_counter()
        sent = 0
        burst = 0
        while time.perf_counter() - started < duration_s:
            for _ in range(per_burst):
                tracks.put_bytes(body)
            sent += per_burst
            burst += 1
            pause = started + burst * BURST_S - time.perf_counter()
            if pause > 0:
                time.sleep(pause)
        elapsed = time.perf_counter() - started
        report("done", sent=sent, seconds=elapsed, rate_hz=sent / elapsed)


if __name__ == "__main__":
    main()
