"""Throughput between two processes over Zenoh on loopback: one publishes, the other counts.

The peer publishes ``count`` numbered samples on ``STREAM_KEY`` as fast as it can, with blocking
congestion control (nothing may be dropped). The measuring process takes every one, checks that
they arrive in order, and stamps the first and the last: the rate is
``(count - 1) / (last - first)``. After the peer has stopped, the count must be exact: none lost,
none extra.

Paths compared
--------------
- ``zenoh``: plain Zenoh publisher ``put(bytes)``; a Python callback counts (reads the index,
  no codec).
- ``zenoh-fifo``: plain Zenoh, taken from Zenoh's own ``FifoChannel`` with ``recv()`` on the
  main thread (our queue's job, done by Zenoh).
- ``bus-raw``: our :class:`~wz_shared.bus.Bus`: ``put_bytes``; ``subscribe_raw`` FIFO,
  taken with ``recv`` on the measuring process's main thread (queue, no codec).
- ``bus-json``: ``put`` (encode) of a ~200-byte :class:`RadarScan`; ``subscribe`` FIFO with
  decode on ``recv``: what a service does.
- ``zenoh-frames`` / ``bus-frames``: 2 MB LiDAR frames, plain bytes with a counting callback,
  or ``encode_lidar_frame`` + ``put_bytes`` and a ``subscribe_frames`` FIFO with decode; with
  Zenoh's shared memory on (its default) and off.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from typing import Any

import numpy as np
import zenoh

from benchmarks.common import (
    FRAME_POINTS,
    SITE,
    STREAM_KEY,
    TIMEOUT_S,
    Peer,
    Watchdog,
    frame_meta,
    frame_points,
    free_port,
    listener_settings,
    raw_index,
    small_message,
    small_raw,
)
from wz_shared import codec
from wz_shared.bus import Bus, Subscription
from wz_shared.messages import LidarFrameMeta, RadarScan

log = logging.getLogger(__name__)


class _Tally:
    """Count, order check and first / last arrival of a stream of numbered samples."""

    def __init__(self, expected: int) -> None:
        self.expected = expected
        self.count = 0
        self.out_of_order = 0
        self.first = 0.0
        self.last = 0.0
        self.complete = threading.Event()

    def add(self, index: int) -> None:
        now = time.perf_counter()
        if self.count == 0:
            self.first = now
        if index >= 0 and index != self.count:
            self.out_of_order += 1
        self.count += 1
        self.last = now
        if self.count == self.expected:
            self.complete.set()


def _take_all(subscription: Subscription[Any], tally: _Tally, index_of: Any) -> None:
    """Take samples on this thread until ``tally`` is complete or the stream stalls."""
    while tally.count < tally.expected:
        value = subscription.recv(TIMEOUT_S)
        if value is None:
            return
        tally.add(index_of(value))


def _take_all_from_channel(channel: Any, tally: _Tally) -> None:
    """Take samples from a Zenoh channel until ``tally`` is complete or the watchdog fires."""
    while tally.count < tally.expected:
        payload = channel.recv().payload.to_bytes()
        if not payload:  # the watchdog: the stream stalled
            return
        tally.add(raw_index(payload))


def stream(path: str, count: int, *, shm: bool = True) -> dict[str, Any]:
    """Publish ``count`` samples along ``path`` from the peer and count them here."""
    port = free_port()
    tally = _Tally(count)
    publish_api = "zenoh" if path == "zenoh-fifo" else path
    settings = listener_settings(port, shm=shm)
    with Bus.open(settings, site=SITE, service="bench-throughput") as bus:
        with contextlib.ExitStack() as stack:
            subscription: Subscription[Any] | None = None
            channel: Any = None
            if path == "zenoh-fifo":
                channel = bus.session.declare_subscriber(
                    STREAM_KEY, zenoh.handlers.FifoChannel(65536)
                )
                stack.callback(channel.undeclare)
                stack.enter_context(Watchdog(bus.session, STREAM_KEY, lambda: tally.count))
            elif path == "zenoh":

                def on_small(sample: zenoh.Sample) -> None:
                    tally.add(raw_index(sample.payload.to_bytes()))

                stack.callback(bus.session.declare_subscriber(STREAM_KEY, on_small).undeclare)
            elif path == "zenoh-frames":
                # Counted without copying the 2 MB out of Zenoh.
                stack.callback(
                    bus.session.declare_subscriber(STREAM_KEY, lambda _s: tally.add(-1)).undeclare
                )
            elif path == "bus-raw":
                subscription = bus.subscribe_raw(STREAM_KEY)
            elif path == "bus-json":
                subscription = bus.subscribe(STREAM_KEY, RadarScan)
            elif path == "bus-frames":
                subscription = bus.subscribe_frames(
                    STREAM_KEY, LidarFrameMeta, mode="fifo", capacity=4
                )
            else:
                raise ValueError(f"unknown path {path!r}")

            endpoint = f"tcp/127.0.0.1:{port}"
            shm_flag = "on" if shm else "off"
            with Peer(
                "publish", publish_api, endpoint, "--count", str(count), "--shm", shm_flag
            ) as peer:
                if channel is not None:
                    _take_all_from_channel(channel, tally)
                elif subscription is None:
                    tally.complete.wait(TIMEOUT_S + count * 1e-3)
                elif path == "bus-frames":
                    _take_all(subscription, tally, lambda frame: frame.meta.frame_index)
                elif path == "bus-json":
                    _take_all(subscription, tally, lambda scan: scan.scan_index)
                else:
                    _take_all(subscription, tally, raw_index)
                done = peer.expect("done")
            # The peer has closed its session: whatever came beyond the count is extra.
            received = tally.count + (0 if subscription is None else subscription.pending)
        stats = bus.stats.snapshot()

    if path in ("zenoh", "zenoh-fifo", "bus-raw"):
        payload_bytes = len(small_raw(0))
    elif path == "bus-json":
        payload_bytes = len(codec.encode(small_message(count // 2)))
    elif path == "zenoh-frames":
        payload_bytes = 8 + FRAME_POINTS * 16
    else:
        payload_bytes = len(codec.encode_lidar_frame(frame_meta(0), frame_points()))
    span_s = tally.last - tally.first
    rate = (tally.count - 1) / span_s if tally.count > 1 and span_s > 0 else 0.0
    return {
        "path": path,
        "shm": shm,
        "payload_bytes": payload_bytes,
        "sent": count,
        "received": received,
        "lost": max(0, count - received),
        "extra": max(0, received - count),
        "out_of_order": tally.out_of_order,
        "invalid": sum(stats["invalid"].values()),
        "dropped": sum(stats["dropped"].values()),
        "receive_span_s": span_s,
        "messages_per_s": rate,
        "megabytes_per_s": rate * payload_bytes / 1e6,
        "publisher_put_s": float(done["put_s"]),
        "publisher_messages_per_s": count / float(done["put_s"]),
    }


SMALL_COUNTS = {"zenoh": 400_000, "zenoh-fifo": 400_000, "bus-raw": 200_000, "bus-json": 100_000}
FRAME_COUNT = 300


def _combine(rounds: list[dict[str, Any]]) -> dict[str, Any]:
    """One path's rounds: median rates (with every round's), totals of the counts."""
    rates = [r["messages_per_s"] for r in rounds]
    first = rounds[0]
    median_rate = float(np.median(rates))
    return {
        "path": first["path"],
        "shm": first["shm"],
        "payload_bytes": first["payload_bytes"],
        "rounds": len(rounds),
        "sent": sum(r["sent"] for r in rounds),
        "sent_per_round": first["sent"],
        "received": sum(r["received"] for r in rounds),
        **{
            name: sum(r[name] for r in rounds)
            for name in ("lost", "extra", "out_of_order", "invalid", "dropped")
        },
        "messages_per_s": median_rate,
        "messages_per_s_rounds": rates,
        "megabytes_per_s": median_rate * first["payload_bytes"] / 1e6,
        "publisher_messages_per_s": float(
            np.median([r["publisher_messages_per_s"] for r in rounds])
        ),
    }


def run(quick: bool) -> dict[str, Any]:
    """Stream every path, 3 rounds (1 quick) round-robin over the paths; median of the rounds.

    Counts are sized for a second or so per round (a fifth of that quick).
    """
    rounds, scale = (1, 0.2) if quick else (3, 1.0)
    variants = [(path, path, True, count) for path, count in SMALL_COUNTS.items()] + [
        (f"{path}{'' if shm else '-noshm'}", path, shm, FRAME_COUNT)
        for shm in (True, False)
        for path in ("zenoh-frames", "bus-frames")
    ]
    results: dict[str, list[dict[str, Any]]] = {name: [] for name, *_ in variants}
    for number in range(rounds):
        for name, path, shm, count in variants:
            n = int(count * scale)
            log.info("bus_throughput: round %d/%d, %s, %d samples", number + 1, rounds, name, n)
            results[name].append(stream(path, n, shm=shm))
    small = {name: _combine(results[name]) for name in SMALL_COUNTS}
    frames = {name: _combine(r) for name, r in results.items() if name not in small}

    def ratio(table: dict[str, Any], a: str, b: str) -> float:
        return float(table[a]["messages_per_s"] / table[b]["messages_per_s"])

    everything = [*small.values(), *frames.values()]
    return {
        "small": small,
        "frames": frames,
        "all_delivered": all(
            r["lost"] == 0 and r["extra"] == 0 and r["out_of_order"] == 0 for r in everything
        ),
        "ratios": {
            "bus-json / zenoh (msg/s)": ratio(small, "bus-json", "zenoh"),
            "bus-raw / zenoh (msg/s)": ratio(small, "bus-raw", "zenoh"),
            "bus-json / bus-raw (msg/s): the codec": ratio(small, "bus-json", "bus-raw"),
            "zenoh-fifo / zenoh (msg/s)": ratio(small, "zenoh-fifo", "zenoh"),
            "bus-raw / zenoh-fifo (msg/s): our queue vs Zenoh's": ratio(
                small, "bus-raw", "zenoh-fifo"
            ),
            "bus-frames / zenoh-frames, shm (msg/s)": ratio(frames, "bus-frames", "zenoh-frames"),
            "bus-frames / zenoh-frames, no shm (msg/s)": ratio(
                frames, "bus-frames-noshm", "zenoh-frames-noshm"
            ),
            "bus-frames shm / no shm (msg/s)": ratio(frames, "bus-frames", "bus-frames-noshm"),
        },
    }
