"""A second process for the bus tests: connects to the test's peer and publishes.

Usage: python -m tests.shared.bus_peer ENDPOINT SCENARIO [ARGS...]

Scenarios
- ``all N``: N messages of every JSON type and N frames of each kind, each on its own key.
- ``frames N HZ POINTS BLOCK``: N LiDAR frames of POINTS points at HZ; BLOCK=1 for blocking
  congestion control (lossless), 0 for drop.
- ``malformed``: good, bad, good ... on one alert key and one frame key (see the test).
- ``history N``: N alerts on a publisher with a history of N, before anyone subscribes; then
  prints ``published`` and, once the test says ``more`` on ``.../test/more``, N more.
The process waits until its publishers match a subscriber before it starts; when every message is
out it waits for the test's acknowledgement on ``wz/test-site/test/ack`` (so it does not close
its session while reliable samples are still in flight), then exits 0.
"""

from __future__ import annotations

import json
import sys
import time

from tests.shared.samples import camera_frame, encoded_lidar, json_samples
from wz_shared import codec
from wz_shared.bus import Bus, Publisher
from wz_shared.messages import Alert, CameraFrameMeta, LidarFrameMeta, Message
from wz_shared.settings import BusSettings

SITE = "test-site"


def _wait(publisher: Publisher[Message], what: str) -> None:
    if not publisher.wait_for_subscribers(10.0):
        raise SystemExit(f"no subscriber matched {what} within 10 s")


def scenario_all(bus: Bus, count: int) -> None:
    samples = json_samples()
    publishers: list[Publisher[Message]] = [
        bus.publisher(f"{bus.keys.prefix}/test/{m.kind}", type(m)) for m in samples
    ]
    lidar = bus.publisher(bus.keys.raw_lidar("lidar-mast"), LidarFrameMeta, block=True)
    camera = bus.publisher(bus.keys.raw_camera("camera-mast"), CameraFrameMeta, block=True)
    for pub in [*publishers, lidar, camera]:
        _wait(pub, pub.key)
    for i in range(count):
        for pub, message in zip(publishers, json_samples(i), strict=True):
            pub.put(message)
        lidar.put_bytes(encoded_lidar(i, 256))
        meta, jpeg = camera_frame(i)
        camera.put_bytes(codec.encode_camera_frame(meta, jpeg))


def scenario_frames(bus: Bus, count: int, rate_hz: float, points: int, block: bool) -> None:
    lidar = bus.publisher(bus.keys.raw_lidar("lidar-mast"), LidarFrameMeta, block=block)
    _wait(lidar, lidar.key)
    envelopes = [encoded_lidar(i, points) for i in range(count)]
    start = time.monotonic()
    for i, envelope in enumerate(envelopes):
        delay = start + i / rate_hz - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        lidar.put_bytes(envelope)


def scenario_malformed(bus: Bus) -> None:
    alert = next(m for m in json_samples() if isinstance(m, Alert))
    good = codec.encode_json(alert)
    obj = json.loads(good)
    bad_version = json.dumps({**obj, "schema_version": 99}).encode()
    nan = good.replace(b'"station_m":500.0', b'"station_m":NaN')
    assert nan != good
    alerts = bus.publisher(bus.keys.alerts("speeding"), Alert)
    frames = bus.publisher(bus.keys.raw_lidar("lidar-mast"), LidarFrameMeta, block=True)
    _wait(alerts, alerts.key)
    _wait(frames, frames.key)
    for payload in (good, b"{oops", bad_version, nan, b" " * (codec.MAX_JSON_BYTES + 10), good):
        alerts.put_bytes(payload)
    envelope = encoded_lidar(7, 128)
    for payload in (envelope, envelope[:-100], b"WZF1", envelope):
        frames.put_bytes(payload)


def scenario_history(bus: Bus, count: int) -> None:
    alert = next(m for m in json_samples() if isinstance(m, Alert))
    alerts = bus.publisher(bus.keys.alerts("speeding"), Alert, history=count)
    more = bus.subscribe_raw(f"{bus.keys.prefix}/test/more")
    for i in range(count):  # nobody listens yet: only the history keeps them
        alerts.put(alert.model_copy(update={"alert_id": f"early-{i}"}))
    print("published", flush=True)
    if more.recv(30.0) is None:
        raise SystemExit("the test never asked for more")
    for i in range(count):
        alerts.put(alert.model_copy(update={"alert_id": f"live-{i}"}))


def main() -> None:
    endpoint, scenario, *args = sys.argv[1:]
    settings = BusSettings(mode="peer", connect_endpoints=[endpoint], listen_endpoints=[])
    with Bus.open(settings, site=SITE, service="bus-peer") as bus:
        ack = bus.subscribe_raw(f"{bus.keys.prefix}/test/ack")
        if scenario == "all":
            scenario_all(bus, int(args[0]))
        elif scenario == "frames":
            scenario_frames(bus, int(args[0]), float(args[1]), int(args[2]), args[3] == "1")
        elif scenario == "malformed":
            scenario_malformed(bus)
        elif scenario == "history":
            scenario_history(bus, int(args[0]))
        else:
            raise SystemExit(f"unknown scenario {scenario}")
        if ack.recv(30.0) is None:
            raise SystemExit("the test never acknowledged")


if __name__ == "__main__":
    main()
