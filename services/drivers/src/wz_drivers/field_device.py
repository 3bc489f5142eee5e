"""What every roadside device the device driver drives has in common, whatever its protocol.

A message sign (NTCIP 1203 over SNMP) and a beacon relay (a Modbus TCP coil) differ in what
they show and how it is put on them, not in how the driver looks after them:

- the alert service says what it wants shown; the driver puts it on the device and reads back
  what the device then says it shows;
- a device that does not answer is tried again every ``retry_s``, and what it shows is read
  back every ``check_s`` (one restarted by its own controller comes back blank or off, and is
  set again);
- the link is reported in the service's status as a :class:`~wz_shared.messages.DeviceLink`.

:class:`FieldDevice` is that bookkeeping, with the protocol left to a subclass (``_put``,
``_get``, ``describe``). :class:`DeviceWorker` runs one device in a thread of its own, so that a
device that hangs (a timeout per exchange) delays only itself: never the other devices, nor
the service's loop and its status.
"""

from __future__ import annotations

import logging
import threading
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import Generic, TypeVar

from wz_shared.messages import DeviceLink

log = logging.getLogger("wz_drivers.field_device")

T = TypeVar("T")

#: A worker with nothing to do looks again this often [s] (a new wish wakes it at once).
IDLE_POLL_S = 0.05


class DeviceError(RuntimeError):
    """An exchange with a device failed.

    ``answered`` is False when the device did not answer at all (no connection, timeout): it
    is then unreachable and tried again soon. True when it answered but refused (the message
    says what and why): asking again at once would not help.
    """

    def __init__(self, message: str, *, answered: bool = True) -> None:
        super().__init__(message)
        self.answered = answered


class FieldDevice(ABC, Generic[T]):
    """Keeps one device showing the wanted value (``T``: a MULTI string, a relay's state).

    Subclasses say how to put a value on the device (:meth:`_put`), read it back
    (:meth:`_get`) and name it for people (:meth:`describe`). Not thread-safe: one thread
    calls :meth:`want` and :meth:`step` (:class:`DeviceWorker`'s).

    Parameters
    ----------
    address : str
        Where the device is, as the status reports it (``udp 10.0.0.9:161``).
    retry_s : float
        After an exchange that got no answer, the next try [s].
    check_s : float
        What the device shows is read back this often [s]; a device that refused is asked
        again after this long.
    """

    #: What the logs call the device.
    kind = "device"

    def __init__(self, address: str, retry_s: float, check_s: float) -> None:
        self.address = address
        self.retry_s = retry_s
        self.check_s = check_s
        self.wanted: T | None = None  # None: nothing asked yet
        self.shown: T | None = None  # what the device last said it shows; None: unknown
        self.reachable: bool | None = None
        self.detail = "not contacted yet"
        self.answered_at: float | None = None
        self._next_try = 0.0
        self._next_check = 0.0

    # --- the protocol (subclasses) ------------------------------------------------------

    @abstractmethod
    def _put(self, value: T) -> T:
        """Put ``value`` on the device; what it then says it shows. Raises DeviceError."""

    @abstractmethod
    def _get(self) -> T:
        """What the device says it shows now. Raises DeviceError."""

    def describe(self, value: T) -> str:
        """``value`` for people (the status's ``shows``, the logs)."""
        return str(value)

    def close(self) -> None:
        """Let go of the connection (the driver stops)."""

    # --- the bookkeeping ----------------------------------------------------------------

    def want(self, value: T) -> None:
        """Ask for ``value``; a new one is put on the device at the next :meth:`step`."""
        if value != self.wanted:
            self.wanted = value
            self._next_try = 0.0

    def step(self, now: float) -> bool:
        """Talk to the device if there is something to do at ``now`` (monotonic [s]).

        Returns
        -------
        bool
            Whether it changed what the device shows.
        """
        if now < self._next_try:
            return False
        try:
            if self.wanted is not None and self.shown != self.wanted:
                started = time.monotonic()
                self.shown = self._put(self.wanted)
                self._answered(now)
                log.info(
                    "%s %s shows %s (%.0f ms)",
                    self.kind,
                    self.address,
                    self.describe(self.shown),
                    1000 * (time.monotonic() - started),
                )
                return True
            if now >= self._next_check:
                self.shown = self._get()
                self._answered(now)
                if self.wanted is not None and self.shown != self.wanted:
                    log.warning(
                        "%s %s shows %s, not %s: setting it again",
                        self.kind,
                        self.address,
                        self.describe(self.shown),
                        self.describe(self.wanted),
                    )
                    return self.step(now)
        except DeviceError as exc:
            if exc.answered:  # it answers but refuses: asking again soon will not help
                log.error("%s %s refused %r: %s", self.kind, self.address, self.wanted, exc)
                self._answered(now)
                wanted = "" if self.wanted is None else self.describe(self.wanted)
                self.detail = f"refused {wanted!r}: {exc}"
                self._next_try = now + self.check_s
                return False
            self.lost(now, str(exc))
        return False

    def lost(self, now: float, why: str) -> None:
        """The device did not answer (or its driver failed): unreachable, tried again after
        ``retry_s``, what it shows unknown until it answers."""
        if self.reachable is not False:
            log.error("%s %s: %s", self.kind, self.address, why)
        self.reachable = False
        self.detail = why
        self.shown = None  # unknown: set it again once it answers
        self._next_try = now + self.retry_s

    def _answered(self, now: float) -> None:
        if self.reachable is False:
            log.warning("%s %s answers again", self.kind, self.address)
        self.reachable = True
        self.detail = "" if self.shown is None else f"showing {self.describe(self.shown)!r}"
        self.answered_at = now
        self._next_check = now + self.check_s

    def link(self, now: float) -> DeviceLink:
        """The device as the status reports it (``now``: monotonic [s])."""
        return DeviceLink(
            address=self.address[:256],
            reachable=self.reachable,
            detail=self.detail[:512],
            shows=None if self.shown is None else self.describe(self.shown)[:512],
            answer_age_s=None if self.answered_at is None else max(0.0, now - self.answered_at),
        )


