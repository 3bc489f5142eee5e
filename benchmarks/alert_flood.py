"""Alerts first: an alert published during a flood of track batches, stored and webhooked.

Four processes on loopback, as on the box: ``wz router``; the real gateway node (SQLite in a
temporary folder, a webhook subscription to a receiver in this process); a flooding tracker
(:mod:`benchmarks.flood_peer`: one-track batches, ~600 bytes, at a target of 20,000 a second
for 10 s, blocking congestion control); and this process, which publishes an alert every
0.5 s from the flood's second second on (``alerts/speeding``, encoded beforehand) and measures
for each:

- **stored**: from just before its ``put_bytes`` (wall clock) to the ``received_at`` the
  gateway's writer stamped on its row (the transaction that stored it; read from the database
  file afterwards);
- **webhooked**: from the same instant to the receiver having read the signed POST whose
  ``webhook-id`` is that alert's (signature checked).

Also: the rate the flood reached, the track batches stored and dropped (the gateway's track
ring keeps the newest, counting the rest), the longest gap between the gateway's status
messages during the flood (its status thread must not starve), and every line of the
gateway's log that says ``database is locked`` (webhook dispatch must never hit one).
"""

from __future__ import annotations

import json
import logging
import socket
import sqlite3
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

from benchmarks.common import ROOT, TIMEOUT_S, free_port, summarize
from benchmarks.webhook_latency import _alert, _gateway, _Receiver
from wz_gateway import webhooks
from wz_shared.bus import Bus
from wz_shared.codec import encode_json
from wz_shared.messages import Alert, AlertType, ServiceStatus
from wz_shared.settings import BusSettings
from wz_shared.site import DEFAULT_SITE_PATH, load_site

log = logging.getLogger(__name__)

RATE_HZ = 20_000.0
#: The issue's bound: stored and delivered within this of its publication [s].
BOUND_S = 1.0


def _wait_listening(port: int, process: subprocess.Popen[bytes], timeout_s: float = 30.0) -> None:
    """Until the router accepts TCP connections on ``port`` (a loaded machine imports slowly)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if process.poll() is not None:
            raise RuntimeError(f"the router exited with code {process.returncode}")
        with socket.socket() as probe:
            if probe.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.1)
    raise RuntimeError(f"the router did not listen on {port} within {timeout_s:.0f} s")


def start_router() -> tuple[int, subprocess.Popen[bytes], BusSettings]:
    """A `wz router` on a free loopback port, accepting connections: its port, its process and
    a client's settings for it."""
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    router = subprocess.Popen(
        [sys.executable, "-m", "wz_cli.main", "--log-level", "WARNING", "router", "--listen",
         endpoint],
        cwd=ROOT,
    )  # fmt: skip
    try:
        _wait_listening(port, router)
    except RuntimeError:
        router.kill()
        raise
    return (
        port,
        router,
        BusSettings(mode="client", connect_endpoints=[endpoint], listen_endpoints=[]),
    )


def start_flood(
    endpoint: str, site_id: str, rate_hz: float, flood_s: float, tracks: int = 1
) -> subprocess.Popen[str]:
    """A :mod:`benchmarks.flood_peer` process flooding ``endpoint``'s tracks key with batches
    of ``tracks`` tracks, returned once it says it floods; its stdout gives the last line."""
    flood = subprocess.Popen(
        [sys.executable, "-m", "benchmarks.flood_peer", endpoint, site_id, str(rate_hz),
         str(flood_s), str(tracks)],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        text=True,
    )  # fmt: skip
    assert flood.stdout is not None
    started = json.loads(flood.stdout.readline())
    if started.get("event") != "flooding":
        raise RuntimeError(f"flood peer: {started}")
    return flood


def flood_done(flood: subprocess.Popen[str]) -> dict[str, Any]:
    """Wait for a :func:`start_flood` process to end; its last report (the rate reached)."""
    assert flood.stdout is not None
    done: dict[str, Any] = json.loads(flood.stdout.readline())
    flood.wait(TIMEOUT_S)
    return done


