"""Gateway under load: ingestion of the tracker's batches while clients hammer the live API.

The real node (``python -m wz_gateway.node``, default site, SQLite file in a temporary folder,
rate limits off) runs as its own process, a Zenoh peer connected to this one on
``tcp/127.0.0.1`` (multicast off). This process publishes a ``TrackBatch`` of 50 tracks every
50 ms (20 Hz, stamps on the same grid, payloads encoded beforehand). Each track lives 10 s and
then gives its place to a new id, so five tracks end every second and the gateway smooths and
stores five 200-point trajectories a second besides the 1,000 fused points.

Two phases, after a warm-up: ingestion alone, then ingestion while ``LIVE_CLIENTS`` threads
(one keep-alive ``httpx`` connection each) ask ``GET /v1/tracks/live`` back to back and one
more thread pages through ``GET /v1/trajectories`` (1,000 points a page, following the
cursor, from the start again at the end). Reported: the live endpoint's requests per second
and latency (request sent to body read), the page's latency, and the *ingest lag*: from just
before a batch's ``put_bytes`` to the moment its row is committed, seen by a watcher process
that polls the database file read-only every 0.5 ms (its own process, so that the client
threads' hold on this one's interpreter does not delay what it sees; both read the same
monotonic clock). Smoothing time per ended track and the write time per group are the
gateway's own histograms, read from ``/metrics`` at the end.

Usage of the watcher (started by :func:`measure`): ``python -m benchmarks.gateway_live
--watch DATABASE SITE``: one JSON line ``[stamp, monotonic_s]`` per new newest batch, until
its stdin closes.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import queue
import sqlite3
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx
import numpy as np
from prometheus_client.parser import text_string_to_metric_families

from benchmarks.common import ROOT, TIMEOUT_S, free_port, listener_settings, summarize
from wz_shared.bus import Bus
from wz_shared.codec import encode_json
from wz_shared.messages import Track, TrackBatch
from wz_shared.site import DEFAULT_SITE_PATH, Site, load_site

log = logging.getLogger(__name__)

RATE_HZ = 20.0
TRACKS = 50
TRACK_LIFE_S = 10.0
SPEED_MPS = 25.0
LIVE_CLIENTS = 4
PAGE_POINTS = 1000
READ_KEY = "bench-read-4f9Qz7Lm2Xv8Tb3Nc6Wd1Ys5"
#: A plausible fused covariance (x, y, vx, vy) [m^2, m^2/s, m^2/s^2], symmetric positive.
COVARIANCE = [
    0.05,
    0.01,
    0.02,
    0.0,
    0.01,
    0.05,
    0.0,
    0.02,
    0.02,
    0.0,
    0.30,
    0.05,
    0.0,
    0.02,
    0.05,
    0.30,
]


# --- the traffic ------------------------------------------------------------------------------


def batches(site: Site, count: int) -> list[tuple[float, bytes]]:
    """``count`` encoded batches (stamp, payload) at ``RATE_HZ``: slot ``i`` of ``TRACKS`` holds
    a track that drives ``TRACK_LIFE_S`` from station 300 m, then a new id in its place."""
    out = []
    road = site.road_frame
    slots = np.arange(TRACKS)
    offsets = np.where(slots % 2 == 0, -1.83, 1.83)
    for k in range(count):
        stamp = k / RATE_HZ
        shifted = stamp + slots * TRACK_LIFE_S / TRACKS
        life = np.floor(shifted / TRACK_LIFE_S)
        age = shifted - life * TRACK_LIFE_S
        station = 300.0 + SPEED_MPS * age
        x, y = road.to_site(station, offsets)
        tangent = road.tangent_at(station)
        tracks = [
            Track(
                track_id=int(life[i]) * TRACKS + i + 1,
                x_m=float(x[i]),
                y_m=float(y[i]),
                vx_mps=float(SPEED_MPS * tangent[i, 0]),
                vy_mps=float(SPEED_MPS * tangent[i, 1]),
                covariance=COVARIANCE,
                station_m=float(station[i]),
                offset_m=float(offsets[i]),
                speed_mps=SPEED_MPS,
                heading_rad=float(math.atan2(tangent[i, 1], tangent[i, 0])),
                lane_index=0 if offsets[i] < 0 else 1,
                age_s=float(age[i]),
                hits=int(age[i] * RATE_HZ) + 1,
                confirmed=True,
                sources=["lidar-mast"],
                length_m=4.6,
                width_m=1.8,
                last_update_s=stamp,
            )
            for i in range(TRACKS)
        ]
        batch = TrackBatch(
            site=site.site_id, source_id="fusion-tracker", stamp=stamp, cycle_index=k, tracks=tracks
        )
        out.append((stamp, encode_json(batch)))
    return out


# --- the watcher process ----------------------------------------------------------------------


def watch(database: str, site_id: str) -> None:
    """Print ``[stamp, monotonic_s]`` each time the newest stored batch changes, until stdin
    closes (the measuring process's signal)."""
    closed = threading.Event()

    def until_stdin_closes() -> None:
        sys.stdin.read()
        closed.set()

    threading.Thread(target=until_stdin_closes, daemon=True).start()
    connection = sqlite3.connect(f"file:{database}?mode=ro", uri=True, check_same_thread=False)
    last: float | None = None
    while not closed.is_set():
        row = connection.execute(
            "SELECT stamp FROM latest WHERE site = ? AND name = 'tracks'", (site_id,)
        ).fetchone()
        seen = time.monotonic()
        if row is not None and row[0] != last:
            last = row[0]
            sys.stdout.write(json.dumps([last, seen]) + "\n")
            sys.stdout.flush()
        time.sleep(0.0005)
    connection.close()


class Watcher:
    """The watcher as a child process; its reports gathered by a thread."""

    def __init__(self, database: Path, site_id: str) -> None:
        self.seen: list[tuple[float, float]] = []
        self._process = subprocess.Popen(
            [sys.executable, "-m", "benchmarks.gateway_live", "--watch", str(database), site_id],
            cwd=ROOT,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self._process.stdout is not None
        for line in self._process.stdout:
            stamp, seen = json.loads(line)
            self.seen.append((float(stamp), float(seen)))

    def close(self) -> None:
        if self._process.stdin is not None:
            self._process.stdin.close()
        if self._process.wait(TIMEOUT_S) != 0:
            raise RuntimeError("the database watcher failed")
        self._reader.join(TIMEOUT_S)


def ingest_lags_ms(
    published: dict[float, float], seen: list[tuple[float, float]], start_s: float, end_s: float
) -> list[float]:
    """Per batch published in [start_s, end_s) (monotonic): the time until the newest stored
    batch was it or a later one [ms]."""
    lags = []
    order = sorted(seen)
    index = 0
    for stamp, published_at in sorted(published.items()):
        while index < len(order) and order[index][0] < stamp - 1e-9:
            index += 1
        if index == len(order) or not start_s <= published_at < end_s:
            continue
        lags.append(1e3 * (order[index][1] - published_at))
    return lags


# --- the clients ------------------------------------------------------------------------------


class Clients:
    """``LIVE_CLIENTS`` threads on ``/v1/tracks/live`` and one paging ``/v1/trajectories``."""

    def __init__(self, base_url: str) -> None:
        self.base_url = base_url
        self.stop = threading.Event()
        self.live: list[tuple[float, float]] = []  # (sent at, latency s)
        self.pages: list[tuple[float, float]] = []
        self.errors: list[str] = []
        self._lock = threading.Lock()
        self._threads = [
            threading.Thread(target=self._live, daemon=True) for _ in range(LIVE_CLIENTS)
        ]
        self._threads.append(threading.Thread(target=self._trajectories, daemon=True))

    def __enter__(self) -> Clients:
        for thread in self._threads:
            thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop.set()
        for thread in self._threads:
            thread.join(TIMEOUT_S)

    def _client(self) -> httpx.Client:
        return httpx.Client(
            base_url=self.base_url, headers={"X-API-Key": READ_KEY}, timeout=TIMEOUT_S
        )

    def _timed(
        self,
        client: httpx.Client,
        path: str,
        params: dict[str, Any],
        into: list[tuple[float, float]],
    ) -> httpx.Response | None:
        sent = time.monotonic()
        try:
            response = client.get(path, params=params)
            response.read()
        except httpx.HTTPError as exc:
            with self._lock:
                self.errors.append(f"{path}: {exc!r}")
            return None
        latency = time.monotonic() - sent
        with self._lock:
            if response.status_code != 200:
                self.errors.append(f"{path}: {response.status_code}")
                return None
            into.append((sent, latency))
        return response

    def _live(self) -> None:
        with self._client() as client:
            while not self.stop.is_set():
                self._timed(client, "/v1/tracks/live", {}, self.live)

    def _trajectories(self) -> None:
        cursor: str | None = None
        with self._client() as client:
            while not self.stop.is_set():
                params: dict[str, Any] = {"limit": PAGE_POINTS}
                if cursor is not None:
                    params["cursor"] = cursor
                response = self._timed(client, "/v1/trajectories", params, self.pages)
                cursor = None if response is None else response.headers.get("x-next-cursor")


def window(samples: list[tuple[float, float]], start_s: float, end_s: float) -> list[float]:
    """Latencies [ms] of the requests sent in [start_s, end_s)."""
    return [1e3 * latency for sent, latency in samples if start_s <= sent < end_s]


# --- the measurement --------------------------------------------------------------------------


def _metrics(text: str) -> dict[str, float]:
    values: dict[str, float] = {}
    for family in text_string_to_metric_families(text):
        for sample in family.samples:
            if not sample.labels:
                values[sample.name] = sample.value
    return values


def _wait(condition: Callable[[], bool], what: str) -> None:
    deadline = time.monotonic() + TIMEOUT_S
    while time.monotonic() < deadline:
        try:
            if condition():
                return
        except httpx.TransportError:
            pass
        time.sleep(0.1)
    raise TimeoutError(f"timed out waiting for {what}")


def measure(
    warmup_s: float, ingest_only_s: float, loaded_s: float, *, smoothing: bool
) -> dict[str, Any]:
    """One run of the node; without ``smoothing`` tracks end only after an hour (none in the
    run), which shows what smoothing costs the ingestion."""
    site = load_site(DEFAULT_SITE_PATH)
    total_s = warmup_s + ingest_only_s + loaded_s + 1.0
    log.info("gateway_live: encoding %.0f s of batches", total_s)
    payloads = batches(site, math.ceil(total_s * RATE_HZ))
    bus_port, http_port = free_port(), free_port()
    base_url = f"http://127.0.0.1:{http_port}"
    with tempfile.TemporaryDirectory(prefix="wz-bench-gateway-") as data_dir:
        env = {k: v for k, v in os.environ.items() if not k.startswith("WZ_")}
        env.update(
            WZ_BUS_CONNECT_ENDPOINTS=f"tcp/127.0.0.1:{bus_port}",
            WZ_BUS_LISTEN_ENDPOINTS="",
            WZ_LOG_LEVEL="WARNING",
            WZ_LOG_FORMAT="json",
            WZ_GATEWAY_PORT=str(http_port),
            WZ_GATEWAY_DATA_DIR=data_dir,
            WZ_GATEWAY_API_KEYS=f"read:{READ_KEY}",
            WZ_GATEWAY_RATE_LIMIT_PER_S="1000000",
            WZ_GATEWAY_RATE_LIMIT_BURST="1000000",
            WZ_GATEWAY_TRACK_END_AFTER_S="3.0" if smoothing else "3600",
        )
        published: dict[float, float] = {}
        with Bus.open(
            listener_settings(bus_port, shm=True), site=site.site_id, service="bench"
        ) as bus:
            tracks = bus.publisher(bus.keys.tracks, TrackBatch)
            node = subprocess.Popen([sys.executable, "-m", "wz_gateway.node"], cwd=ROOT, env=env)
            watcher: Watcher | None = None
            try:
                if not tracks.wait_for_subscribers(TIMEOUT_S):
                    raise TimeoutError("the gateway never subscribed to the tracks")
                _wait(lambda: httpx.get(f"{base_url}/readyz").status_code == 200, "readiness")
                watcher = Watcher(Path(data_dir) / "gateway.sqlite3", site.site_id)
                done = threading.Event()
                errors: queue.Queue[BaseException] = queue.Queue()

                def publish() -> None:
                    try:
                        start = time.monotonic() + 0.2
                        for k, (stamp, payload) in enumerate(payloads):
                            due = start + k / RATE_HZ
                            while (left := due - time.monotonic()) > 0:
                                time.sleep(left)
                            published[stamp] = time.monotonic()
                            tracks.put_bytes(payload)
                            if done.is_set():
                                return
                    except BaseException as exc:  # surfaced in the measuring thread
                        errors.put(exc)

                publisher = threading.Thread(target=publish, daemon=True)
                publisher.start()
                t0 = time.monotonic()
                time.sleep(warmup_s)
                ingest_only = (time.monotonic(), time.monotonic() + ingest_only_s)
                time.sleep(ingest_only_s)
                with Clients(base_url) as clients:
                    time.sleep(1.0)  # the clients' connections open
                    loaded = (time.monotonic(), time.monotonic() + loaded_s)
                    time.sleep(loaded_s)
                done.set()
                publisher.join(TIMEOUT_S)
                if not errors.empty():
                    raise errors.get()
                time.sleep(1.0)  # the last batches stored
                metrics = _metrics(httpx.get(f"{base_url}/metrics").text)
                rows = httpx.get(
                    f"{base_url}/v1/trajectories",
                    params={"limit": 1},
                    headers={"X-API-Key": READ_KEY},
                ).status_code
                if rows != 200:
                    raise RuntimeError(f"/v1/trajectories answered {rows} at the end")
            finally:
                if watcher is not None:
                    watcher.close()
                node.terminate()
                node.wait(TIMEOUT_S)
            invalid = bus.stats.snapshot()["invalid"]
            if invalid:
                raise RuntimeError(f"invalid messages on the bench's side: {invalid}")
    assert watcher is not None
    if clients.errors:
        raise RuntimeError(f"{len(clients.errors)} failed requests, first: {clients.errors[0]}")
    live = window(clients.live, *loaded)
    pages = window(clients.pages, *loaded)
    smoothed = metrics.get("wz_gateway_smoothed_tracks_total", 0.0)
    log.info("gateway_live: %.0f s in all", time.monotonic() - t0)
    return {
        "tracks_per_batch": TRACKS,
        "rate_hz": RATE_HZ,
        "track_life_s": TRACK_LIFE_S,
        "batch_bytes": len(payloads[0][1]),
        "live_clients": LIVE_CLIENTS,
        "page_points": PAGE_POINTS,
        "ingest_only": {
            "duration_s": ingest_only_s,
            "ingest_lag_ms": summarize(ingest_lags_ms(published, watcher.seen, *ingest_only)),
        },
        "loaded": {
            "duration_s": loaded_s,
            "ingest_lag_ms": summarize(ingest_lags_ms(published, watcher.seen, *loaded)),
            "live": {
                "requests": len(live),
                "requests_per_s": len(live) / loaded_s,
                "latency_ms": summarize(live),
            },
            "trajectories": {"requests": len(pages), "latency_ms": summarize(pages)},
        },
        "batches_published": len(published),
        "points_stored": metrics.get("wz_gateway_ingested_track_points_total", 0.0),
        "smoothing": {
            "tracks": smoothed,
            "points": metrics.get("wz_gateway_smoothed_track_points_total", 0.0),
            "mean_ms": 1e3
            * metrics.get("wz_gateway_smoothing_seconds_sum", 0.0)
            / max(smoothed, 1.0),
        },
        "write_group_mean_ms": 1e3
        * metrics.get("wz_gateway_write_seconds_sum", 0.0)
        / max(metrics.get("wz_gateway_write_seconds_count", 0.0), 1.0),
    }


def run(quick: bool) -> dict[str, Any]:
    """5 s warm-up, 10 s of ingestion alone, 20 s loaded (quick: 3, 3 and 5 s); with the
    smoothing of ended tracks, then without."""
    phases = (3.0, 3.0, 5.0) if quick else (5.0, 10.0, 20.0)
    variants = {}
    requests_log = logging.getLogger("httpx")
    level = requests_log.level
    requests_log.setLevel(logging.WARNING)  # a log line per request would load the clients
    try:
        for name, smoothing in (("smoothing", True), ("no_smoothing", False)):
            log.info("gateway_live: %s", name)
            variants[name] = measure(*phases, smoothing=smoothing)
    finally:
        requests_log.setLevel(level)
    return {"variants": variants}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.gateway_live")
    parser.add_argument("--watch", nargs=2, metavar=("DATABASE", "SITE"), required=True)
    args = parser.parse_args(argv)
    watch(*args.watch)


if __name__ == "__main__":
    main()