class DeviceWorker(Generic[T]):
    """One :class:`FieldDevice` driven in a thread of its own.

    The service's loop hands it wishes (:meth:`want`, never blocking) and reads its link
    (:meth:`link`); the thread does the talking, however long the device takes to answer.

    Parameters
    ----------
    name : str
        The thread's name (the device's, in the status).
    address : str
        Where the device is: the link reported before the thread has built its driver.
    make : callable
        Builds the driver, in the thread (a client's sockets and event loop belong to it).
    stop : threading.Event
        Set when the service stops; the thread then closes the driver and ends.
    """

    def __init__(
        self,
        name: str,
        address: str,
        make: Callable[[], FieldDevice[T]],
        stop: threading.Event,
    ) -> None:
        self.name = name
        self.address = address
        self.changes = 0
        self.driver: FieldDevice[T] | None = None
        self._failure: str | None = None  # why no driver could be built
        self._make = make
        self._stop = stop
        self._lock = threading.Lock()  # guards _pending only: never held while talking
        self._pending: tuple[T] | None = None
        self._wake = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)

    def start(self) -> None:
        self._thread.start()

    def join(self, timeout_s: float) -> None:
        """Wait for the thread to end (after ``stop``) at most ``timeout_s``."""
        self._wake.set()
        self._thread.join(timeout_s)
        if self._thread.is_alive():
            log.warning("%s still talking to %s at stop", self.name, self.address)

    def want(self, value: T) -> None:
        """Ask for ``value``: the thread puts the newest wish on the device."""
        with self._lock:
            self._pending = (value,)
        self._wake.set()

    def link(self, now: float) -> DeviceLink:
        """The device's link as its driver last found it (``now``: monotonic [s])."""
        driver = self.driver
        if driver is None:
            reachable = None if self._failure is None else False
            detail = self._failure or "not contacted yet"
            return DeviceLink(address=self.address[:256], reachable=reachable, detail=detail[:512])
        return driver.link(now)

    def _run(self) -> None:
        try:
            driver = self._make()
        except Exception as exc:  # a driver that cannot be built: said, and the service goes on
            log.exception("%s: cannot drive %s", self.name, self.address)
            self._failure = f"cannot drive it: {exc!r}"
            return
        self.driver = driver
        try:
            while not self._stop.is_set():
                self._wake.wait(IDLE_POLL_S)
                self._wake.clear()
                with self._lock:
                    pending, self._pending = self._pending, None
                if pending is not None:
                    driver.want(pending[0])
                try:
                    self.changes += driver.step(time.monotonic())
                except Exception as exc:  # a bug or a library's surprise: said, not fatal
                    log.exception("%s: driving %s failed", self.name, self.address)
                    driver.lost(time.monotonic(), f"driver error: {exc!r}")
        finally:
            driver.close()