def flood_run(
    flood_s: float, alerts: int, data_dir: Path, log_path: Path, rate_hz: float = RATE_HZ
) -> dict[str, Any]:
    """One run (see the module); the measurements, raw."""
    site_id = load_site(DEFAULT_SITE_PATH).site_id
    port, router, settings = start_router()
    endpoint = settings.connect_endpoints[0]
    http_port = free_port()
    try:
        with (
            _Receiver() as receiver,
            Bus.open(settings, site=site_id, service="alert-service") as bus,
            _gateway(port, http_port, data_dir, log_path=log_path) as http,
        ):
            made = http.post("/v1/webhooks", json={"url": receiver.url("/hook")})
            made.raise_for_status()
            secret = made.json()["secret"]
            publisher = bus.publisher(bus.keys.alerts(AlertType.SPEEDING.value), Alert)
            if not publisher.wait_for_subscribers(TIMEOUT_S):
                raise TimeoutError("the gateway never subscribed to the alerts")
            status_at: list[float] = []
            bus.on(
                bus.keys.status("gateway"),
                ServiceStatus,
                lambda _k, _s: status_at.append(time.monotonic()),
            )
            flood = start_flood(endpoint, site_id, rate_hz, flood_s)
            flood_from = time.monotonic()
            time.sleep(1.0)
            # event id -> (alert id, wall clock and perf counter at its put)
            published: dict[str, tuple[str, float, float]] = {}
            webhooked_s: dict[str, float] = {}
            arrivals: list[tuple[float, str, bytes, dict[str, str]]] = []

            def collect() -> None:
                while len(arrivals) < alerts:
                    arrived, _path, got_id, headers, body = receiver.arrivals.get(timeout=TIMEOUT_S)
                    arrivals.append((arrived, got_id, body, headers))

            collector = threading.Thread(target=collect, daemon=True)
            collector.start()
            for number in range(alerts):
                alert = _alert(site_id, 10_000 + number)
                payload = encode_json(alert)
                event_id = webhooks.alert_event_id(alert)
                published[event_id] = (alert.alert_id, time.time(), time.perf_counter())
                publisher.put_bytes(payload)
                time.sleep(0.5)
            collector.join(TIMEOUT_S)
            done = flood_done(flood)
            flood_to = time.monotonic()
            for arrived, got_id, body, headers in arrivals:
                stamp = int(headers["webhook-timestamp"])
                if webhooks.sign(secret, got_id, stamp, body.decode()) not in headers[
                    "webhook-signature"
                ].split(" "):
                    raise RuntimeError(f"bad signature on {got_id}")
                webhooked_s[got_id] = arrived - published[got_id][2]
            time.sleep(1.0)  # the last track batches stored
            metrics = http.get("/metrics").text
        during = [t for t in status_at if flood_from <= t <= flood_to]
        gaps = [b - a for a, b in zip([flood_from, *during], [*during, flood_to], strict=True)]
    finally:
        router.terminate()
        router.wait(TIMEOUT_S)
    with sqlite3.connect(f"file:{data_dir / 'gateway.sqlite3'}?mode=ro", uri=True) as db:
        rows = db.execute("SELECT alert_id, received_at FROM alerts").fetchall()
    batches_stored = sum(
        float(line.split()[-1])
        for line in metrics.splitlines()
        if line.startswith('wz_gateway_ingested_messages_total{kind="track_batch"}')
    )
    stored_at = dict(rows)
    stored_s = {
        event_id: float(stored_at[alert_id]) - wall
        for event_id, (alert_id, wall, _perf) in published.items()
        if alert_id in stored_at
    }
    dropped = sum(
        float(line.split()[-1])
        for line in metrics.splitlines()
        if line.startswith("wz_gateway_bus_dropped_total")
    )
    locked = [
        line for line in log_path.read_text(errors="replace").splitlines() if "locked" in line
    ]
    return {
        "flood": done,
        "alerts": alerts,
        "stored_s": list(stored_s.values()),
        "webhooked_s": list(webhooked_s.values()),
        "batches_stored": int(batches_stored),
        "batches_dropped": int(dropped),
        "status_max_gap_s": max(gaps) if gaps else None,
        "locked_lines": locked[:5],
        "locked_count": len(locked),
    }


def run(quick: bool) -> dict[str, Any]:
    """A 10 s flood with 16 alerts (3 s with 4 quick)."""
    flood_s, alerts = (3.0, 4) if quick else (10.0, 16)
    with tempfile.TemporaryDirectory(prefix="wz-bench-flood-") as tmp:
        result = flood_run(flood_s, alerts, Path(tmp) / "data", Path(tmp) / "gateway.log")
    return {
        "flood_s": flood_s,
        "target_rate_hz": RATE_HZ,
        "bound_s": BOUND_S,
        **result,
        "stored": summarize(result["stored_s"]) if result["stored_s"] else None,
        "webhooked": summarize(result["webhooked_s"]) if result["webhooked_s"] else None,
    }
