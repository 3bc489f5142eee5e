"""``wz replay``: publish a recording back on the bus, each payload on its recorded key.

Pacing follows the recorded receive times (``log_time`` deltas divided by ``--rate``), or none
with ``--fast``. Publishers block under congestion (nothing is dropped: a replay should
reproduce what was recorded, frames included). Declarations take a moment to reach other
processes, so before its first message on a key the replay waits for a subscriber, at most
``--wait-subscribers`` seconds in all.

A recording cut short (no footer, or truncated inside a record) is replayed up to its last
complete message, and the summary says so; the exit code is then 3.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from pathlib import Path
from typing import Any, Literal

import zenoh

from wz_cli.common import CliError, emit, format_table
from wz_cli.recording import (
    ReadReport,
    RecordedMessage,
    RecordingError,
    RecordingReader,
    describe_report,
)
from wz_shared.bus import Bus, Publisher
from wz_shared.messages import FRAME_MESSAGES, JSON_MESSAGES, Message

log = logging.getLogger(__name__)

#: Exit code of a replay whose recording was incomplete (everything readable was replayed).
EXIT_INCOMPLETE = 3


class _UnrecognisedPayload(Message):
    """Type tag of a publisher for payloads that were no valid message when recorded.

    It only selects a publisher for ``put_bytes``; nothing is ever encoded as this type.
    """

    kind: Literal["unrecognised_payload"] = "unrecognised_payload"


def _publisher_class(message: RecordedMessage) -> type[Message]:
    kind = message.kind or ""
    return JSON_MESSAGES.get(kind) or FRAME_MESSAGES.get(kind) or _UnrecognisedPayload


class _Publishers:
    """One publisher per recorded key, declared on first use."""

    def __init__(self, bus: Bus, wait_subscribers_s: float) -> None:
        self._bus = bus
        self._publishers: dict[str, Publisher[Any]] = {}
        self._wait_budget_s = wait_subscribers_s
        self.failed: Counter[str] = Counter()

    def get(self, message: RecordedMessage) -> tuple[Publisher[Any] | None, float]:
        """The publisher of the message's key, and how long was spent waiting for subscribers."""
        publisher = self._publishers.get(message.topic)
        if publisher is not None:
            return publisher, 0.0
        if message.topic in self.failed:
            self.failed[message.topic] += 1
            return None, 0.0
        try:
            publisher = self._bus.publisher(message.topic, _publisher_class(message), block=True)
        except zenoh.ZError as exc:  # a topic that is no valid key
            log.error("cannot publish on %r: %s; skipping its messages", message.topic, exc)
            self.failed[message.topic] += 1
            return None, 0.0
        self._publishers[message.topic] = publisher
        waited_s = 0.0
        if self._wait_budget_s > 0:
            began = time.monotonic()
            if not publisher.wait_for_subscribers(self._wait_budget_s):
                log.info("no subscriber for %s yet; replaying anyway", message.topic)
            waited_s = time.monotonic() - began
            self._wait_budget_s -= waited_s
        return publisher, waited_s


def run_replay(
    bus: Bus,
    path: Path,
    *,
    rate: float | None,
    loop: bool,
    wait_subscribers_s: float,
    stop: threading.Event,
) -> int:
    """Replay ``path`` at ``rate`` x recorded pace (None: as fast as possible).

    Returns 0, or :data:`EXIT_INCOMPLETE` when the file was cut short.
    """
    publishers = _Publishers(bus, wait_subscribers_s)
    counts: Counter[str] = Counter()
    report = ReadReport()
    passes = 0
    began = time.monotonic()
    while not stop.is_set():
        try:
            stream = path.open("rb")
        except OSError as exc:
            raise CliError(f"cannot read {path}: {exc}", 1) from exc
        with stream:
            reader = RecordingReader(stream)
            try:
                _replay_pass(reader, publishers, counts, rate, stop)
            except RecordingError as exc:
                raise CliError(f"cannot replay {path}: {exc}", 1) from exc
            report = reader.report
        passes += 1
        if report.problem is not None and passes == 1:
            log.warning("%s: %s", path, describe_report(report))
        if not loop or report.messages == 0:
            break
    elapsed_s = time.monotonic() - began
    pace = "fast" if rate is None else f"{rate:g}x"
    emit(
        f"replayed {sum(counts.values())} message(s) on {len(counts)} key(s) from {path} "
        f"in {elapsed_s:.1f} s ({passes} pass(es), {pace})"
    )
    if counts:
        for line in format_table(
            ("KEY", "MESSAGES"), sorted((k, str(n)) for k, n in counts.items())
        ):
            emit(line)
    if publishers.failed:
        emit(f"not replayed (invalid keys): {dict(publishers.failed)}")
    if report.problem is not None:
        emit(describe_report(report))
        return EXIT_INCOMPLETE
    return 0


def _replay_pass(
    reader: RecordingReader,
    publishers: _Publishers,
    counts: Counter[str],
    rate: float | None,
    stop: threading.Event,
) -> None:
    origin: tuple[int, float] | None = None  # (log time [ns], monotonic [s]) of the 1st message
    for message in reader.messages():
        if stop.is_set():
            return
        publisher, waited_s = publishers.get(message)
        if rate is not None:
            if origin is None:
                origin = (message.log_time_ns, time.monotonic())
            elif waited_s > 0:  # waiting for a subscriber is no part of the recorded pace
                origin = (origin[0], origin[1] + waited_s)
            target = origin[1] + max(0, message.log_time_ns - origin[0]) / 1e9 / rate
            delay = target - time.monotonic()
            if delay > 0 and stop.wait(delay):
                return
        if publisher is not None:
            publisher.put_bytes(message.payload)
            counts[message.topic] += 1
