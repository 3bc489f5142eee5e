"""``wz alerts``: the open alerts of a site, then each alert event as it comes, one line each.

It asks the alert service (the queryable ``wz/<site>/alerts/active``) for the open episodes and
prints them as ``open``, then prints every event published on ``wz/<site>/alerts/*``::

    12.300  start  speeding  warning  track 7  speeding: 65 mph where the limit is 55 mph (+10 mph)

(capture time [s], phase, type, severity, track or ``site``, description); ``--json`` prints
each alert's whole JSON instead. ``--active`` prints the open ones and stops.

Like ``wz tap``, it listens through a large ring rather than a FIFO: alerts are published with
blocking congestion control, so a slow terminal on a FIFO would hold back the alert service.
"""

from __future__ import annotations

import logging
import threading
import time

from wz_cli.common import emit
from wz_shared.bus import Bus
from wz_shared.messages import ActiveAlerts, Alert

log = logging.getLogger(__name__)

#: Alerts the command may fall behind by before it skips the oldest.
ALERTS_RING_CAPACITY = 10_000


def alert_line(alert: Alert, phase: str | None = None) -> str:
    """``stamp  phase  type  severity  subject  description`` for one alert."""
    subject = "site" if alert.track_id is None else f"track {alert.track_id}"
    return (
        f"{alert.stamp:.3f}  {phase or alert.phase}  {alert.alert_type.value}  "
        f"{alert.severity.value}  {subject}  {alert.description}"
    )


def _show(alert: Alert, full_json: bool, phase: str | None = None) -> None:
    emit(alert.model_dump_json() if full_json else alert_line(alert, phase))


def run_alerts(
    bus: Bus,
    *,
    active_only: bool,
    count: int | None,
    timeout_s: float | None,
    full_json: bool,
    stop: threading.Event,
) -> int:
    """Print the open alerts, then (unless ``active_only``) alert events until ``count`` shown,
    ``timeout_s`` passed or ``stop``.

    Returns 1 when no alert service answered with ``active_only``, or when ``timeout_s`` ran
    out before ``count`` events; else 0.
    """
    keys = bus.keys
    # Subscribe before asking, so no event falls between the answer and the subscription.
    events = None
    if not active_only:
        events = bus.subscribe(keys.alerts_all, Alert, mode="ring", capacity=ALERTS_RING_CAPACITY)
    answers = bus.query(keys.alerts_active, ActiveAlerts, timeout_s=2.0)
    if not answers:
        log.warning("no alert service answered on %s", keys.alerts_active)
    for answer in answers:
        for alert in answer.alerts:
            _show(alert, full_json, phase="open")
        devices = answer.devices
        if not full_json:
            log.info(
                "as of %.3f s: %d open, beacon %s, sign %r",
                answer.stamp,
                len(answer.alerts),
                "on" if devices.beacon_on else "off",
                devices.sign_text,
            )
    if events is None:
        return 0 if answers else 1
    log.info("watching %s", keys.alerts_all)
    deadline = None if timeout_s is None else time.monotonic() + timeout_s
    shown = 0
    while not stop.is_set() and (count is None or shown < count):
        wait_s = 0.2
        if deadline is not None:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                break
            wait_s = min(wait_s, remaining)
        event = events.recv(wait_s)
        if event is None:
            continue
        _show(event, full_json)
        shown += 1
    skipped = bus.stats.dropped.get(keys.alerts_all, 0)
    if skipped:
        log.warning("fell behind and skipped %d alert(s)", skipped)
    if count is not None and shown < count and deadline is not None and not stop.is_set():
        log.warning("only %d of %d alert(s) within %.1f s", shown, count, timeout_s)
        return 1
    return 0
