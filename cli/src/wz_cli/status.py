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

It also listens to the sensors' self-calibration (``wz/<site>/calibration/<sensor>``, the
:class:`SensorCalibration` each detector publishes for each of its sensors on a change of state
and every 5 s of sensor time) and shows one row per sensor: the site file's sensors when the
site is the one of ``WZ_SITE_FILE`` (or the default), and any other heard from. As for the
services, only what comes while listening counts: a sensor not heard from shows ``-``, with a
line saying why (its detector is not running, or nothing came in the time given); it waits
for the sensors whose detector is alive, up to the timeout. A knocked sensor (``bumped``) gets
a line too; neither changes the exit code (the detector already reports itself ``degraded``).

The command exits 1 when an expected service is anything but up.
"""

from __future__ import annotations

import json
import queue
import time
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wz_cli.common import format_duration, format_table
from wz_shared.bus import Bus
from wz_shared.health import waiting_reason
from wz_shared.keys import Keys
from wz_shared.messages import (
    CalibrationState,
    Message,
    SensorCalibration,
    ServiceState,
    ServiceStatus,
)

#: The service that publishes each kind of sensor's calibration (``wz up``'s names).
DETECTOR_OF_KIND = {
    "lidar": "lidar-detector",
    "camera": "camera-detector",
    "radar": "camera-detector",
}


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


@dataclass(frozen=True)
class SensorView:
    """What was heard of one sensor's self-calibration while listening."""

    sensor_id: str
    #: ``lidar``, ``camera`` or ``radar``: the message's, else the site file's.
    kind: str
    #: The newest message; None if none came.
    calibration: SensorCalibration | None
    #: Seconds between receiving ``calibration`` and the end of collection.
    age_s: float | None
    #: Whether the site file lists it.
    expected: bool = False
    #: Whether the service that publishes its calibration is alive on the bus.
    detector_alive: bool = False

    @property
    def detector(self) -> str:
        return DETECTOR_OF_KIND.get(self.kind, "its detector")


@dataclass(frozen=True)
class Survey:
    """Every service's view and every sensor's, from one collection."""

    services: list[ServiceView]
    sensors: list[SensorView]
    #: How long it listened [s].
    listened_s: float


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
    """The services of :func:`survey` (no sensor expected)."""
    return survey(bus, site, timeout_s, expected, notes).services


