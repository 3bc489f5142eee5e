"""What the bus's trust costs: mutual TLS and access control against today's plain bus.

Three processes on loopback, as on the trailer's box: a router (``wz router``), this process
and a peer (:mod:`benchmarks.trust_peer`), both clients of the router, so every sample crosses
the router twice as on the box. The router runs in one of three ways, each measured in the
same run, round-robin over several rounds (fresh processes each round):

- ``plain``: TCP, no access control (the development stack's router, as every link was
  before the trust issue);
- ``tls``: mutual TLS with a certificate per session (``wz credentials``), no access control;
- ``tls+acl``: the deployed trailer router as shipped (``deploy/zenoh/trailer-router.json5``):
  mutual TLS and the access control by role (:mod:`wz_shared.trust`), the sessions holding
  the roles whose keys they use (tracker pings, alert service pongs, a detector streams).

Measured: the session's opening (TCP connect, TLS handshake, Zenoh's own), one-way latency by
ping-pong (200-byte samples, one in flight, after a warm-up; half the round trip), and
throughput (200-byte samples and 2 MB LiDAR-sized frames, as fast as the peer puts them,
every one counted, in order). Plain Zenoh sessions (bytes, Python callbacks): what is
measured is the transport and the router, not the codec.
"""

from __future__ import annotations

import logging
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import ROOT, TIMEOUT_S, Peer, free_port, summarize
from benchmarks.trust_peer import PING_KEY, PONG_KEY, SITE, STREAM_KEY, open_session, publisher
from wz_cli.credentials import make_site

log = logging.getLogger(__name__)

TRAILER_ROUTER = ROOT / "deploy" / "zenoh" / "trailer-router.json5"
VARIANTS = ("plain", "tls", "tls+acl")


class Router:
    """``wz router`` for one variant, on a free loopback port."""

    def __init__(self, variant: str, credentials: Path) -> None:
        port = free_port()
        self.variant = variant
        argv = [sys.executable, "-m", "wz_cli.main", "--log-level", "WARNING", "router"]
        if variant == "plain":
            self.endpoint = f"tcp/127.0.0.1:{port}"
            argv += ["--listen", self.endpoint]
        else:
            self.endpoint = f"tls/127.0.0.1:{port}"
            router_dir = credentials / SITE / "router"
            if variant == "tls":  # the router's own certificate, no access control
                argv += ["--listen", self.endpoint, "--tls-dir", str(router_dir)]
            else:
                argv += ["--config", str(TRAILER_ROUTER), "--listen", self.endpoint]
                argv += ["--connect", "", "--tls-dir", str(router_dir)]
        self._process = subprocess.Popen(argv, cwd=ROOT)
        self.credentials = credentials

    def tls_dir(self, role: str) -> Path | None:
        return None if self.variant == "plain" else self.credentials / SITE / role

    def peer_args(self, role: str) -> list[str]:
        folder = self.tls_dir(role)
        return [] if folder is None else ["--tls-dir", str(folder)]

    def close(self) -> None:
        self._process.terminate()
        self._process.wait(10)


def _open(router: Router, role: str) -> tuple[Any, float]:
    """A session of ``role``, once the router accepts it; the last opening's time [s]."""
    deadline = time.monotonic() + TIMEOUT_S
    while True:
        start = time.perf_counter()
        try:
            session = open_session(router.endpoint, router.tls_dir(role))
            return session, time.perf_counter() - start
        except Exception:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.1)


def opening(router: Router, count: int) -> list[float]:
    """Open and close ``count`` sessions as the tracker [s each]."""
    _open(router, "fusion-tracker")[0].close()  # the router is up
    times = []
    for _ in range(count):
        session, seconds = _open(router, "fusion-tracker")
        times.append(seconds)
        session.close()
    return times


def latency(router: Router, samples: int) -> list[float]:
    """One-way latency of ``samples`` 200-byte pings [s]."""
    session, _ = _open(router, "fusion-tracker")
    arrived = threading.Event()
    stamp = [0.0]

    def on_pong(_sample: Any) -> None:
        stamp[0] = time.perf_counter()
        arrived.set()

    sub = session.declare_subscriber(PONG_KEY, on_pong)
    ping = publisher(session, PING_KEY)
    times: list[float] = []
    try:
        with Peer("echo", router.endpoint, *router.peer_args("alert-service"),
                  module="benchmarks.trust_peer") as echo:  # fmt: skip
            echo.expect("ready")
            payload = bytes(200)
            # Routes settle: pings until one comes back, then a warm-up.
            deadline = time.monotonic() + TIMEOUT_S
            while True:
                arrived.clear()
                ping.put(payload)
                if arrived.wait(0.2):
                    break
                if time.monotonic() > deadline:
                    raise TimeoutError(f"{router.variant}: no pong")
            for index in range(samples + 100):
                arrived.clear()
                start = time.perf_counter()
                ping.put(payload)
                if not arrived.wait(TIMEOUT_S):
                    raise TimeoutError(f"{router.variant}: pong {index} lost")
                if index >= 100:
                    times.append((stamp[0] - start) / 2.0)
    finally:
        sub.undeclare()
        ping.undeclare()
        session.close()
    return times


