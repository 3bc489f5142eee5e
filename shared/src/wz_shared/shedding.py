"""Shed stale work before it is decoded: a gate on a stream of stamped JSON messages.

A consumer that must answer within its normal latency whatever the inbound rate (the alert
service on the track batches) cannot decode every sample of a flood: at 20,000 batches a
second, decoding alone takes more than a core. Yet a batch stream carries information only
forward in time: a batch that is not newer than the last one let in (a replayed or
duplicated batch, a stale one) is worth nothing, and a batch a few milliseconds after the
last one let in says nothing new to rules that hold for a second. So :class:`StampGate`,
run on Zenoh's thread for each sample before it is queued, reads the message's ``stamp``
straight off the JSON bytes (no parsing of the rest) and sheds, by reason:

- ``stale``: not newer than the last admitted stamp of the current run (a duplicate, a
  replay, a late batch);
- ``superseded``: newer, but by less than ``min_interval_s`` (the stream faster than any
  tracker's cycle);

so what reaches the queue is at most one batch per ``min_interval_s`` of stamp time, in
order, and the consumer stays current. A new run (the stamps start again: a restarted
simulation or replay, :class:`~wz_shared.timebase.RunWatch`) is let through: a stamp
further back is admitted while it is newer than the last such stamp admitted (a run
starting again counts up), so the consumer's own :class:`RunWatch` sees the run confirmed;
a flood of one old batch is admitted once, then shed as stale.

The consumer tells the gate what became of each sample it let in (:meth:`StampGate.settle`,
and :meth:`StampGate.refused` for one that failed to decode): a batch refused after all (of
another site, undecodable) does not count as the newest, so the real batch of the same
stamp that follows it is not shed as stale.

A payload whose stamp cannot be read this way (another layout, not JSON) is admitted: the
consumer's full decode decides, and counts it if invalid. The first ``"stamp":`` key in a
valid message is its own: pydantic forbids unknown keys, no nested model of the bus carries a
``stamp``, and every string field before it is an identifier (no quotes).
"""

from __future__ import annotations

import math
import re
import threading
from typing import Literal

from wz_shared.timebase import NEW_RUN_CONFIRM_MESSAGES, NEW_RUN_STEP_BACK_S, RunWatch

ShedReason = Literal["stale", "superseded"]
_STAMP = re.compile(rb'"stamp":\s*(-?[0-9][0-9.eE+-]*)')


def peek_stamp(payload: bytes) -> float | None:
    """The ``stamp`` of a JSON message, read off its bytes; None when it cannot be."""
    match = _STAMP.search(payload)
    if match is None:
        return None
    try:
        value = float(match.group(1))
    except ValueError:
        return None
    return value if math.isfinite(value) else None


class StampGate:
    """Admit a stream's samples that carry news (see the module): :meth:`check` on Zenoh's
    thread, :meth:`settle` and :meth:`refused` on the consumer's (one gate per subscription).

    Parameters
    ----------
    min_interval_s : float
        Least stamp step between two admitted samples of one run [s]; 0 sheds only the stale.
    step_back_s, confirm : float, int
        How a new run is told (as :class:`~wz_shared.timebase.RunWatch`).
    """

    def __init__(
        self,
        min_interval_s: float,
        *,
        step_back_s: float = NEW_RUN_STEP_BACK_S,
        confirm: int = NEW_RUN_CONFIRM_MESSAGES,
    ) -> None:
        if not min_interval_s >= 0.0:
            raise ValueError(f"min_interval_s must be >= 0, got {min_interval_s}")
        self.min_interval_s = min_interval_s
        self._run = RunWatch(step_back_s, confirm)
        #: Last stamp admitted in the current run, and the last one further back admitted as
        #: a new run's candidate.
        self._last: float | None = None
        self._last_behind: float | None = None
        #: The newest stamp the consumer accepted.
        self._accepted: float | None = None
        self._lock = threading.Lock()

    def settle(self, stamp: float, accepted: bool) -> None:
        """The consumer took (``accepted``) or refused the sample of ``stamp`` let in."""
        with self._lock:
            if accepted:
                if self._accepted is None or stamp > self._accepted:
                    self._accepted = stamp
            elif stamp == self._last:
                self._last = self._accepted  # not the newest after all

    def refused(self, payload: bytes) -> None:
        """A sample let in failed to decode."""
        stamp = peek_stamp(payload)
        if stamp is not None:
            self.settle(stamp, accepted=False)

    def check(self, payload: bytes) -> ShedReason | None:
        """Why to shed ``payload``, or None to admit it."""
        stamp = peek_stamp(payload)
        if stamp is None:
            return None
        with self._lock:
            return self._check(stamp)

    def _check(self, stamp: float) -> ShedReason | None:
        verdict = self._run.observe(stamp)
        if verdict == "new_run":
            self._last, self._last_behind, self._accepted = stamp, None, None
            return None
        if verdict == "behind":
            if self._last_behind is not None and stamp <= self._last_behind:
                return "stale"
            self._last_behind = stamp
            return None
        self._last_behind = None
        newest = self._run.newest_s
        if self._accepted is not None and newest is not None and self._accepted > newest:
            self._accepted = None  # the old run's, settled after the new one began
        if self._accepted is not None and stamp <= self._accepted:
            return "stale"
        if self._last is not None:
            if stamp == self._last:
                return "stale"  # the same batch again, before the consumer settled it
            if self._last < stamp < self._last + self.min_interval_s:
                return "superseded"
        if self._last is None or stamp > self._last:
            self._last = stamp
        return None
