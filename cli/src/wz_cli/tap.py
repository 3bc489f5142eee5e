"""``wz tap``: print live bus traffic, one line per message.

Each line is ``key  kind  summary``: ground truth as its stamp, vehicle count and first vehicle,
frames as their index, stamp and size, other messages as their JSON cut to the terminal width
(``--json``: the whole JSON), and payloads that fail validation as ``<invalid: reason: detail>``.

The tap listens through a large ring (latest-wins) rather than a FIFO: a slow terminal must
never hold back the publishers of a running stack. Messages it had to skip are counted and
reported when it stops.
"""

from __future__ import annotations

import logging
import threading
import time

from wz_cli.common import emit
from wz_shared import codec
from wz_shared.bus import Bus
from wz_shared.messages import (
    FRAME_MESSAGES,
    CameraFrameMeta,
    GroundTruth,
    LidarFrameMeta,
    Message,
)

log = logging.getLogger(__name__)

#: Samples the tap may fall behind by before it skips the oldest.
TAP_RING_CAPACITY = 10_000


def _clip(line: str, width: int | None) -> str:
    if width is None or len(line) <= width:
        return line
    return line[: max(width - 1, 0)] + "…"


def _truth_summary(truth: GroundTruth) -> str:
    text = f"stamp={truth.stamp:.3f} step={truth.step_index} vehicles={len(truth.vehicles)}"
    if truth.vehicles:
        first = truth.vehicles[0]
        text += f" first={first.vehicle_id} {first.speed_mps:.1f} m/s"
    return text


def _frame_summary(frame: codec.Frame[Message]) -> str:
    meta = frame.meta
    if isinstance(meta, LidarFrameMeta):
        return (
            f"#{meta.frame_index} stamp={meta.stamp:.3f} source={meta.source_id} "
            f"points={meta.num_points} ({meta.rows}x{meta.columns})"
        )
    if isinstance(meta, CameraFrameMeta):
        return (
            f"#{meta.frame_index} stamp={meta.stamp:.3f} source={meta.source_id} "
            f"{meta.width_px}x{meta.height_px} jpeg={len(frame.payload)} B"
        )
    return f"stamp={meta.stamp:.3f} payload={len(frame.payload)} B"


def _not_a_message(payload: bytes) -> codec.DecodeError:
    if len(payload) > codec.MAX_JSON_BYTES:
        return codec.DecodeError("oversize", f"{len(payload)} bytes is not a message")
    return codec.DecodeError("bad_json", f'{len(payload)} bytes: not JSON with a "kind" tag')


def describe(key: str, payload: bytes, *, full_json: bool = False, width: int | None = None) -> str:
    """One line for one payload: ``key  kind  summary`` (cut to ``width`` unless ``full_json``).

    Never raises for a bad payload: it is shown as ``<invalid: reason: detail>``.
    """
    kind = codec.peek_kind(payload)
    try:
        if payload[:4] == codec.FRAME_MAGIC:
            cls = FRAME_MESSAGES.get(kind or "")
            if cls is None:
                raise codec.DecodeError("wrong_kind", f"unknown frame kind {kind!r}")
            frame = codec.decode_frame(payload, cls)
            summary = (
                f"{frame.meta.model_dump_json()}  +{len(frame.payload)} B payload"
                if full_json
                else _frame_summary(frame)
            )
        elif kind is None:
            raise _not_a_message(payload)
        else:
            message = codec.decode_any_json(payload)
            if isinstance(message, GroundTruth) and not full_json:
                summary = _truth_summary(message)
            else:
                summary = payload.decode("utf-8")
    except codec.DecodeError as exc:
        summary = f"<invalid: {exc.reason}: {exc.detail}>"
    line = f"{key}  {kind or '?'}  {summary}"
    return line if full_json else _clip(line, width)


def run_tap(
    bus: Bus,
    key_expr: str,
    *,
    count: int | None,
    timeout_s: float | None,
    full_json: bool,
    width: int | None,
    stop: threading.Event,
) -> int:
    """Print messages on ``key_expr`` until ``count`` shown, ``timeout_s`` passed or ``stop``.

    Returns 1 when ``timeout_s`` ran out before ``count`` messages, else 0.
    """
    subscription = bus.subscribe_raw(key_expr, mode="ring", capacity=TAP_RING_CAPACITY)
    log.info("tapping %s", key_expr)
    deadline = None if timeout_s is None else time.monotonic() + timeout_s
    shown = 0
    timed_out = False
    while not stop.is_set() and (count is None or shown < count):
        wait_s = 0.2
        if deadline is not None:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                timed_out = True
                break
            wait_s = min(wait_s, remaining)
        received = subscription.recv_with_key(wait_s)
        if received is None:
            continue
        emit(describe(received.key, received.value, full_json=full_json, width=width))
        shown += 1
    skipped = bus.stats.dropped.get(key_expr, 0)
    if skipped:
        log.warning("the tap fell behind and skipped %d message(s) on %s", skipped, key_expr)
    if timed_out and count is not None:
        log.warning("only %d of %d message(s) within %.1f s", shown, count, timeout_s)
        return 1
    return 0
