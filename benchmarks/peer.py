"""The second process of the bus benchmarks.

Usage: ``python -m benchmarks.peer ROLE API ENDPOINT [--shm on|off] [--count N] [--points N]``

Roles
-----
``echo``
    Republish every sample of ``PING_KEY`` on ``PONG_KEY``, the same way it came in (through
    the same API), until stdin closes. Reports ``ready`` once its pong publisher matches the
    measuring process's subscriber.
``publish``
    Publish ``--count`` samples on ``STREAM_KEY`` as fast as possible with blocking congestion
    control, report ``done`` with the time the puts took, then wait until stdin closes (the
    measuring process closes it once every sample has arrived, so no reliable sample is still
    in flight when this session closes).

APIs
----
``zenoh``         a plain Zenoh session and publisher, bytes in a Python callback, no codec
``zenoh-fifo``    the same, received through Zenoh's ``FifoChannel`` on the main thread (echo)
``zenoh-frames``  the same with 2 MB payloads (publish only; echo with ``zenoh``)
``bus-raw``       :class:`~wz_shared.bus.Bus`: ``put_bytes`` and a ``subscribe_raw`` FIFO queue
``bus-json``      :class:`~wz_shared.bus.Bus`: ``put`` (encode) and a ``subscribe`` FIFO (decode)
``bus-callback``  :class:`~wz_shared.bus.Bus`: ``put`` and ``on`` (decoded on Zenoh's thread)
``bus-frames``    :class:`~wz_shared.bus.Bus`: LiDAR envelopes via ``encode_lidar_frame`` and a
                  ``subscribe_frames`` FIFO
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from typing import Any

import zenoh

from benchmarks.common import (
    FRAME_POINTS,
    PING_KEY,
    PONG_KEY,
    SITE,
    STREAM_KEY,
    TIMEOUT_S,
    connector_settings,
    frame_meta,
    frame_points,
    raw_matched,
    small_message,
    small_raw,
)
from wz_shared import codec
from wz_shared.bus import Bus
from wz_shared.messages import LidarFrameMeta, RadarScan

ECHO_APIS = ("zenoh", "zenoh-fifo", "bus-raw", "bus-json", "bus-callback", "bus-frames")
PUBLISH_APIS = ("zenoh", "zenoh-frames", "bus-raw", "bus-json", "bus-frames")


def report(event: str, **fields: Any) -> None:
    sys.stdout.write(json.dumps({"event": event, **fields}) + "\n")
    sys.stdout.flush()


def stdin_closed() -> threading.Event:
    """An event set when stdin reaches end of file (the measuring process's stop signal)."""
    closed = threading.Event()

    def watch() -> None:
        sys.stdin.read()
        closed.set()

    threading.Thread(target=watch, daemon=True).start()
    return closed


def raw_publisher(session: zenoh.Session, key: str) -> Any:
    return session.declare_publisher(
        key,
        congestion_control=zenoh.CongestionControl.BLOCK,
        reliability=zenoh.Reliability.RELIABLE,
    )


def wait_matched(publisher: Any, what: str) -> None:
    """Wait until a raw Zenoh publisher has a matching subscriber."""
    deadline = time.monotonic() + TIMEOUT_S
    while not raw_matched(publisher):
        if time.monotonic() >= deadline:
            raise SystemExit(f"no subscriber matched {what} within {TIMEOUT_S} s")
        time.sleep(0.005)


# --- echo -----------------------------------------------------------------------------------


def echo(bus: Bus, api: str, stop: threading.Event) -> None:
    if api == "zenoh":
        pong = raw_publisher(bus.session, PONG_KEY)
        subscriber = bus.session.declare_subscriber(
            PING_KEY, lambda sample: pong.put(sample.payload)
        )
        try:
            wait_matched(pong, PONG_KEY)
            report("ready")
            stop.wait()
        finally:
            subscriber.undeclare()
            pong.undeclare()
        return

    if api == "zenoh-fifo":
        fifo_pong = raw_publisher(bus.session, PONG_KEY)
        pings = bus.session.declare_subscriber(PING_KEY, zenoh.handlers.FifoChannel(1024))

        def wake_on_stop() -> None:
            stop.wait()
            bus.session.put(PING_KEY, b"")  # delivered locally: ends the loop below

        threading.Thread(target=wake_on_stop, daemon=True).start()
        try:
            wait_matched(fifo_pong, PONG_KEY)
            report("ready")
            while True:
                sample = pings.recv()
                if len(sample.payload) == 0:
                    break
                fifo_pong.put(sample.payload)
        finally:
            pings.undeclare()
            fifo_pong.undeclare()
        return

    if api == "bus-callback":
        json_pong = bus.publisher(PONG_KEY, RadarScan)
        bus.on(PING_KEY, RadarScan, lambda _key, message: json_pong.put(message))
        if not json_pong.wait_for_subscribers(TIMEOUT_S):
            raise SystemExit(f"no subscriber matched {PONG_KEY}")
        report("ready")
        stop.wait()
        return

    if api == "bus-raw":
        raw_pong = bus.publisher(PONG_KEY, RadarScan)
        raw_pings = bus.subscribe_raw(PING_KEY)
        if not raw_pong.wait_for_subscribers(TIMEOUT_S):
            raise SystemExit(f"no subscriber matched {PONG_KEY}")
        report("ready")
        while not stop.is_set():
            payload = raw_pings.recv(0.1)
            if payload is not None:
                raw_pong.put_bytes(payload)
    elif api == "bus-json":
        json_pong = bus.publisher(PONG_KEY, RadarScan)
        json_pings = bus.subscribe(PING_KEY, RadarScan)
        if not json_pong.wait_for_subscribers(TIMEOUT_S):
            raise SystemExit(f"no subscriber matched {PONG_KEY}")
        report("ready")
        while not stop.is_set():
            message = json_pings.recv(0.1)
            if message is not None:
                json_pong.put(message)
    elif api == "bus-frames":
        frame_pong = bus.publisher(PONG_KEY, LidarFrameMeta, block=True)
        frame_pings = bus.subscribe_frames(PING_KEY, LidarFrameMeta, mode="fifo", capacity=4)
        if not frame_pong.wait_for_subscribers(TIMEOUT_S):
            raise SystemExit(f"no subscriber matched {PONG_KEY}")
        report("ready")
        while not stop.is_set():
            frame = frame_pings.recv(0.1)
            if frame is not None:
                frame_pong.put_bytes(codec.encode_lidar_frame(frame.meta, frame.points()))
    else:
        raise SystemExit(f"unknown echo api {api!r}; one of {ECHO_APIS}")


# --- publish --------------------------------------------------------------------------------


def publish(bus: Bus, api: str, count: int, num_points: int) -> dict[str, Any]:
    """Publish ``count`` samples as fast as possible; return how long the puts took."""
    if api in ("zenoh", "zenoh-frames"):
        publisher = raw_publisher(bus.session, STREAM_KEY)
        try:
            wait_matched(publisher, STREAM_KEY)
            if api == "zenoh":
                start = time.perf_counter()
                for index in range(count):
                    publisher.put(small_raw(index))
            else:
                # A few pre-built payloads, sent in turn: Zenoh's cost alone. (Building a fresh
                # 2 MB ``bytes(bytearray)`` per put halved the rate in a test on 2 cores.)
                body = frame_points(num_points).tobytes()
                payloads = [index.to_bytes(8, "little") + body for index in range(4)]
                start = time.perf_counter()
                for index in range(count):
                    publisher.put(payloads[index % len(payloads)])
            put_s = time.perf_counter() - start
        finally:
            publisher.undeclare()
        return {"put_s": put_s, "count": count}

    if api == "bus-raw":
        raw = bus.publisher(STREAM_KEY, RadarScan, block=True)
        raw.wait_for_subscribers(TIMEOUT_S)
        start = time.perf_counter()
        for index in range(count):
            raw.put_bytes(small_raw(index))
    elif api == "bus-json":
        messages = [small_message(index) for index in range(count)]
        scans = bus.publisher(STREAM_KEY, RadarScan, block=True)
        scans.wait_for_subscribers(TIMEOUT_S)
        start = time.perf_counter()
        for message in messages:
            scans.put(message)
    elif api == "bus-frames":
        points = frame_points(num_points)
        metas = [frame_meta(index, num_points) for index in range(count)]
        frames = bus.publisher(STREAM_KEY, LidarFrameMeta, block=True)
        frames.wait_for_subscribers(TIMEOUT_S)
        start = time.perf_counter()
        for meta in metas:
            frames.put_bytes(codec.encode_lidar_frame(meta, points))
    else:
        raise SystemExit(f"unknown publish api {api!r}; one of {PUBLISH_APIS}")
    return {"put_s": time.perf_counter() - start, "count": count}


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.peer")
    parser.add_argument("role", choices=("echo", "publish"))
    parser.add_argument("api")
    parser.add_argument("endpoint")
    parser.add_argument("--shm", choices=("on", "off"), default="on")
    parser.add_argument("--count", type=int, default=0)
    parser.add_argument("--points", type=int, default=FRAME_POINTS)
    args = parser.parse_args()

    stop = stdin_closed()
    settings = connector_settings(args.endpoint, shm=args.shm == "on")
    with Bus.open(settings, site=SITE, service="bench-peer") as bus:
        if args.role == "echo":
            echo(bus, args.api, stop)
        else:
            report("done", **publish(bus, args.api, args.count, args.points))
            stop.wait()


if __name__ == "__main__":
    main()
