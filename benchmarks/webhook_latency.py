"""Gateway webhooks: from an alert published on the bus to its signed POST at the receiver.

The real gateway node (``python -m wz_gateway.node``, SQLite in a temporary folder, default
site) runs as its own process, a Zenoh peer connected to this one on ``tcp/127.0.0.1``
(multicast off). The receiver is an ``http.server`` (HTTP/1.1, keep-alive) in a thread of this
process on a loopback port, subscribed through the API. Each sample is one new alert
(``alerts/speeding``, encoded beforehand); the clock runs from just before its ``put_bytes`` to
the receiver's handler having read the request whose ``webhook-id`` is that alert's. The path:
Zenoh, the gateway's writer queue, the SQLite transaction that stores the alert and its outbox
row, the delivery thread's claim (a second transaction), signing, the HTTP POST. One alert at
a time, after 10 unmeasured ones (first connection, warm caches); every signature is checked
(outside the timing) with the subscription's secret.

Two variants: one subscription, and four (the same alert to four receivers' URLs, delivered in
parallel, one request in flight per subscription): there the time runs to the last of the four.
"""

from __future__ import annotations

import logging
import os
import queue
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

import httpx

from benchmarks.common import ROOT, TIMEOUT_S, free_port, listener_settings, summarize
from wz_gateway import webhooks
from wz_shared.bus import Bus
from wz_shared.codec import encode_json
from wz_shared.messages import Alert, AlertSeverity, AlertType
from wz_shared.site import DEFAULT_SITE_PATH, load_site

log = logging.getLogger(__name__)

ADMIN_KEY = "bench-admin-9fK2xQ7vL4mZ8cW1"
WARMUP = 10


class _Receiver:
    """Arrivals ``(perf_counter, path, webhook-id, headers, body)`` in a queue."""

    def __init__(self) -> None:
        self.arrivals: queue.Queue[tuple[float, str, str, dict[str, str], bytes]] = queue.Queue()
        arrivals = self.arrivals

        class Handler(BaseHTTPRequestHandler):
            protocol_version = "HTTP/1.1"

            def do_POST(self) -> None:
                body = self.rfile.read(int(self.headers.get("content-length", "0")))
                arrived = time.perf_counter()
                headers = {k.lower(): v for k, v in self.headers.items()}
                self.send_response(204)
                self.send_header("content-length", "0")
                self.end_headers()
                arrivals.put((arrived, self.path, headers.get("webhook-id", ""), headers, body))

            def log_message(self, format: str, *args: Any) -> None:
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.server.daemon_threads = True
        self.port = self.server.server_address[1]
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)

    def url(self, path: str) -> str:
        return f"http://127.0.0.1:{self.port}{path}"

    def __enter__(self) -> _Receiver:
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.server.shutdown()
        self.server.server_close()


def _alert(site_id: str, number: int) -> Alert:
    return Alert(
        site=site_id,
        source_id="alert-service",
        stamp=0.1 * number,
        alert_id=f"bench-{number}",
        alert_type=AlertType.SPEEDING,
        severity=AlertSeverity.WARNING,
        track_id=number,
        station_m=700.0,
        offset_m=-1.83,
        speed_mps=29.0,
        measured_value=29.0,
        threshold_value=26.8,
        description="speeding: 65 mph in the 55 mph zone",
        episode_id=f"bench-ep-{number}",
        onset_stamp=0.1 * number,
        value_unit="m/s",
        evidence={"speed_limit_mps": 24.587},
    )


