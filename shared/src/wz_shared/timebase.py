"""Simulation time and wall-clock time behind one interface.

Logic never reads the wall clock or sleeps: it takes ``stamp`` values from messages, or asks a
:class:`Clock`. The simulator advances a :class:`SimClock`; a :class:`Pacer` holds a loop to a
multiple of real time (or lets it run as fast as possible).
"""

from __future__ import annotations

import threading
import time
from typing import Literal, Protocol

#: A stream whose own stamps go back by more than this [s], several messages in a row, has
#: started a new run (:class:`RunWatch`).
NEW_RUN_STEP_BACK_S = 1.0
#: ... that many messages in a row [-].
NEW_RUN_CONFIRM_MESSAGES = 3

RunVerdict = Literal["run", "behind", "new_run"]


def stamp_went_back(
    newest_s: float | None, stamp_s: float, step_back_s: float = NEW_RUN_STEP_BACK_S
) -> bool:
    """Whether ``stamp_s`` is further back than ``step_back_s`` from a stream's newest stamp.

    The one test of "the stamps went back" (a restarted simulation or replay counts from its
    start again); None: no stamp yet. :class:`RunWatch` calls a new run only after
    ``confirm`` such stamps in a row; a consumer that must decide on the first one (the
    gateway's store) calls this directly.
    """
    return newest_s is not None and stamp_s < newest_s - step_back_s


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

    def restart(self, t_s: float) -> None:
        """A new run (a restarted simulation counts from its start again): the time is ``t_s``,
        earlier or not. Only for that; within a run, :meth:`advance_to`."""
        with self._lock:
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


class RunWatch:
    """Tells when one stream's stamps start again: a new run.

    A restarted simulation counts from its start again (a replayed recording too). A consumer
    that keeps state over time (a tracker, an ordering check) would otherwise drop everything
    as late or out of order until the new stamps passed the old ones; told of the new run, it
    starts its state again. One stream's own stamps (one sensor's frames, one producer's
    batches) never go back otherwise: lateness is against other streams.

    :meth:`observe` says, for each stamp of the stream in arrival order:

    - ``"run"``: in the current run (at most ``step_back_s`` before its newest stamp);
    - ``"behind"``: further back, not (yet) a new run: treat it as late or out of order. A
      single stray message stays that;
    - ``"new_run"``: the ``confirm`` th stamp in a row that far back, each after the one
      before: the stream has started again, and this stamp belongs to the new run.
    """

    def __init__(
        self, step_back_s: float = NEW_RUN_STEP_BACK_S, confirm: int = NEW_RUN_CONFIRM_MESSAGES
    ) -> None:
        if step_back_s < 0 or confirm < 1:
            raise ValueError(f"step_back_s >= 0 and confirm >= 1, got {step_back_s}, {confirm}")
        self.step_back_s = step_back_s
        self.confirm = confirm
        #: Newest stamp of the current run [s]; None before the first.
        self.newest_s: float | None = None
        self._behind: list[float] = []

    def observe(self, stamp_s: float) -> RunVerdict:
        newest = self.newest_s
        if not stamp_went_back(newest, stamp_s, self.step_back_s):
            self._behind.clear()
            self.newest_s = stamp_s if newest is None else max(newest, stamp_s)
            return "run"
        if self._behind and stamp_s <= self._behind[-1]:
            self._behind.clear()  # not a stream going on from a new start
        self._behind.append(stamp_s)
        if len(self._behind) < self.confirm:
            return "behind"
        self._behind.clear()
        self.newest_s = stamp_s
        return "new_run"
