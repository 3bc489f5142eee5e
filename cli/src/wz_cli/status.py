"""``wz status``: which services of a site are alive, and how their traffic looks.

Alive means the service's liveliness token ``wz/<site>/status/<service>`` is declared now (it
disappears when the process exits or loses the bus). The rest comes from the
:class:`ServiceStatus` each service publishes on that key every second or so: pid, uptime,
message rates per key, invalid and dropped counts.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from typing import Any

from wz_cli.common import format_duration, format_table
from wz_shared.bus import Bus
from wz_shared.keys import Keys
from wz_shared.messages import ServiceStatus


@dataclass(frozen=True)
class ServiceView:
    """What is known about one service: liveliness, and its newest status message if any."""

    name: str
    alive: bool
    status: ServiceStatus | None
    #: Seconds between receiving ``status`` and the end of collection.
    status_age_s: float | None


def _name(key: str) -> str:
    return key.rsplit("/", 1)[-1]


def collect(bus: Bus, site: str, timeout_s: float) -> list[ServiceView]:
    """Ask who is alive at ``site`` and listen to status messages for up to ``timeout_s``.

    Returns early once every alive service has reported.
    """
    keys = Keys(site)
    deadline = time.monotonic() + timeout_s
    statuses = bus.subscribe(keys.status_all, ServiceStatus, mode="fifo", capacity=1024)
    alive = {_name(key) for key in bus.alive(keys.status_all, timeout_s=min(timeout_s, 2.0))}
    latest: dict[str, tuple[ServiceStatus, float]] = {}
    while not (alive and alive <= latest.keys()):
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            break
        received = statuses.recv_with_key(remaining)
        if received is None:
            break
        latest[_name(received.key)] = (received.value, time.monotonic())
    end = time.monotonic()
    return [
        ServiceView(
            name=name,
            alive=name in alive,
            status=latest[name][0] if name in latest else None,
            status_age_s=end - latest[name][1] if name in latest else None,
        )
        for name in sorted(alive | latest.keys())
    ]


def _per_key(status: ServiceStatus) -> list[tuple[str, str, str, str, str]]:
    """Rows (key, published Hz, received Hz, invalid, dropped) of one status message."""
    invalid: dict[str, dict[str, int]] = {}
    for key_reason, count in status.invalid_counts.items():
        key, _, reason = key_reason.partition("|")
        invalid.setdefault(key, {})[reason or "?"] = count
    keys = sorted(
        status.published_hz.keys()
        | status.received_hz.keys()
        | invalid.keys()
        | status.dropped_counts.keys()
    )

    def rate(rates: dict[str, float], key: str) -> str:
        return f"{rates[key]:.1f}" if key in rates else "-"

    rows = []
    for key in keys:
        reasons = invalid.get(key, {})
        total = sum(reasons.values())
        rows.append(
            (
                key,
                rate(status.published_hz, key),
                rate(status.received_hz, key),
                f"{total} ({', '.join(sorted(reasons))})" if total else "0",
                str(status.dropped_counts.get(key, 0)),
            )
        )
    return rows


def render_table(site: str, views: list[ServiceView]) -> list[str]:
    """The human-readable report: one block of rows per service, one row per key."""
    alive = sum(view.alive for view in views)
    lines = [f"site {site}: {alive} of {len(views)} service(s) alive"]
    if not views:
        lines.append("no service answered (is the stack running? `wz up`)")
        return lines
    header = (
        "SERVICE",
        "ALIVE",
        "STATE",
        "PID",
        "UPTIME",
        "KEY",
        "PUB HZ",
        "RECV HZ",
        "INVALID",
        "DROPPED",
    )
    rows: list[tuple[str, ...]] = []
    for view in views:
        status = view.status
        ident: tuple[str, ...] = (
            view.name,
            "yes" if view.alive else "no",
            status.state.value if status else "-",
            str(status.pid) if status else "-",
            format_duration(status.uptime_s) if status else "-",
        )
        per_key = _per_key(status) if status else []
        if not per_key:
            rows.append((*ident, "-", "-", "-", "-", "-"))
        for i, key_row in enumerate(per_key):
            rows.append((*(ident if i == 0 else ("",) * len(ident)), *key_row))
    lines.extend(format_table(header, rows))
    silent = [view.name for view in views if view.alive and view.status is None]
    if silent:
        lines.append(f"no status message received from: {', '.join(silent)}")
    return lines


def render_json(site: str, views: list[ServiceView]) -> str:
    """The report as one JSON object (for scripts)."""
    report: dict[str, Any] = {
        "site": site,
        "alive": sum(view.alive for view in views),
        "services": [
            {
                "service": view.name,
                "alive": view.alive,
                "status": view.status.model_dump(mode="json") if view.status else None,
                "status_age_s": (
                    None if view.status_age_s is None else round(view.status_age_s, 3)
                ),
            }
            for view in views
        ],
    }
    return json.dumps(report)
