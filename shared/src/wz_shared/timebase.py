"""Simulation time and wall-clock time behind one interface.

Logic never reads the wall clock or sleeps: it takes ``stamp`` values from messages, or asks a
:class:`Clock`. The simulator advances a :class:`SimClock`; a :class:`Pacer` holds a loop to a
multiple of real time (or lets it run as fast as possible).
"""

from __future__ import annotations

import threading
import time
from typing import Protocol


class Clock(Protocol):
    def now(self) -> float:
        """Current time [s]."""
        ...


class WallClock:
    """Real time (seconds since the epoch), for drivers of real sensors."""

    def now(self) -> float:
        return time.time()


class SimClock:
    """Simulation time, advanced by whoever owns the simulation. Thread-safe."""

    def __init__(self, start_s: float = 0.0) -> None:
        self._now = start_s
        self._lock = threading.Lock()

    def now(self) -> float:
        with self._lock:
            return self._now

    def advance_to(self, t_s: float) -> None:
        with self._lock:
            if t_s < self._now:
                raise ValueError(f"simulation time cannot go back ({t_s} < {self._now})")
            self._now = t_s


class Pacer:
    """Holds a loop to ``realtime_factor`` x real time; 0 means as fast as possible.

    ``wait_until(sim_t)`` sleeps until the wall clock has caught up with simulation time
    ``sim_t`` (measured from the first call). If the loop falls behind it does not try to catch
    up in a burst by more than ``max_lag_s``.
    """

    def __init__(self, realtime_factor: float, max_lag_s: float = 1.0) -> None:
        if realtime_factor < 0:
            raise ValueError("realtime_factor must be >= 0")
        self.realtime_factor = realtime_factor
        self.max_lag_s = max_lag_s
        self._origin: tuple[float, float] | None = None  # (wall, sim)

    def wait_until(self, sim_t_s: float, stop: threading.Event | None = None) -> None:
        if self.realtime_factor == 0:
            return
        wall = time.monotonic()
        if self._origin is None:
            self._origin = (wall, sim_t_s)
            return
        wall0, sim0 = self._origin
        target = wall0 + (sim_t_s - sim0) / self.realtime_factor
        delay = target - wall
        if delay < -self.max_lag_s:
            self._origin = (wall, sim_t_s)  # fell far behind: re-anchor rather than burst
            return
        if delay > 0:
            if stop is not None:
                stop.wait(delay)
            else:
                time.sleep(delay)
