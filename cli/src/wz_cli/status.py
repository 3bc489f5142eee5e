"""``wz status``: is every service of a site up and working, and how its traffic looks.

Alive means the service's liveliness token ``wz/<site>/status/<service>`` is declared now (it
disappears when the process exits or loses the bus). The rest comes from the
:class:`ServiceStatus` each service publishes on that key every second or so: pid, uptime,
its loop's progress, message rates per key, invalid and dropped counts.

Each expected service (by default those ``wz up`` runs) gets a health:

- ``up``: its status came, and its loop goes round;
- ``stalled``: its status says its loop has not gone round for longer than its limit (the
  process is alive, its work is not);
- ``silent``: its token is there but no status came while listening (a stopped process, whose
  session the router has not yet given up);
- ``down``: neither token nor status (not running).

With ``--health-dir`` (``wz up``'s state folder), a service that is not up also shows what its
health file says: a service still waiting for its router writes why there
(:mod:`wz_shared.reach`: ``waiting for the bus: tcp/127.0.0.1:7447: connection refused``).

The command exits 1 when an expected service is anything but up.
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wz_cli.common import format_duration, format_table
from wz_shared.bus import Bus
from wz_shared.health import waiting_reason
from wz_shared.keys import Keys
from wz_shared.messages import ServiceState, ServiceStatus


@dataclass(frozen=True)
class ServiceView:
    """What is known about one service: liveliness, and its newest status message if any."""

    name: str
    alive: bool
    status: ServiceStatus | None
    #: Seconds between receiving ``status`` and the end of collection.
    status_age_s: float | None
    #: Whether ``wz status`` was told to expect it.
    expected: bool = False
    #: What its health file says while it is not working (``waiting for the bus: ...``).
    note: str | None = None

    @property
    def health(self) -> str:
        """``up``, ``stalled``, ``silent`` or ``down`` (see the module)."""
        if self.status is not None:
            return "stalled" if self.status.state == ServiceState.STALLED else "up"
        return "silent" if self.alive else "down"


def _name(key: str) -> str:
    return key.rsplit("/", 1)[-1]


def health_notes(folder: Path) -> dict[str, str]:
    """Service name -> what its health file says (``folder/<service>/health``), for the
    services whose file holds a reason (:func:`wz_shared.health.mark_waiting`)."""
    notes = {}
    for path in sorted(folder.glob("*/health")):
        reason = waiting_reason(path)
        if reason is not None:
            notes[path.parent.name] = reason
    return notes


def collect(
    bus: Bus,
    site: str,
    timeout_s: float,
    expected: Iterable[str] = (),
    notes: dict[str, str] | None = None,
) -> list[ServiceView]:
    """Ask who is alive at ``site`` and listen to status messages for up to ``timeout_s``;
    one view per service alive, heard or ``expected``; ``notes`` (:func:`health_notes`) go
    to the services that did not report.

    Returns early once every alive and expected service has reported.
    """
    wanted = set(expected)
    keys = Keys(site)
    deadline = time.monotonic() + timeout_s
    statuses = bus.subscribe(keys.status_all, ServiceStatus, mode="fifo", capacity=1024)
    alive = {_name(key) for key in bus.alive(keys.status_all, timeout_s=min(timeout_s, 2.0))}
    latest: dict[str, tuple[ServiceStatus, float]] = {}
    while not ((alive or wanted) and alive | wanted <= latest.keys()):
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
            expected=name in wanted,
            note=None if name in latest else (notes or {}).get(name),
        )
        for name in sorted(alive | latest.keys() | wanted)
    ]


def problems(views: list[ServiceView]) -> list[str]:
    """One line per expected service that is not up."""
    out = []
    for view in views:
        if not view.expected or view.health == "up":
            continue
        if view.health == "stalled" and view.status is not None:
            age = view.status.loop_age_s
            out.append(f"{view.name}: stalled (its loop has not gone round for {age:.1f} s)")
        elif view.health == "silent":
            out.append(f"{view.name}: silent (alive on the bus, but no status: stopped or hung)")
        elif view.note is not None:
            out.append(f"{view.name}: {view.health} ({view.note})")
        else:
            out.append(f"{view.name}: down (not running)")
    return out


def _by_reason(counts: dict[str, int]) -> dict[str, dict[str, int]]:
    """``"<key>|<reason>"`` -> count, as key -> reason -> count."""
    out: dict[str, dict[str, int]] = {}
    for key_reason, count in counts.items():
        key, _, reason = key_reason.partition("|")
        out.setdefault(key, {})[reason or "?"] = count
    return out


def _with_reasons(total: int, reasons: dict[str, int]) -> str:
    return f"{total} ({', '.join(sorted(reasons))})" if reasons else str(total)


def _per_key(status: ServiceStatus) -> list[tuple[str, str, str, str, str]]:
    """Rows (key, published Hz, received Hz, invalid, dropped) of one status message; the
    dropped column counts a ring's overwritten samples and those shed undecoded (with the
    shedding's reasons: ``stale``, ``superseded``)."""
    invalid = _by_reason(status.invalid_counts)
    shed = _by_reason(status.shed_counts)
    keys = sorted(
        status.published_hz.keys()
        | status.received_hz.keys()
        | invalid.keys()
        | status.dropped_counts.keys()
        | shed.keys()
    )

    def rate(rates: dict[str, float], key: str) -> str:
        return f"{rates[key]:.1f}" if key in rates else "-"

    rows = []
    for key in keys:
        reasons = invalid.get(key, {})
        shed_reasons = shed.get(key, {})
        dropped = status.dropped_counts.get(key, 0) + sum(shed_reasons.values())
        rows.append(
            (
                key,
                rate(status.published_hz, key),
                rate(status.received_hz, key),
                _with_reasons(sum(reasons.values()), reasons),
                _with_reasons(dropped, shed_reasons),
            )
        )
    return rows


def render_table(site: str, views: list[ServiceView]) -> list[str]:
    """The human-readable report: one block of rows per service, one row per key."""
    up = sum(view.health == "up" for view in views)
    lines = [f"site {site}: {up} of {len(views)} service(s) up"]
    if not views:
        lines.append("no service answered (is the stack running? `wz up`)")
        return lines
    header = (
        "SERVICE",
        "HEALTH",
        "LOOP AGE",
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
        loop_age = status.loop_age_s if status else None
        ident: tuple[str, ...] = (
            view.name,
            view.health,
            "-" if loop_age is None else f"{loop_age:.1f} s",
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
    lines.extend(problems(views))
    return lines


def render_json(site: str, views: list[ServiceView]) -> str:
    """The report as one JSON object (for scripts)."""
    report: dict[str, Any] = {
        "site": site,
        "alive": sum(view.alive for view in views),
        "ok": not problems(views),
        "problems": problems(views),
        "services": [
            {
                "service": view.name,
                "alive": view.alive,
                "expected": view.expected,
                "health": view.health,
                "note": view.note,
                "status": view.status.model_dump(mode="json") if view.status else None,
                "status_age_s": (
                    None if view.status_age_s is None else round(view.status_age_s, 3)
                ),
            }
            for view in views
        ],
    }
    return json.dumps(report)
