"""What every service node shares: open the bus, say it is alive, report health, stop cleanly.

A node's ``main()`` reads its settings, then::

    with ServiceRuntime("simulator", site.site_id, BusSettings()) as runtime:
        while not runtime.stop.is_set():
            ...  # decode, call the core, publish on runtime.bus

On entry the runtime declares the liveliness token ``wz/<site>/status/<service>`` and starts
publishing a :class:`ServiceStatus` there every ``status_period_s`` (message rates per key,
invalid and dropped counts). SIGTERM and SIGINT set ``stop``; leaving the block closes the bus.

Liveness comes from the work, not from the status thread: the node's loop calls
:meth:`ServiceRuntime.beat` each time it goes round (``processed=True`` when it handled an
input), and each status message says how old that is (``loop_age_s``, ``input_age_s``); past
``stall_after_s`` the state is ``stalled``. With a ``health_file`` (``WZ_HEALTH_FILE``), each
status published also sets that file's modification time to the loop's last round, so a
container healthcheck (``python -m wz_shared.health``) and ``wz up``'s supervisor see a blocked
loop even while the status thread goes on. Until the loop's first round (start-up: models
loading, the simulator warming up) the file is touched with the current time.

:class:`NodeApp` is the rest of every ``main()``: settings read (or the process stops saying
what is wrong), the site file read, logging configured with site/service/sensor, start-up
problems turned into an exit with their message, then the runtime around the node's loop::

    def main() -> None:
        node = NodeApp(SERVICE, AlertServiceSettings)
        site = node.load_site()
        published = node.serve(lambda runtime: run(runtime, site, node.settings, node.clock))
        log.info("stopped after %d alerts", published)
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Generic, TypeVar

from pydantic import ValidationError

from wz_shared import health
from wz_shared.bus import Bus, BusStats
from wz_shared.logs import configure_logging
from wz_shared.messages import DeviceLink, ServiceState, ServiceStatus
from wz_shared.metrics import RuntimeView, ServiceMetrics
from wz_shared.reach import BusWaitAbortedError
from wz_shared.settings import BusSettings, ServiceSettings
from wz_shared.signals import stop_on_signals
from wz_shared.site import Site, SiteFileError, load_site
from wz_shared.timebase import SimClock

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
        stall_after_s: float = 5.0,
        metrics_port: int | None = None,
        metrics_host: str = "127.0.0.1",
    ) -> None:
        self.service = service
        self.site = site
        self.bus_settings = bus_settings
        self.status_period_s = status_period_s
        #: Touched after each status message published; removed on a clean stop.
        self.health_file = health_file
        self.stop = threading.Event()
        self.state = ServiceState.STARTING
        #: A loop not gone round for this long is stalled [s].
        self.stall_after_s = stall_after_s
        #: Wall-clock times of the loop's last round and last processed input (None: not yet).
        self._loop_at: float | None = None
        self._input_at: float | None = None
        self._stalled = False
        #: Callable returning the stamp to put on status messages (simulation time in sim).
        self._clock_stamp = clock_stamp or time.time
        self._started = time.monotonic()
        self._bus: Bus | None = None
        self._health: threading.Thread | None = None
        #: The field devices the node drives, as it last found them (replaced whole by the
        #: node; read by the status thread): one it cannot reach makes the state ``degraded``.
        self.devices: dict[str, DeviceLink] = {}
        self.metrics_port = metrics_port
        self.metrics_host = metrics_host
        self.metrics: ServiceMetrics | None = None
        self._observed_arrival: float | None = None

    @property
    def bus(self) -> Bus:
        if self._bus is None:
            raise RuntimeError("the service runtime is not entered")
        return self._bus

    def __enter__(self) -> ServiceRuntime:
        self._install_signal_handlers()
        self._bus = Bus.open(
            self.bus_settings,
            site=self.site,
            service=self.service,
            on_wait=self._waiting_for_bus,
            stop=self.stop,
        )
        if self.health_file is not None:
            health.touch(self.health_file)  # on the bus: no more "waiting for the bus"
        self._bus.declare_alive()
        self.state = ServiceState.RUNNING
        if self.metrics_port is not None:
            self.metrics = ServiceMetrics(self._metrics_view(self._bus))
            self.metrics.serve(self.metrics_host, self.metrics_port)
        self._health = threading.Thread(target=self._report_health, name="health", daemon=True)
        self._health.start()
        log.info("service %s up at site %s (pid %d)", self.service, self.site, os.getpid())
        return self

    def _waiting_for_bus(self, reason: str) -> None:
        """No router yet (:mod:`wz_shared.reach`): the health file says why."""
        if self.health_file is not None:
            health.mark_waiting(self.health_file, reason)

    def __exit__(self, *exc: object) -> None:
        self.state = ServiceState.STOPPING
        self.stop.set()
        if self._health is not None:
            self._health.join(timeout=2.0)
        if self._bus is not None:
            self._bus.close()
        if self.metrics is not None:
            self.metrics.close()
        if self.health_file is not None:
            self.health_file.unlink(missing_ok=True)
        log.info("service %s stopped", self.service)

    def beat(self, processed: bool = False) -> None:
        """The node's loop went round (call it each time, also when it waited for input and
        got none); ``processed``: it handled an input this time."""
        now = time.time()
        self._loop_at = now
        if processed:
            self._input_at = now
            arrived = None if self._bus is None else self._bus.stats.last_taken_arrival
            if self.metrics is not None and arrived not in (None, self._observed_arrival):
                self._observed_arrival = arrived  # each input observed once
                self.metrics.processing.observe(max(0.0, time.monotonic() - arrived))

    def input_age_s(self, now: float | None = None) -> float | None:
        """Seconds since the loop last processed an input; None before its first."""
        if self._input_at is None:
            return None
        return max(0.0, (time.time() if now is None else now) - self._input_at)

    def current_state(self, loop_age_s: float | None = None) -> ServiceState:
        """The state to report: ``stalled`` past the stall limit, ``degraded`` while a field
        device it drives does not answer, else the runtime's own."""
        loop_age_s = self.loop_age_s() if loop_age_s is None else loop_age_s
        if self.state != ServiceState.STOPPING and (loop_age_s or 0.0) > self.stall_after_s:
            return ServiceState.STALLED
        if self.state == ServiceState.RUNNING and any(
            link.reachable is False for link in self.devices.values()
        ):
            return ServiceState.DEGRADED
        return self.state

    def _metrics_view(self, bus: Bus) -> RuntimeView:
        return RuntimeView(
            service=self.service,
            site=self.site,
            bus_snapshot=bus.stats.snapshot,
            queue_depths=bus.queue_depths,
            loop_age_s=self.loop_age_s,
            input_age_s=self.input_age_s,
            state=self.current_state,
            uptime_s=lambda: time.monotonic() - self._started,
            devices=lambda: dict(self.devices),
        )

    def loop_age_s(self, now: float | None = None) -> float | None:
        """Seconds since the loop's last round; None before its first."""
        if self._loop_at is None:
            return None
        return max(0.0, (time.time() if now is None else now) - self._loop_at)

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
        now = time.time()
        loop_age_s = self.loop_age_s(now)
        input_age_s = self.input_age_s(now)
        devices = dict(self.devices)
        state = self.current_state(loop_age_s)
        status = ServiceStatus(
            site=self.site,
            source_id=self.service,
            stamp=max(0.0, float(self._clock_stamp())),
            service=self.service,
            state=state,
            uptime_s=time.monotonic() - self._started,
            pid=os.getpid(),
            published_hz=_rates(snap["published"], previous.get("published", {}), dt_s),
            received_hz=_rates(snap["received"], previous.get("received", {}), dt_s),
            invalid_counts=snap["invalid"],
            dropped_counts=snap["dropped"],
            shed_counts=snap["shed"],
            loop_age_s=None if loop_age_s is None else round(loop_age_s, 3),
            input_age_s=None if input_age_s is None else round(input_age_s, 3),
            devices=devices,
        )
        stalled = state == ServiceState.STALLED
        if stalled and not self._stalled:
            log.error(
                "the %s loop has not gone round for %.1f s (limit %.1f s): stalled",
                self.service,
                loop_age_s,
                self.stall_after_s,
            )
        elif self._stalled and not stalled:
            log.warning("the %s loop goes round again", self.service)
        self._stalled = stalled
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
                    # The loop's last round, not now: a blocked loop ages the file.
                    health.touch(self.health_file, self._loop_at)
            except Exception:
                if bus.closed:
                    return
                log.exception("could not publish health")
            last = now