def throughput(router: Router, count: int, size: int) -> dict[str, float]:
    """``count`` samples of ``size`` bytes from a detector's session, all received here."""
    session, _ = _open(router, "fusion-tracker")
    received = [0]
    in_order = [True]
    done = threading.Event()
    first_last = [0.0, 0.0]

    def on_sample(sample: Any) -> None:
        index = int.from_bytes(sample.payload.to_bytes()[:8], "little")
        if index != received[0]:
            in_order[0] = False
        if received[0] == 0:
            first_last[0] = time.perf_counter()
        received[0] += 1
        if received[0] == count:
            first_last[1] = time.perf_counter()
            done.set()

    sub = session.declare_subscriber(STREAM_KEY, on_sample)
    try:
        with Peer("publish", router.endpoint, *router.peer_args("lidar-detector"),
                  "--count", str(count), "--bytes", str(size),
                  module="benchmarks.trust_peer") as source:  # fmt: skip
            source.expect("ready")
            time.sleep(0.5)  # the subscriber's route at the router
            source.send("go")
            report = source.expect("done", timeout_s=300.0)
            if not done.wait(120.0):
                raise TimeoutError(f"{router.variant}: {received[0]} of {count} arrived")
    finally:
        sub.undeclare()
        session.close()
    seconds = first_last[1] - first_last[0]
    return {
        "count": count,
        "bytes": size,
        "received": received[0],
        "in_order": in_order[0],
        "msg_per_s": (count - 1) / seconds,
        "mb_per_s": (count - 1) * size / seconds / 1e6,
        "put_per_s": count / report["put_s"],
    }


def run(quick: bool) -> dict[str, Any]:
    rounds = 2 if quick else 3
    pings = 300 if quick else 2000
    small = 20_000 if quick else 200_000
    frames = 50 if quick else 300
    opens = 5 if quick else 20
    raw: dict[str, dict[str, list[Any]]] = {
        v: {"open": [], "latency": [], "small": [], "frames": []} for v in VARIANTS
    }
    with tempfile.TemporaryDirectory(prefix="wz-bench-trust-") as tmp:
        credentials = Path(tmp)
        make_site(credentials, SITE)
        for round_index in range(rounds):
            for variant in VARIANTS:
                log.info("bus_trust: round %d, %s", round_index + 1, variant)
                router = Router(variant, credentials)
                try:
                    raw[variant]["open"] += opening(router, opens)
                    raw[variant]["latency"].append(latency(router, pings))
                    raw[variant]["small"].append(throughput(router, small, 200))
                    raw[variant]["frames"].append(throughput(router, frames, 2_097_152))
                finally:
                    router.close()
    results: dict[str, Any] = {}
    for variant, data in raw.items():
        all_latency = [t for one in data["latency"] for t in one]

        def median_round(runs: list[dict[str, float]]) -> dict[str, Any]:
            rates = sorted(runs, key=lambda r: r["msg_per_s"])
            return {**rates[len(rates) // 2], "rounds": [r["msg_per_s"] for r in runs]}

        results[variant] = {
            "open_ms": summarize([t * 1e3 for t in data["open"]]),
            "latency_us": summarize([t * 1e6 for t in all_latency]),
            "latency_round_p50_us": [float(np.median(one)) * 1e6 for one in data["latency"]],
            "small": median_round(data["small"]),
            "frames": median_round(data["frames"]),
        }
    plain = results["plain"]
    ratios = {}
    for variant in ("tls", "tls+acl"):
        mine = results[variant]
        ratios[variant] = {
            "latency_p50": mine["latency_us"]["p50"] / plain["latency_us"]["p50"],
            "latency_p99": mine["latency_us"]["p99"] / plain["latency_us"]["p99"],
            "small_msg_per_s": mine["small"]["msg_per_s"] / plain["small"]["msg_per_s"],
            "frames_msg_per_s": mine["frames"]["msg_per_s"] / plain["frames"]["msg_per_s"],
            "open_p50": mine["open_ms"]["p50"] / plain["open_ms"]["p50"],
        }
    ratios["acl_over_tls"] = {
        "latency_p50": results["tls+acl"]["latency_us"]["p50"]
        / results["tls"]["latency_us"]["p50"],
        "small_msg_per_s": results["tls+acl"]["small"]["msg_per_s"]
        / results["tls"]["small"]["msg_per_s"],
    }
    return {
        "rounds": rounds,
        "pings_per_round": pings,
        "variants": results,
        "ratios": ratios,
    }
