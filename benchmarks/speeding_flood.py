"""A speeding car inside a flood of track batches: alerted, stored and webhooked in time?

Five processes on loopback, as on the box: ``wz router``; the real alert service node; the
real gateway node (SQLite in a temporary folder, a webhook subscription to a receiver in this
process); a flooding source (:mod:`benchmarks.flood_peer`: one old batch of 20 tracks, about
11 kB as a queue's batch is, replayed at 20,000 a second, as a faulty or hostile source with
the tracker's key would); and this
process as the real tracker: a batch every 0.1 s (stamps from 100 s on) with one car at
50 mph in the 55 mph zone, which speeds up to 70 mph 2 s into the flood.

Measured, from the wall-clock instant the first batch with the car over the limit was put:

- **raised**: when the alert service's speeding start for the car reached this process on
  the bus;
- **stored**: the ``received_at`` the gateway's writer stamped on its row;
- **webhooked**: the receiver having read the signed POST of it;

each minus the rule's hold time (``alerts.speeding.hold_s``, 1 s on the default site): what
the flood added to the normal latency. Also the batches the alert service received, shed
(by reason) and took, from its own status. Run with the gate on (``WZ_ALERT_SHED_STALE_
BATCHES``, the default) and off (every batch queued: the code before the gate), side by
side in one run.
"""

from __future__ import annotations

import json
import os
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from benchmarks.alert_flood import RATE_HZ, flood_done, start_flood, start_router
from benchmarks.common import ROOT, TIMEOUT_S, free_port
from benchmarks.flood_peer import lane_track
from benchmarks.webhook_latency import _gateway, _Receiver
from wz_shared.bus import Bus
from wz_shared.messages import Alert, AlertType, ServiceStatus, TrackBatch
from wz_shared.site import DEFAULT_SITE_PATH, MPH_TO_MPS, load_site

#: The issue's bound: the alert within this of the rule's hold time [s].
BOUND_S = 1.0
SLOW_MPS = 50.0 * MPH_TO_MPS
FAST_MPS = 70.0 * MPH_TO_MPS
TRACK_ID = 7
PERIOD_S = 0.1
#: Tracks in each flooding batch.
FLOOD_TRACKS = 20
#: The flood's first seconds, before the car speeds up [s].
LEAD_S = 2.0


def _alert_service(bus_port: int, log_path: Path, shed: bool) -> subprocess.Popen[bytes]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("WZ_")}
    env.update(
        WZ_BUS_MODE="client",
        WZ_BUS_CONNECT_ENDPOINTS=f"tcp/127.0.0.1:{bus_port}",
        WZ_BUS_LISTEN_ENDPOINTS="",
        WZ_LOG_FORMAT="json",
        WZ_LOG_LEVEL="WARNING",
        WZ_ALERT_SHED_STALE_BATCHES="true" if shed else "false",
        WZ_ALERT_EPISODE_ID_PREFIX="flood",
    )
    with log_path.open("ab") as out:
        return subprocess.Popen(
            [sys.executable, "-m", "wz_alert_service.node"],
            cwd=ROOT,
            env=env,
            stdout=out,
            stderr=subprocess.STDOUT,
        )


