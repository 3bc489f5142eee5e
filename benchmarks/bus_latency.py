"""One-way latency between two processes over Zenoh on loopback, by ping-pong.

The measuring process sends sample ``i`` on ``PING_KEY``; the echo peer republishes it on
``PONG_KEY`` through the same API; the clock stops when sample ``i`` is back. One-way latency is
half the round trip. Samples go one at a time (no pipelining), after a warm-up.

Paths compared
--------------
Small messages (about 200 bytes):

- ``zenoh``: plain Zenoh publisher and a Python callback on each side, no codec. The callback
  stamps the arrival; the baseline for the rest.
- ``zenoh-fifo``: plain Zenoh with its own FIFO channel (``FifoChannel``): the receiving
  thread blocks in ``recv()`` (in Rust) instead of running a Python callback; what our queue
  would cost if it were Zenoh's.
- ``bus-raw``: our :class:`~wz_shared.bus.Bus` with bytes: ``put_bytes`` and a
  ``subscribe_raw`` FIFO queue (the sample crosses from Zenoh's thread to the service's thread).
- ``bus-callback``: our codec without the queue: ``put`` (encode) and ``on`` (decode on Zenoh's
  thread).
- ``bus-json``: the path a service uses: ``put`` (encode) and ``subscribe`` (FIFO queue, decode
  on the service's thread).

LiDAR frames (131072 points x 4 float32, 2 MB), with Zenoh's shared memory on (its default) and
off:

- ``zenoh``: the envelope as plain bytes, Python callbacks.
- ``bus-frames``: ``encode_lidar_frame``, ``put_bytes``, ``subscribe_frames`` FIFO, decode;
  the echo decodes and re-encodes, so both directions pay what a producer and a consumer pay.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import zenoh

from benchmarks.common import (
    FRAME_POINTS,
    PING_KEY,
    PONG_KEY,
    SITE,
    TIMEOUT_S,
    Peer,
    Watchdog,
    frame_meta,
    frame_points,
    free_port,
    listener_settings,
    raw_index,
    raw_matched,
    small_message,
    small_raw,
    summarize,
)
from wz_shared import codec
from wz_shared.bus import Bus
from wz_shared.messages import LidarFrameMeta, RadarScan

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class _PingPath:
    """How to send sample ``i`` and get its round-trip time [s]; whether the echo is reachable."""

    ping: Callable[[int], float]
    matched: Callable[[], bool]


class _Arrivals:
    """Arrival times stamped in a Zenoh callback, handed to the waiting thread."""

    def __init__(self) -> None:
        self._event = threading.Event()
        self.stamp = 0.0
        self.index = -1
        self.count = 0

    def arrived(self, index: int) -> None:
        self.stamp = time.perf_counter()
        self.index = index
        self.count += 1
        self._event.set()

    def wait(self) -> float:
        if not self._event.wait(TIMEOUT_S):
            raise TimeoutError(f"no pong within {TIMEOUT_S} s")
        self._event.clear()
        return self.stamp


def _zenoh_pinger(
    bus: Bus, stack: contextlib.ExitStack, make_payload: Callable[[int], bytes], check_index: bool
) -> _PingPath:
    arrivals = _Arrivals()

    def on_pong(sample: zenoh.Sample) -> None:
        # Small payloads carry their index; 2 MB ones are not copied out just to read it.
        arrivals.arrived(raw_index(sample.payload.to_bytes()) if check_index else -1)

    subscriber = bus.session.declare_subscriber(PONG_KEY, on_pong)
    publisher = bus.session.declare_publisher(
        PING_KEY,
        congestion_control=zenoh.CongestionControl.BLOCK,
        reliability=zenoh.Reliability.RELIABLE,
    )
    # A callback subscriber still declared at exit hangs the interpreter: undeclare on the way out.
    stack.callback(subscriber.undeclare)
    stack.callback(publisher.undeclare)

    def ping(index: int) -> float:
        payload = make_payload(index)
        start = time.perf_counter()
        publisher.put(payload)
        stop = arrivals.wait()
        if check_index and arrivals.index != index:
            raise RuntimeError(f"sent {index}, got {arrivals.index} back")
        if arrivals.count != index + 1:
            raise RuntimeError(f"{arrivals.count} pongs for {index + 1} pings")
        return stop - start

    return _PingPath(ping, lambda: raw_matched(publisher))


def _zenoh_fifo_pinger(bus: Bus, stack: contextlib.ExitStack) -> _PingPath:
    pongs = bus.session.declare_subscriber(PONG_KEY, zenoh.handlers.FifoChannel(1024))
    publisher = bus.session.declare_publisher(
        PING_KEY,
        congestion_control=zenoh.CongestionControl.BLOCK,
        reliability=zenoh.Reliability.RELIABLE,
    )
    stack.callback(pongs.undeclare)
    stack.callback(publisher.undeclare)
    returned = [0]
    stack.enter_context(Watchdog(bus.session, PONG_KEY, lambda: returned[0]))

    def ping(index: int) -> float:
        payload = small_raw(index)
        start = time.perf_counter()
        publisher.put(payload)
        sample = pongs.recv()
        stop = time.perf_counter()
        received = sample.payload.to_bytes()
        if not received:
            raise TimeoutError(f"no pong within {TIMEOUT_S} s")
        if raw_index(received) != index:
            raise RuntimeError(f"sent {index}, got {raw_index(received)} back")
        returned[0] += 1
        return stop - start

    return _PingPath(ping, lambda: raw_matched(publisher))


def _bus_raw_pinger(bus: Bus) -> _PingPath:
    pongs = bus.subscribe_raw(PONG_KEY)
    publisher = bus.publisher(PING_KEY, RadarScan)

    def ping(index: int) -> float:
        payload = small_raw(index)
        start = time.perf_counter()
        publisher.put_bytes(payload)
        received = pongs.recv(TIMEOUT_S)
        stop = time.perf_counter()
        if received is None or raw_index(received) != index:
            raise RuntimeError(f"sent {index}, got {received and raw_index(received)} back")
        return stop - start

    return _PingPath(ping, lambda: publisher.matched)


def _bus_json_pinger(bus: Bus) -> _PingPath:
    pongs = bus.subscribe(PONG_KEY, RadarScan)
    publisher = bus.publisher(PING_KEY, RadarScan)

    def ping(index: int) -> float:
        message = small_message(index)
        start = time.perf_counter()
        publisher.put(message)
        received = pongs.recv(TIMEOUT_S)
        stop = time.perf_counter()
        if received is None or received.scan_index != index:
            raise RuntimeError(f"sent {index}, got {received and received.scan_index} back")
        return stop - start

    return _PingPath(ping, lambda: publisher.matched)


def _bus_callback_pinger(bus: Bus) -> _PingPath:
    arrivals = _Arrivals()
    bus.on(PONG_KEY, RadarScan, lambda _key, message: arrivals.arrived(message.scan_index))
    publisher = bus.publisher(PING_KEY, RadarScan)

    def ping(index: int) -> float:
        message = small_message(index)
        start = time.perf_counter()
        publisher.put(message)
        stop = arrivals.wait()
        if arrivals.index != index:
            raise RuntimeError(f"sent {index}, got {arrivals.index} back")
        return stop - start

    return _PingPath(ping, lambda: publisher.matched)


def _bus_frames_pinger(bus: Bus) -> _PingPath:
    points = frame_points()
    pongs = bus.subscribe_frames(PONG_KEY, LidarFrameMeta, mode="fifo", capacity=4)
    publisher = bus.publisher(PING_KEY, LidarFrameMeta, block=True)

    def ping(index: int) -> float:
        meta = frame_meta(index)
        start = time.perf_counter()
        publisher.put_bytes(codec.encode_lidar_frame(meta, points))
        frame = pongs.recv(TIMEOUT_S)
        stop = time.perf_counter()
        if frame is None or frame.meta.frame_index != index:
            raise RuntimeError(f"sent frame {index}, got {frame and frame.meta.frame_index}")
        if index == 0 and not np.array_equal(frame.points(), points):
            raise RuntimeError("the echoed frame's points differ from the ones sent")
        return stop - start

    return _PingPath(ping, lambda: publisher.matched)


def _frame_bytes(index: int) -> bytes:
    return index.to_bytes(8, "little") + bytes(FRAME_POINTS * 16)


def _make_pinger(bus: Bus, stack: contextlib.ExitStack, path: str) -> _PingPath:
    if path == "zenoh":
        return _zenoh_pinger(bus, stack, small_raw, check_index=True)
    if path == "zenoh-frames":
        return _zenoh_pinger(bus, stack, _frame_bytes, check_index=False)
    if path == "zenoh-fifo":
        return _zenoh_fifo_pinger(bus, stack)
    if path == "bus-raw":
        return _bus_raw_pinger(bus)
    if path == "bus-json":
        return _bus_json_pinger(bus)
    if path == "bus-callback":
        return _bus_callback_pinger(bus)
    if path == "bus-frames":
        return _bus_frames_pinger(bus)
    raise ValueError(f"unknown path {path!r}")


def ping_pong(path: str, samples: int, warmup: int, *, shm: bool = True) -> list[float]:
    """One-way latencies [µs] of ``samples`` round trips along ``path`` with a fresh echo.

    ``warmup`` round trips go first and are not kept.
    """
    port = free_port()
    echo_api = "zenoh" if path == "zenoh-frames" else path
    shm_flag = "on" if shm else "off"
    settings = listener_settings(port, shm=shm)
    with Bus.open(settings, site=SITE, service="bench-latency") as bus:
        with contextlib.ExitStack() as stack:
            ping_path = _make_pinger(bus, stack, path)
            with Peer("echo", echo_api, f"tcp/127.0.0.1:{port}", "--shm", shm_flag) as peer:
                peer.expect("ready")
                # The echo knows our pong subscriber; wait until we know its ping subscriber too,
                # or the first ping goes nowhere.
                deadline = time.monotonic() + TIMEOUT_S
                while not ping_path.matched():
                    if time.monotonic() > deadline:
                        raise TimeoutError(f"the echo's subscriber never matched ({path})")
                    time.sleep(0.005)
                count = warmup + samples
                round_trips_s = [ping_path.ping(index) for index in range(count)][warmup:]
        invalid = bus.stats.snapshot()["invalid"]
    if invalid:
        raise RuntimeError(f"{path}: invalid samples {invalid}")
    return [0.5e6 * rtt for rtt in round_trips_s]


def payload_bytes(path: str) -> int:
    """Size of one sample on ``path`` [bytes] (JSON sizes vary by a byte or two with the index)."""
    if path in ("zenoh", "zenoh-fifo", "bus-raw"):
        return len(small_raw(0))
    if path in ("bus-json", "bus-callback"):
        return len(codec.encode(small_message(1000)))
    if path == "zenoh-frames":
        return len(_frame_bytes(0))
    return len(codec.encode_lidar_frame(frame_meta(0), frame_points()))


SMALL_PATHS = ("zenoh", "zenoh-fifo", "bus-raw", "bus-callback", "bus-json")
FRAME_PATHS = ("zenoh-frames", "bus-frames")


def run(quick: bool) -> dict[str, Any]:
    """Ping-pong every path.

    Small messages: 4 rounds of 500 samples per path (1 of 300 quick); frames: 4 rounds of 50
    (1 of 40 quick). Each round is a fresh pair of processes and the rounds go round-robin over
    the paths, so a burst of other work on the machine does not land on one path only; the
    samples of a path's rounds are pooled.
    """
    rounds = 1 if quick else 4
    small_samples, frame_samples = (300, 40) if quick else (500, 50)
    variants = [(path, path, True, small_samples, 200) for path in SMALL_PATHS] + [
        (f"{path}{'' if shm else '-noshm'}", path, shm, frame_samples, 10)
        for shm in (True, False)
        for path in FRAME_PATHS
    ]
    pooled: dict[str, list[float]] = {name: [] for name, *_ in variants}
    round_p50: dict[str, list[float]] = {name: [] for name, *_ in variants}
    for number in range(rounds):
        for name, path, shm, samples, warmup in variants:
            log.info("bus_latency: round %d/%d, %s, %d samples", number + 1, rounds, name, samples)
            one_way_us = ping_pong(path, samples, warmup, shm=shm)
            pooled[name] += one_way_us
            round_p50[name].append(float(np.median(one_way_us)))
    table = {
        name: {
            "path": path,
            "shm": shm,
            "payload_bytes": payload_bytes(path),
            "rounds": rounds,
            "warmup_per_round": warmup,
            "one_way_us": summarize(pooled[name]),
            "round_p50_us": round_p50[name],
        }
        for name, path, shm, _, warmup in variants
    }
    small = {name: table[name] for name in SMALL_PATHS}
    frames = {name: entry for name, entry in table.items() if name not in small}

    def ratio(table: dict[str, Any], a: str, b: str, stat: str = "p50") -> float:
        return float(table[a]["one_way_us"][stat] / table[b]["one_way_us"][stat])

    return {
        "small": small,
        "frames": frames,
        "ratios": {
            "bus-json / zenoh (p50)": ratio(small, "bus-json", "zenoh"),
            "bus-json / zenoh (p99)": ratio(small, "bus-json", "zenoh", "p99"),
            "bus-raw / zenoh (p50): our queue, no codec": ratio(small, "bus-raw", "zenoh"),
            "bus-json / bus-raw (p50): the codec on top of our queue": ratio(
                small, "bus-json", "bus-raw"
            ),
            "bus-callback / zenoh (p50): codec, no queue": ratio(small, "bus-callback", "zenoh"),
            "zenoh-fifo / zenoh (p50): Zenoh's own queue": ratio(small, "zenoh-fifo", "zenoh"),
            "bus-raw / zenoh-fifo (p50): our queue vs Zenoh's": ratio(
                small, "bus-raw", "zenoh-fifo"
            ),
            "bus-frames / zenoh-frames, shm (p50)": ratio(frames, "bus-frames", "zenoh-frames"),
            "bus-frames / zenoh-frames, no shm (p50)": ratio(
                frames, "bus-frames-noshm", "zenoh-frames-noshm"
            ),
            "bus-frames no shm / shm (p50)": ratio(frames, "bus-frames-noshm", "bus-frames"),
        },
    }
