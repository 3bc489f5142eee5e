"""``wz record``: record raw bus payloads into an MCAP file (see :mod:`wz_cli.recording`).

Every key expression gets a FIFO raw subscription: when the recorder falls behind, Zenoh is
held back rather than samples dropped. Recording stops after ``--duration``, after
``--max-messages``, or on SIGINT/SIGTERM; samples already received are written, then the file
is finished (summary, index, footer). Chunks are flushed every second, so even a recorder
killed outright leaves a file ``wz replay`` can read up to its last second.
"""

from __future__ import annotations

import logging
import queue
import socket
import threading
import time
from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path

import zenoh

from wz_cli.common import CliError, emit, format_table
from wz_cli.recording import RecordingWriter, recording_metadata
from wz_shared.bus import Bus, Subscription

log = logging.getLogger(__name__)

#: How often the file is brought up to date on disk [s].
FLUSH_PERIOD_S = 1.0
#: Samples handed from the subscriptions to the writer, at most (then back-pressure).
HANDOFF_CAPACITY = 1024

_Sample = tuple[int, str, bytes]  # (receive time [ns], key, payload)


def _key_expr(text: str) -> zenoh.KeyExpr:
    try:
        return zenoh.KeyExpr(text)
    except zenoh.ZError as exc:
        raise CliError(f"{text!r} is not a valid key expression: {exc}") from exc


def distinct_key_exprs(texts: Sequence[str]) -> list[str]:
    """Key expressions with those included in another dropped (each sample recorded once).

    Two that only overlap (``wz/a/*`` and ``wz/*/b``) would record a sample twice: refused.
    """
    kept: list[zenoh.KeyExpr] = []
    for expr in map(_key_expr, texts):
        if not any(other.includes(expr) for other in kept):
            kept = [other for other in kept if not expr.includes(other)] + [expr]
    for i, a in enumerate(kept):
        for b in kept[i + 1 :]:
            if a.intersects(b):
                raise CliError(
                    f"key expressions {a} and {b} overlap: samples on both would be recorded twice"
                )
    return [str(expr) for expr in kept]


def _pump(subscription: Subscription[bytes], handoff: queue.Queue[_Sample | None]) -> None:
    """Move samples from one subscription to the writer, stamped with their receive time."""
    while (received := subscription.recv_with_key(None)) is not None:
        handoff.put((time.time_ns(), received.key, received.value))
    handoff.put(None)  # this subscription is closed and drained


def run_record(
    bus: Bus,
    out_path: Path,
    key_exprs: Sequence[str],
    *,
    duration_s: float | None,
    max_messages: int | None,
    overwrite: bool,
    stop: threading.Event,
    connect: Sequence[str],
) -> int:
    """Record until the duration, the count or ``stop``; write the summary; return 0."""
    exprs = distinct_key_exprs(key_exprs)
    try:
        stream = out_path.open("wb" if overwrite else "xb")
    except FileExistsError as exc:
        raise CliError(f"{out_path} exists: choose another name or pass --overwrite") from exc
    except OSError as exc:
        raise CliError(f"cannot write {out_path}: {exc}") from exc
    started = datetime.now(UTC)
    with stream:
        writer = RecordingWriter(
            stream,
            metadata=recording_metadata(
                {
                    "key_exprs": exprs,
                    "started_utc": started.isoformat(),
                    "host": socket.gethostname(),
                    "connect": list(connect),
                    "recorder": "wz record",
                }
            ),
        )
        handoff: queue.Queue[_Sample | None] = queue.Queue(maxsize=HANDOFF_CAPACITY)
        pumps = [
            threading.Thread(
                target=_pump,
                args=(bus.subscribe_raw(expr, mode="fifo"), handoff),
                name=f"record {expr}",
                daemon=True,
            )
            for expr in exprs
        ]
        for pump in pumps:
            pump.start()
        log.info("recording %s into %s", " ".join(exprs), out_path)
        begin = time.monotonic()
        deadline = None if duration_s is None else begin + duration_s
        last_flush = begin
        last_log_time_ns = 0
        open_pumps = len(pumps)
        closing = False
        while open_pumps:
            if not closing and (
                stop.is_set()
                or (deadline is not None and time.monotonic() >= deadline)
                or (max_messages is not None and writer.total >= max_messages)
            ):
                # No new samples from here on; what is queued is still written.
                closing = True
                bus.close()
            try:
                item = handoff.get(timeout=0.1)
            except queue.Empty:
                pass
            else:
                if item is None:
                    open_pumps -= 1
                elif max_messages is None or writer.total < max_messages:
                    log_time_ns, key, payload = item
                    last_log_time_ns = max(last_log_time_ns, log_time_ns)  # never backwards
                    writer.add(key, payload, last_log_time_ns)
            if time.monotonic() - last_flush >= FLUSH_PERIOD_S:
                writer.flush()
                last_flush = time.monotonic()
        writer.finish()
        elapsed_s = time.monotonic() - begin
    for line in _summary(writer, out_path, elapsed_s):
        emit(line)
    return 0


def _summary(writer: RecordingWriter, out_path: Path, elapsed_s: float) -> list[str]:
    size = out_path.stat().st_size
    lines = [
        f"recorded {writer.total} message(s) on {len(writer.counts)} key(s) in {elapsed_s:.1f} s "
        f"into {out_path} ({size} bytes)"
    ]
    if writer.counts:
        invalid: dict[str, int] = {}
        for (key, _reason), n in writer.invalid.items():
            invalid[key] = invalid.get(key, 0) + n
        rows = [(key, str(n), str(invalid.get(key, 0))) for key, n in sorted(writer.counts.items())]
        lines.extend(format_table(("KEY", "MESSAGES", "INVALID"), rows))
    return lines