def speeding_run(
    flood_s: float, shed: bool, folder: Path, rate_hz: float = RATE_HZ
) -> dict[str, Any]:
    """One run (see the module); the measurements, raw (None where it never came)."""
    site = load_site(DEFAULT_SITE_PATH)
    hold_s = float(site.alerts.speeding.hold_s)
    port, router, settings = start_router()
    endpoint = settings.connect_endpoints[0]
    http_port = free_port()
    alerting = None
    try:
        alerting = _alert_service(port, folder / "alert-service.log", shed)
        with (
            _Receiver() as receiver,
            Bus.open(settings, site=site.site_id, service="fusion-tracker") as bus,
            _gateway(port, http_port, folder / "data", log_path=folder / "gateway.log") as http,
        ):
            made = http.post("/v1/webhooks", json={"url": receiver.url("/hook")})
            made.raise_for_status()
            tracks = bus.publisher(bus.keys.tracks, TrackBatch)
            raised: list[tuple[float, Alert]] = []
            bus.on(
                bus.keys.alerts(AlertType.SPEEDING.value),
                Alert,
                lambda _k, alert: raised.append((time.time(), alert)),
            )
            statuses: list[ServiceStatus] = []
            bus.on(
                bus.keys.status("alert-service"),
                ServiceStatus,
                lambda _k, status: statuses.append(status),
            )
            deadline = time.monotonic() + TIMEOUT_S
            while not bus.alive(bus.keys.status("alert-service")):
                if time.monotonic() > deadline:
                    raise TimeoutError("the alert service never came up")
                time.sleep(0.2)
            # Wait for the alert service's and the gateway's subscriptions on the tracks.
            if not tracks.wait_for_subscribers(TIMEOUT_S):
                raise TimeoutError("nobody subscribes to the tracks")
            time.sleep(1.0)
            flood = start_flood(endpoint, site.site_id, rate_hz, flood_s, FLOOD_TRACKS)
            # The real tracker, on the wall clock: 10 Hz until the flood is over and 2 s on.
            onset_wall: float | None = None
            station = 400.0
            began = time.perf_counter()
            k = 0
            while (elapsed := time.perf_counter() - began) < flood_s + 2.0:
                fast = elapsed >= LEAD_S
                speed = FAST_MPS if fast else SLOW_MPS
                now = time.time()
                tracks.put(
                    TrackBatch(
                        site=site.site_id,
                        source_id="fusion-tracker",
                        stamp=100.0 + k * PERIOD_S,
                        cycle_index=k,
                        tracks=[lane_track(TRACK_ID, station, speed)],
                    )
                )
                if fast and onset_wall is None:
                    onset_wall = now
                station += speed * PERIOD_S
                k += 1
                pause = began + k * PERIOD_S - time.perf_counter()
                if pause > 0:
                    time.sleep(pause)
            done = flood_done(flood)
            time.sleep(1.5)  # the last webhook and status
            hooks: list[tuple[float, dict[str, Any]]] = []
            perf_to_wall = time.time() - time.perf_counter()
            while not receiver.arrivals.empty():
                arrived, _path, _id, _headers, body = receiver.arrivals.get()
                hooks.append((arrived + perf_to_wall, json.loads(body)))
    finally:
        if alerting is not None:
            alerting.terminate()
            alerting.wait(TIMEOUT_S)
        router.terminate()
        router.wait(TIMEOUT_S)
    assert onset_wall is not None
    starts = [(at, a) for at, a in raised if a.phase == "start" and a.track_id == TRACK_ID]
    raised_s = starts[0][0] - onset_wall - hold_s if starts else None
    stored_s = webhooked_s = None
    if starts:
        alert_id = starts[0][1].alert_id
        with sqlite3.connect(f"file:{folder / 'data' / 'gateway.sqlite3'}?mode=ro", uri=True) as db:
            row = db.execute(
                "SELECT received_at FROM alerts WHERE alert_id = ?", (alert_id,)
            ).fetchone()
        if row is not None:
            stored_s = float(row[0]) - onset_wall - hold_s
        for at, event in hooks:
            if alert_id in json.dumps(event):
                webhooked_s = at - onset_wall - hold_s
                break
    last = statuses[-1] if statuses else None
    tracks_key = f"wz/{site.site_id}/tracks"
    shed_counts = {
        key.partition("|")[2]: n
        for key, n in (last.shed_counts if last else {}).items()
        if key.startswith(tracks_key + "|")
    }
    return {
        "shed": shed,
        "flood": done,
        "hold_s": hold_s,
        "raised_s": raised_s,
        "stored_s": stored_s,
        "webhooked_s": webhooked_s,
        "alert_service_shed": shed_counts,
        "alert_service_invalid": {
            key.partition("|")[2]: n
            for key, n in (last.invalid_counts if last else {}).items()
            if key.startswith(tracks_key + "|")
        },
    }


def run(quick: bool) -> dict[str, Any]:
    """A 10 s flood (5 s quick), the gate on and off, in one run."""
    flood_s = 5.0 if quick else 10.0
    out: dict[str, Any] = {"flood_s": flood_s, "target_rate_hz": RATE_HZ, "bound_s": BOUND_S}
    for shed in (True, False):
        with tempfile.TemporaryDirectory(prefix="wz-bench-speeding-") as tmp:
            out["gate_on" if shed else "gate_off"] = speeding_run(flood_s, shed, Path(tmp))
    return out


if __name__ == "__main__":
    sys.stdout.write(json.dumps(run("--quick" in sys.argv[1:]), indent=2) + "\n")
