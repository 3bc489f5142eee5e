"""Alert service: from the track batch that completes a rule to the alert received on the bus.

The real node (``python -m wz_alert_service.node``, default site and thresholds) runs as its own
process, a Zenoh peer connected to this one on ``tcp/127.0.0.1`` (multicast off). Each sample is
one speeding car (a new track id, 65 mph in the 55 mph zone, lane 0 from 400 m): its first ten
10 Hz track batches (0.0-0.9 s of data) hold the condition without completing the 1 s hold; once
the node has taken them (its ``alerts/active`` answer carries the last batch's stamp), the
eleventh batch (1.0 s), encoded beforehand, is published and the clock runs from just before
that ``put_bytes`` to the arrival here of the first alert stamped 1.0 s (the speeding start; the aggressive-approach start
follows it). The node's path: receive, decode the batch, run every rule on every track, encode
and publish the alert (before the devices' state and the query snapshot). The previous car's
track is gone from the sample's first batch, so its episodes clear there, not in the timed one.

Two batch sizes: the car alone, and the car among 50 other tracks at a legal speed (a busy
approach: every rule runs on 51 tracks and the batch is about 50 times larger to decode).
"""

from __future__ import annotations

import logging
import math
import os
import subprocess
import sys
import time
from typing import Any

from benchmarks.common import ROOT, TIMEOUT_S, free_port, listener_settings, summarize
from wz_shared.bus import Bus
from wz_shared.codec import encode_json
from wz_shared.messages import ActiveAlerts, Alert, Track, TrackBatch
from wz_shared.site import DEFAULT_SITE_PATH, MPH_TO_MPS, load_site

log = logging.getLogger(__name__)

SPEEDER_MPS = 65.0 * MPH_TO_MPS
BACKGROUND_MPS = 20.0
PERIOD_S = 0.1
HOLD_BATCHES = 10  # batches 0.0-0.9 s; the 11th (1.0 s) completes the speeding rule's 1 s hold
SAMPLE_SPAN_S = 2.0  # data time between the first batches of two samples


def _track(track_id: int, station_m: float, speed_mps: float) -> Track:
    """A confirmed track in lane 0 on the straight road (x = -d, y = s)."""
    return Track(
        track_id=track_id,
        x_m=1.83,
        y_m=station_m,
        vx_mps=0.0,
        vy_mps=speed_mps,
        covariance=[0.0] * 16,
        station_m=station_m,
        offset_m=-1.83,
        speed_mps=speed_mps,
        heading_rad=math.pi / 2,
        lane_index=0,
        age_s=1.0,
        hits=10,
        confirmed=True,
        sources=["lidar-mast"],
        length_m=4.6,
        width_m=1.8,
    )


def _batches(site_id: str, sample: int, background: int) -> list[TrackBatch]:
    """The sample's 11 batches: the speeder (id 1000 + sample) and the background tracks."""
    start_s = sample * SAMPLE_SPAN_S
    batches = []
    for k in range(HOLD_BATCHES + 1):
        dt = k * PERIOD_S
        # Legal traffic 170 m and more ahead of the speeder, all at one speed: no rule fires.
        tracks = [
            _track(i, 600.0 + 20.0 * i + BACKGROUND_MPS * dt, BACKGROUND_MPS)
            for i in range(background)
        ]
        tracks.append(_track(1000 + sample, 400.0 + SPEEDER_MPS * dt, SPEEDER_MPS))
        batches.append(
            TrackBatch(
                site=site_id,
                source_id="fusion-tracker",
                stamp=start_s + dt,
                cycle_index=sample * (HOLD_BATCHES + 1) + k,
                tracks=tracks,
            )
        )
    return batches


def _wait_until_taken(bus: Bus, stamp_s: float) -> None:
    """Until the node's answer on alerts/active says it has taken the batch at ``stamp_s``."""
    deadline = time.monotonic() + TIMEOUT_S
    while time.monotonic() < deadline:
        answers = bus.query(bus.keys.alerts_active, ActiveAlerts, timeout_s=TIMEOUT_S)
        if answers and answers[0].stamp >= stamp_s - 1e-9:
            return
    raise TimeoutError(f"the node did not take the batch at {stamp_s:.1f} s")


def measure(samples: int, background: int) -> dict[str, Any]:
    """Latencies [ms] of ``samples`` speeding starts, ``background`` other tracks per batch."""
    site = load_site(DEFAULT_SITE_PATH)
    port = free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("WZ_")}
    env.update(
        WZ_BUS_CONNECT_ENDPOINTS=f"tcp/127.0.0.1:{port}",
        WZ_BUS_LISTEN_ENDPOINTS="",
        WZ_LOG_LEVEL="WARNING",
        WZ_LOG_FORMAT="json",
        WZ_ALERT_EPISODE_ID_PREFIX="bench",
    )
    latencies_ms: list[float] = []
    batch_bytes = 0
    with Bus.open(listener_settings(port, shm=True), site=site.site_id, service="bench") as bus:
        tracks = bus.publisher(bus.keys.tracks, TrackBatch)
        alerts = bus.subscribe(bus.keys.alerts_all, Alert)
        node = subprocess.Popen([sys.executable, "-m", "wz_alert_service.node"], cwd=ROOT, env=env)
        try:
            if not tracks.wait_for_subscribers(TIMEOUT_S):
                raise TimeoutError("the alert node never subscribed to the tracks")
            for sample in range(samples):
                *holding, completing = _batches(site.site_id, sample, background)
                for message in holding:
                    tracks.put(message)
                _wait_until_taken(bus, holding[-1].stamp)
                alerts.drain()  # the previous car's clears
                payload = encode_json(completing)  # encoded before the clock starts
                batch_bytes = len(payload)
                started = time.perf_counter()
                tracks.put_bytes(payload)
                while True:
                    alert = alerts.recv(TIMEOUT_S)
                    if alert is None:
                        raise TimeoutError(f"no alert for sample {sample}")
                    if abs(alert.stamp - completing.stamp) < 1e-9 and alert.phase == "start":
                        latencies_ms.append(1e3 * (time.perf_counter() - started))
                        break
            invalid = bus.stats.snapshot()["invalid"]
            if invalid:
                raise RuntimeError(f"invalid messages on the bench's side: {invalid}")
        finally:
            node.terminate()
            node.wait(TIMEOUT_S)
    return {
        "tracks_per_batch": background + 1,
        "batch_bytes": batch_bytes,
        "latency_ms": summarize(latencies_ms),
    }


def run(quick: bool) -> dict[str, Any]:
    """200 samples per batch size (30 quick), one node process per batch size."""
    samples = 30 if quick else 200
    results = {}
    for name, background in (("one_track", 0), ("51_tracks", 50)):
        log.info("alert_latency: %s, %d samples", name, samples)
        results[name] = measure(samples, background)
    return {"samples": samples, "variants": results}
