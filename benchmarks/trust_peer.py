"""The second process of the ``bus_trust`` benchmark: a client of the router under test.

Usage: ``python -m benchmarks.trust_peer ROLE ENDPOINT [--tls-dir DIR] [--count N] [--bytes N]``

``echo``     republish every sample of :data:`PING_KEY` on :data:`PONG_KEY` (as the alert service
             turns track batches into alerts), reporting ``ready`` once the pong publisher
             matches, until stdin closes.
``publish``  put ``--count`` samples of ``--bytes`` on :data:`STREAM_KEY` as fast as it can
             (blocking congestion control), report ``done``, wait until stdin closes.

Plain Zenoh sessions (bytes, a Python callback): the benchmark measures the bus's transport
and the router, not the codec. With ``--tls-dir`` the session is mutual TLS with that
identity's certificate (``wz credentials``).
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from pathlib import Path
from typing import Any

import zenoh

from wz_shared.bus import zenoh_config
from wz_shared.settings import BusSettings

SITE = "bench"
#: Keys whose roles the deployed access control allows: the tracker puts pings (track batches),
#: the alert service pongs (alerts), a detector the stream (detections).
PING_KEY = f"wz/{SITE}/tracks"
PONG_KEY = f"wz/{SITE}/alerts/speeding"
STREAM_KEY = f"wz/{SITE}/detections/lidar-mast"
TIMEOUT_S = 30.0


def report(event: str, **fields: Any) -> None:
    sys.stdout.write(json.dumps({"event": event, **fields}) + "\n")
    sys.stdout.flush()


def open_session(endpoint: str, tls_dir: Path | None) -> zenoh.Session:
    settings = BusSettings(
        mode="client", connect_endpoints=[endpoint], listen_endpoints=[], tls_dir=tls_dir
    )
    return zenoh.open(zenoh_config(settings))


def publisher(session: zenoh.Session, key: str) -> Any:
    return session.declare_publisher(
        key,
        congestion_control=zenoh.CongestionControl.BLOCK,
        reliability=zenoh.Reliability.RELIABLE,
    )


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("role", choices=["echo", "publish"])
    parser.add_argument("endpoint")
    parser.add_argument("--tls-dir", type=Path)
    parser.add_argument("--count", type=int, default=0)
    parser.add_argument("--bytes", type=int, default=200)
    args = parser.parse_args()
    session = open_session(args.endpoint, args.tls_dir)
    if args.role == "echo":
        closed = threading.Event()

        def watch_stdin() -> None:
            sys.stdin.read()
            closed.set()

        threading.Thread(target=watch_stdin, daemon=True).start()
        pong = publisher(session, PONG_KEY)
        sub = session.declare_subscriber(PING_KEY, lambda s: pong.put(s.payload.to_bytes()))
        deadline = time.monotonic() + TIMEOUT_S
        while not pong.matching_status.matching and time.monotonic() < deadline:
            time.sleep(0.01)
        report("ready")
        closed.wait()
        sub.undeclare()  # type: ignore[no-untyped-call]
    else:
        stream = publisher(session, STREAM_KEY)
        deadline = time.monotonic() + TIMEOUT_S
        while not stream.matching_status.matching and time.monotonic() < deadline:
            time.sleep(0.01)
        payloads = [i.to_bytes(8, "little") + bytes(args.bytes - 8) for i in range(64)]
        report("ready")
        sys.stdin.readline()  # go
        start = time.perf_counter()
        for index in range(args.count):
            payload = payloads[index % 64]
            stream.put(index.to_bytes(8, "little") + payload[8:])
        report("done", put_s=time.perf_counter() - start)
        sys.stdin.read()  # the measuring process closes stdin once every sample arrived
    session.close()  # type: ignore[no-untyped-call]


if __name__ == "__main__":
    main()
