"""The drivers node: a trailer's real sensors (or a field log) onto the bus.

Run it as ``python -m wz_drivers.node`` with ``WZ_DRIVERS_SOURCES=<manifest>``: a field-log
manifest (:mod:`wz_drivers.log`) whose sources are live devices (``ouster://<host>``,
``rtsp://...``, ``udp://<host>:<port>``) or recordings. Each source gets a thread that reads it
and publishes its messages as they come (the simulator's keys: ``raw/lidar/<id>``,
``raw/camera/<id>``, ``detections/<id>``); a manifest of recordings only is replayed in time
order at ``WZ_DRIVERS_RATE`` (1: the recorded pace), looped with ``WZ_DRIVERS_LOOP``.

The site is the manifest's: the other services must run with the same site file. A device
that fails (unreachable, a stream that ends) is logged and read again after
``WZ_DRIVERS_RETRY_S``; records it sends that cannot be used are counted in the status
message's ``invalid_counts`` (``<key>|<reason>``) and dropped.
"""

from __future__ import annotations

import logging
import threading
from typing import Any

from wz_drivers.log import FieldLog, LogSource, load_log
from wz_drivers.records import FieldDataError, Problems
from wz_drivers.replay import MESSAGE_CLASS, replay_log
from wz_drivers.settings import DriversSettings
from wz_drivers.sources import key_of, source_messages
from wz_shared.bus import Bus, Publisher
from wz_shared.service import NodeApp, ServiceRuntime

SERVICE = "drivers"
log = logging.getLogger(__name__)


class _Reporter(Problems):
    """Problems of one source, counted on the bus's invalid counters under its key."""

    def __init__(self, bus: Bus, key: str) -> None:
        super().__init__()
        self._bus, self._key = bus, key

    def add(self, error: FieldDataError) -> None:
        super().add(error)
        self._bus.stats.count_invalid(self._key, "bad_record", str(error))


def _run_live(
    bus: Bus,
    field_log: FieldLog,
    source: LogSource,
    settings: DriversSettings,
    stop: threading.Event,
) -> None:
    key = key_of(field_log.site, source)
    # Frames are dropped under congestion (a stale frame is worthless), object lists are not.
    publisher: Publisher[Any] = bus.publisher(
        key, MESSAGE_CLASS[source.kind], block=source.kind == "objects"
    )
    problems = _Reporter(bus, key)
    while not stop.is_set():
        try:
            for out in source_messages(field_log, source, problems, stop):
                publisher.put_bytes(out.payload)
                if stop.is_set():
                    return
            log.warning(
                "%s: %s ended; reading it again in %.0f s",
                source.sensor_id,
                source.path,
                settings.retry_s,
            )
        except FieldDataError as exc:
            log.warning("%s: %s; trying again in %.0f s", source.sensor_id, exc, settings.retry_s)
        except Exception:  # a driver bug must not take the other sensors down
            log.exception(
                "%s: the driver failed; trying again in %.0f s", source.sensor_id, settings.retry_s
            )
        stop.wait(settings.retry_s)


def run(runtime: ServiceRuntime, field_log: FieldLog, settings: DriversSettings) -> None:
    if not any(source.live for source in field_log.sources):
        rate = None if settings.rate == 0.0 else settings.rate
        sent, problems = replay_log(
            runtime.bus, field_log, rate=rate, stop=runtime.stop, loop=settings.loop
        )
        log.info("replayed %s: %s; %d records skipped", field_log.folder, dict(sent), len(problems))
        while not runtime.stop.wait(1.0):  # stay alive (and healthy) until stopped
            runtime.beat()
        return
    threads = [
        threading.Thread(
            target=_run_live,
            name=source.sensor_id,
            daemon=True,
            args=(runtime.bus, field_log, source, settings, runtime.stop),
        )
        for source in field_log.sources
    ]
    for thread in threads:
        thread.start()
    log.info("reading %s", ", ".join(f"{s.sensor_id} ({s.path})" for s in field_log.sources))
    # The readers are threads of their own (a silent sensor is no stalled loop): this loop
    # goes round while the process's main thread is free.
    while not runtime.stop.wait(1.0):
        runtime.beat()
    for thread in threads:
        thread.join(timeout=5.0)


def main() -> None:
    node = NodeApp(SERVICE, DriversSettings)
    sources = node.settings.sources
    with node.fatal(FieldDataError):  # the site is the field log's
        field_log = load_log(sources.parent if sources.is_file() else sources)
    node.start_logging(field_log.site.site_id)
    node.serve(lambda runtime: run(runtime, field_log, node.settings), sim_clock=False)


if __name__ == "__main__":
    main()
