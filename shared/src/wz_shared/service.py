"""What every service node shares: open the bus, say it is alive, report health, stop cleanly.

A node's ``main()`` reads its settings, then::

    with ServiceRuntime("simulator", site.site_id, BusSettings()) as runtime:
        while not runtime.stop.is_set():
            ...  # decode, call the core, publish on runtime.bus

On entry the runtime declares the liveliness token ``wz/<site>/status/<service>`` and starts
publishing a :class:`ServiceStatus` there every ``status_period_s`` (message rates per key,
invalid and dropped counts). With a ``health_file`` (``WZ_HEALTH_FILE``), each status published
also touches that file, which a container healthcheck reads (``python -m wz_shared.health``).
SIGTERM and SIGINT set ``stop``; leaving the block closes the bus.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from pathlib import Path
from typing import Any

from wz_shared import health
from wz_shared.bus import Bus, BusStats
from wz_shared.messages import ServiceState, ServiceStatus
from wz_shared.settings import BusSettings
from wz_shared.signals import stop_on_signals

log = logging.getLogger(__name__)


def _rates(now: dict[str, int], before: dict[str, int], dt_s: float) -> dict[str, float]:
    return {key: round((n - before.get(key, 0)) / dt_s, 3) for key, n in now.items()}


class ServiceRuntime:
    """Bus, liveliness, health reporting and signal handling for one service process."""

    def __init__(
        self,
        service: str,
        site: str,
        bus_settings: BusSettings,
        *,
        status_period_s: float = 1.0,
        clock_stamp: Any = None,
        health_file: Path | None = None,
    ) -> None:
        self.service = service
        self.site = site
        self.bus_settings = bus_settings
        self.status_period_s = status_period_s
        #: Touched after each status message published; removed on a clean stop.
        self.health_file = health_file
        self.stop = threading.Event()
        self.state = ServiceState.STARTING
        #: Callable returning the stamp to put on status messages (simulation time in sim).
        self._clock_stamp = clock_stamp or time.time
        self._started = time.monotonic()
        self._bus: Bus | None = None
        self._health: threading.Thread | None = None

    @property
    def bus(self) -> Bus:
        if self._bus is None:
            raise RuntimeError("the service runtime is not entered")
        return self._bus

    def __enter__(self) -> ServiceRuntime:
        self._install_signal_handlers()
        self._bus = Bus.open(self.bus_settings, site=self.site, service=self.service)
        self._bus.declare_alive()
        self.state = ServiceState.RUNNING
        self._health = threading.Thread(target=self._report_health, name="health", daemon=True)
        self._health.start()
        log.info("service %s up at site %s (pid %d)", self.service, self.site, os.getpid())
        return self

    def __exit__(self, *exc: object) -> None:
        self.state = ServiceState.STOPPING
        self.stop.set()
        if self._health is not None:
            self._health.join(timeout=2.0)
        if self._bus is not None:
            self._bus.close()
        if self.health_file is not None:
            self.health_file.unlink(missing_ok=True)
        log.info("service %s stopped", self.service)

    def _install_signal_handlers(self) -> None:
        if threading.current_thread() is threading.main_thread():
            stop_on_signals(self.stop)  # (wz_shared.signals: no lock taken in the handler)

    def status_message(
        self,
        stats: BusStats,
        previous: dict[str, dict[str, int]],
        dt_s: float,
    ) -> tuple[ServiceStatus, dict[str, dict[str, int]]]:
        snap = stats.snapshot()
        status = ServiceStatus(
            site=self.site,
            source_id=self.service,
            stamp=max(0.0, float(self._clock_stamp())),
            service=self.service,
            state=self.state,
            uptime_s=time.monotonic() - self._started,
            pid=os.getpid(),
            published_hz=_rates(snap["published"], previous.get("published", {}), dt_s),
            received_hz=_rates(snap["received"], previous.get("received", {}), dt_s),
            invalid_counts=snap["invalid"],
            dropped_counts=snap["dropped"],
        )
        return status, snap

    def _report_health(self) -> None:
        bus = self.bus
        publisher = bus.publisher(bus.keys.status(self.service), ServiceStatus)
        previous: dict[str, dict[str, int]] = {}
        last = time.monotonic()
        while not self.stop.wait(self.status_period_s):
            now = time.monotonic()
            try:
                status, previous = self.status_message(bus.stats, previous, max(now - last, 1e-3))
                publisher.put(status)
                if self.health_file is not None:
                    health.touch(self.health_file)
            except Exception:
                if bus.closed:
                    return
                log.exception("could not publish health")
            last = now