@contextmanager
def _gateway(
    bus_port: int, http_port: int, data_dir: Path, *, log_path: Path | None = None
) -> Iterator[httpx.Client]:
    """The gateway node connected to ``bus_port``, ready; its output in ``log_path``."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("WZ_")}
    env.update(
        WZ_BUS_CONNECT_ENDPOINTS=f"tcp/127.0.0.1:{bus_port}",
        WZ_BUS_LISTEN_ENDPOINTS="",
        WZ_LOG_LEVEL="WARNING",
        WZ_LOG_FORMAT="json",
        WZ_GATEWAY_PORT=str(http_port),
        WZ_GATEWAY_DATA_DIR=str(data_dir),
        WZ_GATEWAY_API_KEYS=f"admin:{ADMIN_KEY}",
        WZ_GATEWAY_WEBHOOK_ALLOWED_NETWORKS="127.0.0.1/32",
    )
    out = None if log_path is None else log_path.open("ab")
    node = subprocess.Popen(
        [sys.executable, "-m", "wz_gateway.node"],
        cwd=ROOT,
        env=env,
        stdout=out,
        stderr=None if out is None else subprocess.STDOUT,
    )
    http = httpx.Client(
        base_url=f"http://127.0.0.1:{http_port}",
        timeout=TIMEOUT_S,
        headers={"X-API-Key": ADMIN_KEY},
    )
    try:
        deadline = time.monotonic() + TIMEOUT_S
        while True:
            try:
                if http.get("/readyz").status_code == 200:
                    break
            except httpx.TransportError:
                pass
            if time.monotonic() > deadline or node.poll() is not None:
                raise TimeoutError("the gateway did not become ready")
            time.sleep(0.05)
        yield http
    finally:
        http.close()
        node.terminate()
        node.wait(TIMEOUT_S)
        if out is not None:
            out.close()


def _measure(
    bus: Bus, receiver: _Receiver, site_id: str, secrets: dict[str, str], first: int, samples: int
) -> list[float]:
    """Latencies [ms] to the last of the subscriptions' receivers, alerts first, first+1..."""
    publisher = bus.publisher(bus.keys.alerts(AlertType.SPEEDING.value), Alert)
    if not publisher.wait_for_subscribers(TIMEOUT_S):
        raise TimeoutError("the gateway never subscribed to the alerts")
    latencies_ms: list[float] = []
    for number in range(first, first + WARMUP + samples):
        alert = _alert(site_id, number)
        webhook_id = webhooks.alert_event_id(alert)
        payload = encode_json(alert)
        started = time.perf_counter()
        publisher.put_bytes(payload)
        waiting = set(secrets)
        last = started
        while waiting:
            arrived, path, got_id, headers, body = receiver.arrivals.get(timeout=TIMEOUT_S)
            if got_id != webhook_id:
                raise RuntimeError(f"unexpected webhook {got_id} while waiting for {webhook_id}")
            expected = webhooks.sign(
                secrets[path], got_id, int(headers["webhook-timestamp"]), body.decode()
            )
            if expected not in headers["webhook-signature"].split(" "):
                raise RuntimeError(f"bad signature on {got_id} to {path}")
            waiting.discard(path)
            last = max(last, arrived)
        if number >= first + WARMUP:
            latencies_ms.append(1e3 * (last - started))
    return latencies_ms


def run(quick: bool) -> dict[str, Any]:
    """200 alerts per variant (30 quick), one gateway process."""
    samples = 30 if quick else 200
    site_id = load_site(DEFAULT_SITE_PATH).site_id
    port, http_port = free_port(), free_port()
    results: dict[str, Any] = {}
    with (
        tempfile.TemporaryDirectory(prefix="wz-bench-webhooks-") as data_dir,
        _Receiver() as receiver,
        Bus.open(listener_settings(port, shm=True), site=site_id, service="bench") as bus,
        _gateway(port, http_port, Path(data_dir)) as http,
    ):
        secrets: dict[str, str] = {}
        next_alert = 0
        for name, subscriptions in (("one_subscription", 1), ("four_subscriptions", 4)):
            while len(secrets) < subscriptions:
                path = f"/hooks/{len(secrets)}"
                made = http.post("/v1/webhooks", json={"url": receiver.url(path)})
                made.raise_for_status()
                secrets[path] = made.json()["secret"]
            log.info("webhook_latency: %s, %d samples", name, samples)
            latencies = _measure(bus, receiver, site_id, secrets, next_alert, samples)
            next_alert += WARMUP + samples
            results[name] = {"subscriptions": subscriptions, "latency_ms": summarize(latencies)}
        metrics = http.get("/metrics").text
    delivered = next(
        float(line.split()[-1])
        for line in metrics.splitlines()
        if line.startswith('wz_gateway_webhook_events_total{state="delivered"}')
    )
    return {"samples": samples, "warmup": WARMUP, "delivered": int(delivered), "variants": results}