SettingsT = TypeVar("SettingsT", bound=ServiceSettings)
T = TypeVar("T")


class NodeApp(Generic[SettingsT]):
    """The start and stop every service's ``main()`` shares, around its own loop.

    In order: the constructor reads the settings; :meth:`load_site` reads the site file and
    :meth:`start_logging` configures the logs (:meth:`load_site` does both, for a node with no
    sensor of its own); :meth:`fatal` wraps the node's own start-up checks; :meth:`serve` runs
    the loop inside a :class:`ServiceRuntime`. Every start-up problem ends the process with
    ``SystemExit("<service>: <what is wrong>")``, for an operator, not a traceback.

    Parameters
    ----------
    service : str
        The service's name (``alert-service``): the logs', the status key's and the exits'.
    settings_type : type of ServiceSettings
        Built here, from the environment.

    Attributes
    ----------
    settings : ServiceSettings
        The settings read.
    clock : SimClock
        The node's time, advanced by its loop from the stamps of what it handles; the status
        messages carry it when :meth:`serve` is given ``sim_clock=True``.
    """

    def __init__(self, service: str, settings_type: type[SettingsT]) -> None:
        self.service = service
        try:
            self.settings: SettingsT = settings_type()
        except ValidationError as exc:
            raise SystemExit(f"{service}: invalid settings: {exc}") from exc
        self.clock = SimClock()
        self.site_id: str | None = None

    @contextmanager
    def fatal(self, *errors: type[Exception]) -> Iterator[None]:
        """Turn ``errors`` raised in the block into the process's exit, with their message."""
        try:
            yield
        except errors as exc:
            raise SystemExit(f"{self.service}: {exc}") from exc

    def read_site(self) -> Site:
        """The settings' site file (``WZ_SITE_FILE``); logging is not configured yet."""
        with self.fatal(SiteFileError):
            return load_site(self.settings.site_file)

    def load_site(self) -> Site:
        """The settings' site file, and logging configured for it (no sensor)."""
        site = self.read_site()
        self.start_logging(site.site_id)
        return site

    def start_logging(self, site_id: str, sensor: str | None = None) -> None:
        """Structured logs with site, service (and sensor) on every line; the site is the one
        :meth:`serve` reports under."""
        configure_logging(
            service=self.service, site=site_id, sensor=sensor, level=self.settings.log_level
        )
        self.site_id = site_id

    def serve(
        self,
        loop: Callable[[ServiceRuntime], T],
        *,
        sim_clock: bool = True,
        health_file: bool = True,
    ) -> T:
        """Run ``loop(runtime)`` inside a :class:`ServiceRuntime`; what it returns.

        Parameters
        ----------
        loop : callable
            The node's loop, until ``runtime.stop``.
        sim_clock : bool
            Stamp status messages with :attr:`clock` (stream time); False: the wall clock.
        health_file : bool
            Touch the settings' ``health_file`` with each status message.
        """
        if self.site_id is None:
            raise RuntimeError("start_logging (or load_site) comes before serve")
        settings = self.settings
        try:
            with ServiceRuntime(
                self.service,
                self.site_id,
                BusSettings(),
                status_period_s=settings.status_period_s,
                clock_stamp=self.clock.now if sim_clock else None,
                health_file=settings.health_file if health_file else None,
                stall_after_s=settings.stall_after_s,
                metrics_port=settings.metrics_port,
                metrics_host=settings.metrics_host,
            ) as runtime:
                return loop(runtime)
        except BusWaitAbortedError:  # SIGTERM while no router could be reached: a clean stop
            if settings.health_file is not None and health_file:
                settings.health_file.unlink(missing_ok=True)
            log.info("%s stopped before it joined the bus", self.service)
            raise SystemExit(0) from None
