"""Helper processes for the `wz` tests: a publisher of a known mix, and a counter.

Usage::

    python -m tests.cli.bus_tools publish ENDPOINT MIX N   # MIX: "mix" or "tap"; until SIGTERM
    python -m tests.cli.bus_tools stream ENDPOINT HZ        # until SIGTERM
    python -m tests.cli.bus_tools count ENDPOINT TOTAL TIMEOUT_S

``publish`` waits until every one of its publishers matches a subscriber, publishes, prints
``published``, and keeps its session open until SIGTERM (then exits 0).
``count`` subscribes (FIFO) to ``wz/**``, prints ``ready``, then counts samples per key until
TOTAL arrived or TIMEOUT_S passed of silence, and prints one JSON line:
``{key: [count, sha256 of the payloads in arrival order]}``.
"""

from __future__ import annotations

import hashlib
import json
import sys
import time
from collections.abc import Callable

from tests.shared.samples import SITE, camera_frame, encoded_lidar, json_samples
from wz_shared import codec
from wz_shared.bus import Bus
from wz_shared.keys import Keys
from wz_shared.messages import (
    Alert,
    CameraFrameMeta,
    GroundTruth,
    LidarFrameMeta,
    Message,
)
from wz_shared.settings import BusSettings
from wz_shared.signals import stop_on_signals

KEYS = Keys(SITE)
JUNK_KEY = f"{KEYS.prefix}/test/junk"


def _key_of(message: Message) -> str:
    """Where each sample message type travels in the stack."""
    return {
        "radar_scan": KEYS.raw_radar("radar-mast"),
        "ground_truth": KEYS.truth,
        "detection_batch": KEYS.detections("lidar-mast"),
        "track_batch": KEYS.tracks,
        "alert": KEYS.alerts("speeding"),
        "roadside_devices": KEYS.devices_state,
        "active_alerts": f"{KEYS.prefix}/test/active_alerts",
        "service_status": KEYS.status("tracker"),
        "sensor_calibration": KEYS.calibration("cam-1"),
    }[getattr(message, "kind")]  # noqa: B009 (kind is declared on subclasses only)


Sample = tuple[str, type[Message], bytes]


def mix(count: int) -> list[Sample]:
    """``count`` of every JSON type and of each frame kind, plus junk and broken frames.

    Returns (key, publisher type, payload) in publication order.
    """
    samples: list[Sample] = []
    for i in range(count):
        for message in json_samples(i):
            samples.append((_key_of(message), type(message), codec.encode(message)))
        samples.append((KEYS.raw_lidar("lidar-mast"), LidarFrameMeta, encoded_lidar(i, 64)))
        meta, jpeg = camera_frame(i)
        samples.append(
            (KEYS.raw_camera("camera-mast"), CameraFrameMeta, codec.encode_camera_frame(meta, jpeg))
        )
        # Not messages at all: recorded and replayed as they are.
        samples.append((JUNK_KEY, Alert, b"{oops " + str(i).encode()))
        samples.append((KEYS.raw_lidar("broken-lidar"), LidarFrameMeta, encoded_lidar(i, 8)[:-5]))
    return samples


def tap_mix() -> list[Sample]:
    """One of each interesting case for `wz tap`."""
    truth = next(m for m in json_samples(3) if isinstance(m, GroundTruth))
    alert = next(m for m in json_samples(3) if isinstance(m, Alert))
    bad_version = json.dumps({**json.loads(codec.encode(alert)), "schema_version": 99}).encode()
    meta, jpeg = camera_frame(5)
    return [
        (KEYS.truth, GroundTruth, codec.encode(truth)),
        (KEYS.raw_lidar("lidar-mast"), LidarFrameMeta, encoded_lidar(4, 32)),
        (KEYS.raw_camera("camera-mast"), CameraFrameMeta, codec.encode_camera_frame(meta, jpeg)),
        (KEYS.alerts("speeding"), Alert, codec.encode(alert)),
        (KEYS.alerts("speeding"), Alert, bad_version),
        (JUNK_KEY, Alert, b"\x00\x01 not json"),
        (KEYS.raw_lidar("lidar-mast"), LidarFrameMeta, encoded_lidar(4, 32)[:-7]),
    ]


def expected_counts(samples: list[Sample]) -> dict[str, list[object]]:
    """What ``count`` prints for these samples."""
    digests: dict[str, hashlib._Hash] = {}
    counts: dict[str, int] = {}
    for key, _cls, payload in samples:
        digests.setdefault(key, hashlib.sha256()).update(payload)
        counts[key] = counts.get(key, 0) + 1
    return {key: [counts[key], digests[key].hexdigest()] for key in counts}


def _settings(endpoint: str) -> BusSettings:
    return BusSettings(mode="peer", connect_endpoints=[endpoint], listen_endpoints=[])


def publish(endpoint: str, samples: list[Sample]) -> None:
    stop = stop_on_signals()
    with Bus.open(_settings(endpoint), site=SITE, service="publisher") as bus:
        publishers = {}
        for key, cls, _payload in samples:
            if key not in publishers:
                publishers[key] = bus.publisher(key, cls, block=True)
        for publisher in publishers.values():
            if not publisher.wait_for_subscribers(20.0):
                raise SystemExit(f"no subscriber for {publisher.key} within 20 s")
        for key, _cls, payload in samples:
            publishers[key].put_bytes(payload)
        # Closing a session right after its last put may drop what is still queued for the
        # router: the session stays open until the test has seen everything arrive.
        sys.stdout.write("published\n")
        sys.stdout.flush()
        stop.wait()


def stream(endpoint: str, rate_hz: float) -> None:
    """Ground truth at ``rate_hz`` until SIGTERM (for the crash-while-recording test)."""
    stop = stop_on_signals()
    with Bus.open(_settings(endpoint), site=SITE, service="streamer") as bus:
        truth = bus.publisher(KEYS.truth, GroundTruth)
        template = next(m for m in json_samples() if isinstance(m, GroundTruth))
        step = 0
        while not stop.wait(1.0 / rate_hz):
            truth.put(template.model_copy(update={"step_index": step, "stamp": step / rate_hz}))
            step += 1


def count(endpoint: str, total: int, silence_s: float) -> None:
    with Bus.open(_settings(endpoint), site=SITE, service="counter") as bus:
        subscription = bus.subscribe_raw("wz/**", mode="fifo")
        sys.stdout.write("ready\n")
        sys.stdout.flush()
        digests: dict[str, hashlib._Hash] = {}
        counts: dict[str, int] = {}
        arrivals: list[float] = []
        while sum(counts.values()) < total:
            received = subscription.recv_with_key(silence_s)
            if received is None:
                break
            arrivals.append(time.monotonic())
            digests.setdefault(received.key, hashlib.sha256()).update(received.value)
            counts[received.key] = counts.get(received.key, 0) + 1
        report: dict[str, object] = {key: [counts[key], digests[key].hexdigest()] for key in counts}
        report["_spread_s"] = arrivals[-1] - arrivals[0] if arrivals else 0.0
        sys.stdout.write(json.dumps(report) + "\n")
        sys.stdout.flush()


def main() -> None:
    command, endpoint, *args = sys.argv[1:]
    commands: dict[str, Callable[[], None]] = {
        "publish": lambda: publish(endpoint, mix(int(args[1])) if args[0] == "mix" else tap_mix()),
        "stream": lambda: stream(endpoint, float(args[0])),
        "count": lambda: count(endpoint, int(args[0]), float(args[1])),
    }
    commands[command]()


if __name__ == "__main__":
    main()
