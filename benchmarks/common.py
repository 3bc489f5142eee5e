"""What the bus benchmarks share: keys, payloads, bus settings, the second process, statistics.

Two processes talk over real Zenoh on loopback: the measuring process listens on a free
``tcp/127.0.0.1`` port, the peer (:mod:`benchmarks.peer`) connects to it; multicast scouting is
off, so nothing else can join. The peer reports on its stdout, one JSON object a line, and runs
until its stdin closes.
"""

from __future__ import annotations

import json
import queue
import socket
import subprocess
import sys
import tempfile
import threading
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from wz_shared.keys import Keys
from wz_shared.messages import LidarFrameMeta, RadarScan, RadarTarget
from wz_shared.settings import BusSettings

ROOT = Path(__file__).resolve().parents[1]
SITE = "bench"
KEYS = Keys(SITE)
#: The measuring process publishes here and the echo peer answers on PONG.
PING_KEY = f"{KEYS.prefix}/bench/ping"
PONG_KEY = f"{KEYS.prefix}/bench/pong"
#: The throughput peer publishes here.
STREAM_KEY = f"{KEYS.prefix}/bench/stream"

#: A small raw payload [bytes]: the sequence number (8 bytes, little-endian) then padding.
SMALL_BYTES = 200
#: Points of a benchmark LiDAR frame: 128 beams x 1024 columns, float32 x, y, z, intensity.
FRAME_POINTS = 131072
#: Longest wait for one sample or for a peer to start [s]; a benchmark that hits it fails.
TIMEOUT_S = 30.0


# --- payloads -------------------------------------------------------------------------------


def small_message(index: int) -> RadarScan:
    """A radar scan with one target: about 200 bytes of JSON, numbered ``index``."""
    return RadarScan(
        site=SITE,
        source_id="radar-mast",
        stamp=10.0,
        scan_index=index,
        targets=[RadarTarget(range_m=50.0, azimuth_rad=0.1, radial_speed_mps=-30.0, rcs_dbsm=10.0)],
    )


def small_raw(index: int) -> bytes:
    """``SMALL_BYTES`` raw bytes that start with ``index``."""
    return index.to_bytes(8, "little") + bytes(SMALL_BYTES - 8)


def raw_index(payload: bytes) -> int:
    return int.from_bytes(payload[:8], "little")


def frame_points(num_points: int = FRAME_POINTS, seed: int = 0) -> npt.NDArray[np.float32]:
    """Seeded random ``(num_points, 4)`` float32 points."""
    rng = np.random.default_rng(seed)
    return rng.normal(scale=30.0, size=(num_points, 4)).astype(np.float32)


def frame_meta(index: int, num_points: int = FRAME_POINTS) -> LidarFrameMeta:
    """Metadata of an organised 128-beam frame numbered ``index``."""
    rows = 128 if num_points % 128 == 0 else 1
    return LidarFrameMeta(
        site=SITE,
        source_id="lidar-mast",
        stamp=0.1 * index,
        frame_index=index,
        rows=rows,
        columns=num_points // rows,
        num_points=num_points,
        sweep_duration_s=0.1,
        organized=rows > 1,
    )


# --- bus settings ---------------------------------------------------------------------------


def _no_shm_config() -> Path:
    """A Zenoh config file that turns shared memory off (Zenoh 1.x has it on by default)."""
    path = Path(tempfile.gettempdir()) / "wz-bench-no-shm.json5"
    path.write_text("{ transport: { shared_memory: { enabled: false } } }\n")
    return path


def listener_settings(port: int, *, shm: bool) -> BusSettings:
    """The measuring process: a peer listening on ``port`` that connects nowhere."""
    return BusSettings(
        mode="peer",
        listen_endpoints=[f"tcp/127.0.0.1:{port}"],
        connect_endpoints=[],
        multicast_scouting=False,
        config_file=None if shm else _no_shm_config(),
    )