def survey(
    bus: Bus,
    site: str,
    timeout_s: float,
    expected: Iterable[str] = (),
    notes: dict[str, str] | None = None,
    sensors: Iterable[tuple[str, str]] = (),
) -> Survey:
    """Ask who is alive at ``site`` and listen to status and calibration messages for up to
    ``timeout_s``; one view per service alive, heard or ``expected``; ``notes``
    (:func:`health_notes`) go to the services that did not report; one view per sensor of
    ``sensors`` (``(sensor_id, kind)``, the site file's) or heard from.

    Returns early once every alive and expected service has reported, and every sensor of
    ``sensors`` whose detector is alive has sent its calibration.
    """
    wanted = set(expected)
    keys = Keys(site)
    started = time.monotonic()
    deadline = started + timeout_s
    arrivals: queue.Queue[tuple[str, Message, float]] = queue.Queue()

    def arrived(key: str, message: Message) -> None:  # Zenoh's thread
        arrivals.put((key, message, time.monotonic()))

    bus.on(keys.status_all, ServiceStatus, arrived)
    bus.on(keys.calibration_all, SensorCalibration, arrived)
    alive = {_name(key) for key in bus.alive(keys.status_all, timeout_s=min(timeout_s, 2.0))}
    site_sensors = dict(sensors)
    waited_sensors = {s for s, kind in site_sensors.items() if DETECTOR_OF_KIND.get(kind) in alive}
    latest: dict[str, tuple[ServiceStatus, float]] = {}
    calibrations: dict[str, tuple[SensorCalibration, float]] = {}
    while not (
        (alive or wanted)
        and alive | wanted <= latest.keys()
        and waited_sensors <= calibrations.keys()
    ):
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            break
        try:
            key, message, at = arrivals.get(timeout=remaining)
        except queue.Empty:
            break
        if isinstance(message, ServiceStatus):
            latest[_name(key)] = (message, at)
        elif isinstance(message, SensorCalibration):
            calibrations[_name(key)] = (message, at)
    end = time.monotonic()
    services = [
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
    heard_only = sorted(calibrations.keys() - site_sensors.keys())
    sensor_views = []
    for sensor_id in [*site_sensors, *heard_only]:
        heard, heard_at = calibrations.get(sensor_id) or (None, None)
        kind = heard.sensor_kind if heard is not None else site_sensors[sensor_id]
        sensor_views.append(
            SensorView(
                sensor_id=sensor_id,
                kind=kind,
                calibration=heard,
                age_s=None if heard_at is None else end - heard_at,
                expected=sensor_id in site_sensors,
                detector_alive=DETECTOR_OF_KIND.get(kind) in alive,
            )
        )
    return Survey(services, sensor_views, end - started)


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


def _signed(value: float, digits: int) -> str:
    return f"{value:+.{digits}f}"


def calibration_rows(sensors: list[SensorView]) -> list[tuple[str, ...]]:
    """One row per sensor: sensor, kind, state, the learned yaw, pitch and roll corrections
    [deg], clock offset [ms], samples, how long in that state (``-`` where nothing came)."""
    rows: list[tuple[str, ...]] = []
    for view in sensors:
        message = view.calibration
        if message is None:
            rows.append((view.sensor_id, view.kind, *("-",) * 7))
            continue
        correction = message.correction
        rows.append(
            (
                view.sensor_id,
                message.sensor_kind,
                message.state.value,
                _signed(correction.yaw_deg, 2),
                _signed(correction.pitch_deg, 2),
                _signed(correction.roll_deg, 2),
                _signed(message.clock_offset_s * 1000.0, 0),
                str(message.samples),
                format_duration(max(0.0, message.stamp - message.state_since_s)),
            )
        )
    return rows


def calibration_notes(sensors: list[SensorView], listened_s: float) -> list[str]:
    """One line per sensor not heard from (and why, as far as the bus tells) and per sensor
    knocked."""
    out = []
    for view in sensors:
        message = view.calibration
        if message is None:
            if view.detector_alive:
                out.append(
                    f"{view.sensor_id}: no calibration heard in {listened_s:.1f} s "
                    f"({view.detector} is alive; it sends one every 5 s of sensor time, or "
                    "none when it does not learn its pose)"
                )
            else:
                out.append(f"{view.sensor_id}: no calibration ({view.detector} is not running)")
        elif message.state == CalibrationState.BUMPED:
            since = format_duration(max(0.0, message.stamp - message.state_since_s))
            why = f" ({message.detail})" if message.detail else ""
            out.append(
                f"{view.sensor_id}: bumped {since} ago{why}: its pose is being learned again, "
                "its detections weigh less"
            )
    return out


def render_table(
    site: str,
    views: list[ServiceView],
    sensors: list[SensorView] | None = None,
    listened_s: float = 0.0,
) -> list[str]:
    """The human-readable report: one block of rows per service, one row per key; then, with
    ``sensors``, the CALIBRATION table, one row per sensor, and what is to be said of them
    (:func:`calibration_notes`, ``listened_s``: how long it listened)."""
    up = sum(view.health == "up" for view in views)
    lines = [f"site {site}: {up} of {len(views)} service(s) up"]
    if not views:
        lines.append("no service answered (is the stack running? `wz up`)")
    else:
        lines.extend(_services_table(views))
        lines.extend(problems(views))
    if sensors:
        lines.append("")
        lines.append("CALIBRATION")
        lines.extend(
            format_table(
                (
                    "SENSOR",
                    "KIND",
                    "STATE",
                    "DYAW DEG",
                    "DPITCH DEG",
                    "DROLL DEG",
                    "CLOCK MS",
                    "SAMPLES",
                    "SINCE",
                ),
                calibration_rows(sensors),
            )
        )
        lines.extend(calibration_notes(sensors, listened_s))
    return lines


def _services_table(views: list[ServiceView]) -> list[str]:
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
    return format_table(header, rows)


def render_json(
    site: str,
    views: list[ServiceView],
    sensors: list[SensorView] | None = None,
    listened_s: float | None = None,
) -> str:
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
        "calibration": [
            {
                "sensor": sensor.sensor_id,
                "kind": sensor.kind,
                "expected": sensor.expected,
                "detector_alive": sensor.detector_alive,
                "calibration": (
                    None
                    if sensor.calibration is None
                    else sensor.calibration.model_dump(mode="json")
                ),
                "age_s": None if sensor.age_s is None else round(sensor.age_s, 3),
            }
            for sensor in sensors or []
        ],
        "calibration_notes": calibration_notes(sensors or [], listened_s or 0.0),
    }
    return json.dumps(report)
