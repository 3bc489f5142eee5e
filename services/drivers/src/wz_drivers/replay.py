"""Publish a field log on the bus: ``wz replay LOG_DIR`` and the drivers node.

Every source's records become the messages the simulator would publish for that sensor
(:mod:`wz_drivers.sources`), merged in stamp order and paced on the first stamp: a message
stamped ``t`` goes out at ``start + (t - t0) / rate`` (``rate`` None: as fast as possible; the
detectors then see the newest frame each time they are free, as they would behind a live
sensor they cannot keep up with). The pipeline downstream (LiDAR and camera detectors, fusion
tracker, alert service, gateway) must run with the log's site file, whose mounts place each
sensor: ``wz up --site LOG_DIR/site.yaml --only lidar-detector,...``.

Records the readers could not use are reported (file and line) and skipped; the summary
counts them and the exit code is then 3, as for a recording cut short.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from pathlib import Path
from typing import Any

from wz_drivers.log import FieldLog, load_log
from wz_drivers.records import Problems
from wz_drivers.sources import Outgoing, merged
from wz_shared.bus import Bus, Publisher
from wz_shared.messages import CameraFrameMeta, DetectionBatch, LidarFrameMeta

log = logging.getLogger(__name__)

#: Exit code of a replay that skipped records (everything readable was replayed).
EXIT_SKIPPED = 3
#: The message type of each source kind (frames travel as envelopes of their metadata).
MESSAGE_CLASS = {"lidar": LidarFrameMeta, "camera": CameraFrameMeta, "objects": DetectionBatch}


class _Publishers:
    """One publisher per sensor of the log, declared up front; frames block like every
    replayed message (a replay reproduces the log: nothing is dropped on the way out)."""

    def __init__(self, bus: Bus, field_log: FieldLog, wait_subscribers_s: float) -> None:
        self._by_sensor: dict[str, Publisher[Any]] = {}
        self._waited = False
        self._wait_s = wait_subscribers_s
        self._bus = bus
        self._log = field_log

    def publisher(self, out: Outgoing) -> Publisher[Any]:
        publisher = self._by_sensor.get(out.sensor_id)
        if publisher is None:
            source = next(s for s in self._log.sources if s.sensor_id == out.sensor_id)
            publisher = self._bus.publisher(out.key, MESSAGE_CLASS[source.kind], block=True)
            self._by_sensor[out.sensor_id] = publisher
            if not self._waited:  # declarations take a moment to reach the subscribers
                publisher.wait_for_subscribers(self._wait_s)
                self._waited = True
        return publisher


def replay_log(
    bus: Bus,
    field_log: FieldLog,
    *,
    rate: float | None,
    stop: threading.Event,
    wait_subscribers_s: float = 2.0,
    loop: bool = False,
    only: set[str] | None = None,
) -> tuple[Counter[str], Problems]:
    """Publish the log; the messages sent per sensor, and the records skipped."""
    problems = Problems()
    sent: Counter[str] = Counter()
    publishers = _Publishers(bus, field_log, wait_subscribers_s)
    while True:
        first_stamp: float | None = None
        start = time.monotonic()
        for out in merged(field_log, problems, only):
            if stop.is_set():
                return sent, problems
            if first_stamp is None:
                first_stamp = out.stamp
            if rate is not None:
                delay = start + (out.stamp - first_stamp) / rate - time.monotonic()
                if delay > 0 and stop.wait(delay):
                    return sent, problems
            publishers.publisher(out).put_bytes(out.payload)
            sent[out.sensor_id] += 1
        if not loop or stop.is_set() or not sent:
            return sent, problems


def run_field_replay(
    bus: Bus,
    folder: Path,
    *,
    rate: float | None,
    loop: bool,
    wait_subscribers_s: float,
    stop: threading.Event,
    emit: Any = print,
) -> int:
    """``wz replay LOG_DIR``: replay, print a summary, return the exit code."""
    field_log = load_log(folder)
    log.info("replaying field log %s of site %s", folder, field_log.site.site_id)
    started = time.monotonic()
    sent, problems = replay_log(
        bus, field_log, rate=rate, stop=stop, loop=loop, wait_subscribers_s=wait_subscribers_s
    )
    elapsed = time.monotonic() - started
    emit(f"replayed {folder} (site {field_log.site.site_id}) in {elapsed:.1f} s:")
    for source in field_log.sources:
        emit(
            f"  {source.sensor_id:<16} {source.kind:<8} {source.format:<7} "
            f"{sent.get(source.sensor_id, 0):>6} messages"
        )
    if problems:
        emit(f"skipped {len(problems)} records that could not be read:")
        for path, count in problems.summary().items():
            first = next(e for e in problems.errors if e.path == path)
            emit(f"  {count:>5} in {path}; first: {first}")
        return EXIT_SKIPPED
    return 0