def connector_settings(endpoint: str, *, shm: bool) -> BusSettings:
    """The peer process: connects to ``endpoint``, listens nowhere."""
    return BusSettings(
        mode="peer",
        listen_endpoints=[],
        connect_endpoints=[endpoint],
        multicast_scouting=False,
        config_file=None if shm else _no_shm_config(),
    )


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def raw_matched(publisher: Any) -> bool:
    """Whether a plain Zenoh publisher has a matching subscriber now."""
    # zenoh's stub says bool; at run time it is a MatchingStatus with a .matching flag.
    return bool(publisher.matching_status.matching)


# --- the second process ---------------------------------------------------------------------


class Peer:
    """``python -m benchmarks.peer ...`` as a child process.

    It writes JSON lines on stdout (read here by a thread) and stops when its stdin closes.
    """

    def __init__(self, *args: str, module: str = "benchmarks.peer") -> None:
        self.args = args
        self._process = subprocess.Popen(
            [sys.executable, "-m", module, *args],
            cwd=ROOT,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        self._lines: queue.Queue[str | None] = queue.Queue()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self._process.stdout is not None
        for line in self._process.stdout:
            self._lines.put(line)
        self._lines.put(None)

    def expect(self, event: str, timeout_s: float = TIMEOUT_S) -> dict[str, Any]:
        """Wait for the peer's next report and check it is ``event``."""
        try:
            line = self._lines.get(timeout=timeout_s)
        except queue.Empty:
            raise TimeoutError(f"peer {self.args} sent no {event!r} within {timeout_s} s") from None
        if line is None:
            raise RuntimeError(
                f"peer {self.args} exited (rc={self._process.wait()}) before {event!r}"
            )
        report: dict[str, Any] = json.loads(line)
        if report.get("event") != event:
            raise RuntimeError(f"peer {self.args}: expected {event!r}, got {report}")
        return report

    def send(self, line: str) -> None:
        """Write one line to the peer's stdin."""
        assert self._process.stdin is not None
        self._process.stdin.write(line + "\n")
        self._process.stdin.flush()

    def finish(self, timeout_s: float = TIMEOUT_S) -> None:
        """Close the peer's stdin (its signal to stop) and require a clean exit."""
        if self._process.stdin is not None and not self._process.stdin.closed:
            self._process.stdin.close()
        try:
            code = self._process.wait(timeout_s)
        except subprocess.TimeoutExpired:
            self._process.kill()
            self._process.wait()
            raise RuntimeError(f"peer {self.args} did not stop within {timeout_s} s") from None
        if code != 0:
            raise RuntimeError(f"peer {self.args} exited with {code}")

    def __enter__(self) -> Peer:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, *_: object) -> None:
        if exc_type is None:
            self.finish()
        elif self._process.poll() is None:
            self._process.kill()
            self._process.wait()


class Watchdog:
    """Wakes a thread blocked in a Zenoh channel's ``recv()`` when a stream stalls.

    Zenoh's channel ``recv()`` takes no timeout. When ``progress()`` has not changed for
    ``TIMEOUT_S``, this publishes an empty sample on ``key`` from the same session (delivered
    locally); the reader takes an empty payload as "stalled" and fails instead of hanging.
    """

    def __init__(self, session: Any, key: str, progress: Callable[[], int]) -> None:
        self._session = session
        self._key = key
        self._progress = progress
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._watch, daemon=True)

    def _watch(self) -> None:
        last = self._progress()
        while not self._done.wait(TIMEOUT_S):
            now = self._progress()
            if now == last:
                self._session.put(self._key, b"")
            last = now

    def __enter__(self) -> Watchdog:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._done.set()
        self._thread.join()


# --- statistics -----------------------------------------------------------------------------


def summarize(values: Sequence[float]) -> dict[str, float]:
    """Median, p90, p99, min, max and mean of ``values`` (same unit as the values)."""
    array = np.asarray(values, dtype=float)
    p50, p90, p99 = np.percentile(array, [50.0, 90.0, 99.0])
    return {
        "n": int(array.size),
        "p50": float(p50),
        "p90": float(p90),
        "p99": float(p99),
        "min": float(array.min()),
        "max": float(array.max()),
        "mean": float(array.mean()),
    }
