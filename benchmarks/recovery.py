"""Recovery from a crashed service: ``kill -9`` of each service of ``wz up`` in turn.

The real stack runs as ``wz up`` does it (a subprocess: the router, the simulator with its SUMO
work zone and sensors, both detectors, the fusion tracker, the alert service and the gateway,
each its own process on real Zenoh; the gateway on a fresh SQLite database, dev mode, a free
port; ``--seed 3``, status messages every 0.5 s). Once the gateway serves fused tracks fed by
both sensors, each service in turn gets SIGKILL (its pid from the supervisor's ``started <name>
(pid N)`` line) while the pipeline is steady (every service running, the gateway's newest track
batch fresh and fed by both sensors) and the service's warm standby is ready, as they are from
about half a minute after ``wz up`` (see :mod:`wz_cli.supervisor`). Then, from the kill, with
one wall clock:

- **restart**: the supervisor's ``started <name> (pid M), restart #k`` line (its own log
  timestamp): the crash noticed, the backoff (0.5 s for a first crash) waited, the process
  started;
- **status**: the first ``wz/<site>/status/<name>`` message of pid M (received here) whose state
  is ``running`` and that shows data going through it (messages received, or for the simulator
  published, in its last period);
- **pipeline**: the first time ``GET /v1/tracks/live`` of the gateway (polled every 0.1 s)
  answers with a batch the gateway received after the restart holding a track that a sensor
  updated within the tracker's sources window (0.25 s: fresh detections, not coasting); after a
  detector's kill, a track updated by that detector's sensor; after the gateway's, the new
  gateway has stored it and serves it;
- **alert service** (its kill only): the first ``wz/<site>/devices/state`` message after the
  restart (the node publishes one for the first track batch it evaluates);
- **recovered** = the latest of status, pipeline (and devices): the service is back and data
  flows through it to the gateway again.

Around the gateway's kill, what the gateway stored is read from its SQLite file (read-only):
every track point, track id and alert id stored before the kill must still be there after its
restart (``lost`` lists any that are not).

A service killed again is killed no sooner than ``BACKOFF_RESET_S`` after its restart, so that
every restart is a first crash's (the supervisor's backoff doubles for a child that crashes
again within 30 s of its start). Traffic sets a floor under **pipeline** for the detectors: a
detector's sensor shows in the tracks again only while a vehicle is within its range, so kills
wait for a steady state with tracks from both sensors.

:func:`run` (``python -m benchmarks.run --only recovery``) kills every service in three rounds,
then once more each with its standby killed first (the supervisor then restarts it as a new
interpreter, as without standbys).
"""

from __future__ import annotations

import json
import logging
import os
import re
import signal
import sqlite3
import statistics
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import httpx

from benchmarks.common import ROOT, free_port
from wz_shared.bus import Bus
from wz_shared.messages import RoadsideDeviceState, ServiceState, ServiceStatus
from wz_shared.settings import BusSettings
from wz_shared.site import DEFAULT_SITE_PATH, load_site

log = logging.getLogger(__name__)

#: The services of ``wz up``, in the order they are killed.
SERVICES = (
    "simulator",
    "lidar-detector",
    "camera-detector",
    "fusion-tracker",
    "alert-service",
    "gateway",
)
#: The sensor whose detections each detector produces (in the site file).
SENSOR_OF = {"lidar-detector": "lidar-mast", "camera-detector": "camera-mast"}
#: What the deployment issue asks for: the pipeline back within this long [s].
TARGET_S = 5.0
#: The supervisor's backoff starts again at 0.5 s for a child that ran this long [s].
BACKOFF_RESET_S = 30.0
SEED = 3
STATUS_PERIOD_S = 0.5
POLL_PERIOD_S = 0.1
#: Longest wait for one recovery; longer is recorded as a failure [s].
RECOVERY_TIMEOUT_S = 60.0
#: Longest wait for the stack to come up, or to be steady before a kill [s].
READY_TIMEOUT_S = 240.0
STEADY_TIMEOUT_S = 90.0
#: Longest wait for the gateway to store a first alert, before its kill [s].
ALERT_TIMEOUT_S = 180.0
#: How fresh the gateway's newest batch must be to count as the pipeline flowing [s].
FRESH_S = 0.5

_STARTED = re.compile(
    r"^started (?P<name>\S+) \(pid (?P<pid>\d+)\)(?P<standby> from its warm standby)?"
)
_STANDBY_STARTED = re.compile(r"^standby of (?P<name>\S+) \(pid (?P<pid>\d+)\) importing")
_STANDBY_READY = re.compile(r"^standby of (?P<name>\S+) \(pid (?P<pid>\d+)\) ready")
_STANDBY_GONE = re.compile(r"^the standby of (?P<name>\S+) \(pid (?P<pid>\d+)\) ")
_EXITED = re.compile(
    r"^(?P<name>\S+) \(pid (?P<pid>\d+)\) (?P<how>.+?) after [\d.]+ s; "
    r"restarting in (?P<delay>[\d.]+) s"
)


@dataclass(frozen=True)
class SupervisorEvent:
    """One line of the supervisor's own log: a child started, or a child exited."""

    ts: float  # the supervisor's wall clock [s since the epoch]
    kind: str  # "started", "exited", "standby_started", "standby_ready" or "standby_gone"
    name: str
    pid: int
    how: str = ""  # "killed by SIGKILL (signal 9)" ...
    delay_s: float = 0.0  # the backoff it announced
    standby: bool = False  # started from its warm standby


@dataclass
class Recovery:
    """One kill and what followed, in seconds after the SIGKILL."""

    service: str
    killed_pid: int
    new_pid: int
    exit_seen: str  # how the supervisor described the exit
    backoff_s: float  # the delay it announced
    from_standby: bool  # the new process was the service's warm standby
    restart_s: float
    status_s: float | None
    pipeline_s: float | None
    devices_s: float | None  # alert service only
    batch_stamp: float | None  # the stamp of the batch that showed the pipeline back
    batch_tracks: int

    @property
    def recovered_s(self) -> float | None:
        parts = [self.status_s, self.pipeline_s]
        if self.service == "alert-service":
            parts.append(self.devices_s)
        return None if any(p is None for p in parts) else max(p for p in parts if p is not None)

    def as_dict(self) -> dict[str, Any]:
        return {**asdict(self), "recovered_s": self.recovered_s}


@dataclass
class Stored:
    """What the gateway's database holds."""

    track_points: int
    track_ids: set[int] = field(default_factory=set)
    alert_ids: set[str] = field(default_factory=set)

    def missing_from(self, later: Stored) -> dict[str, Any]:
        """What this holds that ``later`` lost (empty when nothing was lost)."""
        lost: dict[str, Any] = {}
        if later.track_points < self.track_points:
            lost["track_points"] = self.track_points - later.track_points
        if self.track_ids - later.track_ids:
            lost["track_ids"] = sorted(self.track_ids - later.track_ids)
        if self.alert_ids - later.alert_ids:
            lost["alert_ids"] = sorted(self.alert_ids - later.alert_ids)
        return lost


class Stack:
    """``wz up`` as a subprocess, watched on the bus, through the gateway's API and its log.

    Use as a context manager; ``work_dir`` gets the supervisor's log (``up.log``), the
    simulator's work folder and the gateway's database.
    """

    def __init__(self, work_dir: Path, *, seed: int = SEED) -> None:
        self.work_dir = work_dir
        self.seed = seed
        self.site = load_site(DEFAULT_SITE_PATH)
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.http_port = free_port()
        self.gateway_dir = work_dir / "gateway"
        self.log_path = work_dir / "up.log"
        self._lock = threading.Lock()
        self._events: list[SupervisorEvent] = []
        self._supervisor_lines: list[str] = []
        self._statuses: list[tuple[float, ServiceStatus]] = []
        self._devices: list[float] = []
        self._process: subprocess.Popen[bytes] | None = None
        self._reader: threading.Thread | None = None
        self._bus: Bus | None = None
        self._http = httpx.Client(base_url=f"http://127.0.0.1:{self.http_port}", timeout=2.0)
        #: Each service's latest start: (wall clock, pid).
        self.started: dict[str, tuple[float, int]] = {}

    # --- life cycle ---------------------------------------------------------------------------

    def __enter__(self) -> Stack:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def start(self) -> None:
        env = {k: v for k, v in os.environ.items() if not k.startswith("WZ_")}
        env.update(
            WZ_LOG_FORMAT="json",
            PYTHONUNBUFFERED="1",
            WZ_STATUS_PERIOD_S=str(STATUS_PERIOD_S),
            WZ_SIM_WORK_DIR=str(self.work_dir / "sim"),
            WZ_GATEWAY_PORT=str(self.http_port),
            WZ_GATEWAY_DATA_DIR=str(self.gateway_dir),
        )
        self._process = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "wz_cli.main",
                "up",
                "--listen",
                self.endpoint,
                "--seed",
                str(self.seed),
            ],
            cwd=ROOT,
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
        )
        self._reader = threading.Thread(target=self._read_log, name="up-log", daemon=True)
        self._reader.start()
        settings = BusSettings(
            mode="client",
            connect_endpoints=[self.endpoint],
            listen_endpoints=[],
            multicast_scouting=False,
        )
        deadline = time.monotonic() + 30.0
        while True:  # the router listens once `wz up` has started it
            try:
                self._bus = Bus.open(settings, site=self.site.site_id, service="recovery-bench")
                break
            except Exception:
                if time.monotonic() > deadline or self._process.poll() is not None:
                    raise
                time.sleep(0.2)
        self._bus.on(self._bus.keys.status_all, ServiceStatus, self._on_status)
        self._bus.on(self._bus.keys.devices_state, RoadsideDeviceState, self._on_devices)

    def close(self) -> int | None:
        """SIGINT to ``wz up`` (it stops every child); its exit code, None if it was gone."""
        code = None
        if self._bus is not None:
            self._bus.close()
            self._bus = None
        self._http.close()
        process = self._process
        if process is not None:
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
                try:
                    code = process.wait(40.0)
                except subprocess.TimeoutExpired:
                    process.kill()
                    process.wait()
            else:
                code = None
        if self._reader is not None:
            self._reader.join(5.0)
        return code

    def _read_log(self) -> None:
        assert self._process is not None and self._process.stdout is not None
        with self.log_path.open("wb") as out:
            for raw in iter(self._process.stdout.readline, b""):
                out.write(raw)
                out.flush()
                if raw.startswith(b"{"):  # the supervisor's own lines (children's: "name | ...")
                    self._on_supervisor_line(raw)

    def _on_supervisor_line(self, raw: bytes) -> None:
        try:
            entry = json.loads(raw)
        except ValueError:
            return
        message = str(entry.get("msg", ""))
        ts = float(entry.get("ts", time.time()))
        with self._lock:
            self._supervisor_lines.append(message)
        event = None
        if match := _STARTED.match(message):
            event = SupervisorEvent(
                ts,
                "started",
                match["name"],
                int(match["pid"]),
                standby=match["standby"] is not None,
            )
        elif match := _STANDBY_STARTED.match(message):
            event = SupervisorEvent(ts, "standby_started", match["name"], int(match["pid"]))
        elif match := _STANDBY_READY.match(message):
            event = SupervisorEvent(ts, "standby_ready", match["name"], int(match["pid"]))
        elif match := _STANDBY_GONE.match(message):
            event = SupervisorEvent(ts, "standby_gone", match["name"], int(match["pid"]))
        elif match := _EXITED.match(message):
            event = SupervisorEvent(
                ts, "exited", match["name"], int(match["pid"]), match["how"], float(match["delay"])
            )
        if event is not None:
            with self._lock:
                self._events.append(event)
                if event.kind == "started":
                    self.started[event.name] = (event.ts, event.pid)

    def _on_status(self, _key: str, status: ServiceStatus) -> None:
        with self._lock:
            self._statuses.append((time.time(), status))

    def _on_devices(self, _key: str, _state: RoadsideDeviceState) -> None:
        with self._lock:
            self._devices.append(time.time())

    def check_alive(self) -> None:
        if self._process is None or self._process.poll() is not None:
            raise RuntimeError(f"`wz up` exited; its log: {self.log_tail()}")

    def log_tail(self, chars: int = 4000) -> str:
        """The supervisor's last lines, then the end of the whole log."""
        with self._lock:
            own = "\n".join(self._supervisor_lines[-30:])
        try:
            whole = self.log_path.read_text(errors="replace")[-chars:]
        except OSError:
            whole = ""
        return f"supervisor:\n{own}\n...\n{whole}"

    # --- what the stack shows -----------------------------------------------------------------

    def live(self) -> tuple[float, dict[str, Any]] | None:
        """``(received_at, batch)`` of the gateway's newest track batch; None while it does
        not answer or has none."""
        try:
            response = self._http.get("/v1/tracks/live")
        except httpx.TransportError:
            return None
        now = time.time()
        if response.status_code != 200:
            return None
        body: dict[str, Any] = response.json()
        if body.get("stamp") is None or body.get("age_s") is None:
            return None
        return now - float(body["age_s"]), body

    def _flowing(self, status: ServiceStatus) -> bool:
        if status.state != ServiceState.RUNNING:
            return False
        rates = status.published_hz if status.service == "simulator" else status.received_hz
        return any(rate > 0 for rate in rates.values())

    def status_since(self, service: str, pid: int, since: float) -> float | None:
        """When the first flowing, running status of ``pid`` came after ``since``; or None."""
        with self._lock:
            for received, status in self._statuses:
                if (
                    received >= since
                    and status.service == service
                    and status.pid == pid
                    and self._flowing(status)
                ):
                    return received
        return None

    def devices_since(self, since: float) -> float | None:
        with self._lock:
            return next((t for t in self._devices if t >= since), None)

    def standby(self, service: str, *, ready: bool = True) -> int | None:
        """The pid of ``service``'s warm standby, if the supervisor has one (``ready``: ready)
        for its current process; None otherwise."""
        current = self.started.get(service)
        if current is None:
            return None
        kind = "standby_ready" if ready else "standby_started"
        with self._lock:
            found = [
                e.pid
                for e in self._events
                if e.kind == kind and e.name == service and e.ts >= current[0]
            ]
            # Gone, or woken (the service's process now): not a standby any more.
            gone = {
                e.pid
                for e in self._events
                if e.kind in ("standby_gone", "started") and e.name == service
            }
        found = [pid for pid in found if pid not in gone]
        return found[-1] if found else None

    def gave_up_standbys(self, service: str) -> bool:
        """Whether the supervisor restarts ``service`` without a standby from now on."""
        with self._lock:
            return any(e.kind == "standby_gone" and e.name == service for e in self._events)

    def steady(self, standby_of: str | None = None) -> bool:
        """Every service running (flowing) from its current pid within the last two status
        periods, ``standby_of`` (a service) with its warm standby ready, and the gateway's
        newest batch fresh with tracks from both sensors."""
        now = time.time()
        if standby_of is not None and self.standby(standby_of) is None:
            return False
        for service in SERVICES:
            current = self.started.get(service)
            if current is None:
                return False
            since = now - 2 * STATUS_PERIOD_S - 0.2
            with self._lock:
                recent = [s for t, s in self._statuses if t >= since and s.service == service]
            if not any(s.pid == current[1] and self._flowing(s) for s in recent):
                return False
        live = self.live()
        if live is None or live[0] < time.time() - FRESH_S:
            return False
        sources = {source for track in live[1]["tracks"] for source in track["sources"]}
        return set(SENSOR_OF.values()) <= sources

    def wait(self, condition: Callable[[], bool], timeout_s: float, what: str) -> None:
        deadline = time.monotonic() + timeout_s
        while not condition():
            self.check_alive()
            if time.monotonic() > deadline:
                raise TimeoutError(f"no {what} within {timeout_s:.0f} s; log: {self.log_tail()}")
            time.sleep(POLL_PERIOD_S)

    def wait_steady(
        self, timeout_s: float = STEADY_TIMEOUT_S, *, standby_of: str | None = None
    ) -> None:
        self.wait(
            lambda: self.steady(standby_of),
            timeout_s,
            "steady pipeline (all running, fresh tracks from both sensors at the gateway"
            + (f", {standby_of}'s standby ready" if standby_of else "")
            + ")",
        )

    def drop_standby(self, service: str, timeout_s: float = STEADY_TIMEOUT_S) -> None:
        """Make the supervisor restart ``service`` the plain way (a new interpreter) from now
        on: SIGKILL its standby once it has started one (ready or not), and wait until it has
        noticed; nothing to do once it has given up on them."""
        self.wait(
            lambda: (
                self.standby(service, ready=False) is not None or self.gave_up_standbys(service)
            ),
            timeout_s,
            f"{service}'s standby",
        )
        pid = self.standby(service, ready=False)
        if pid is None:
            return
        os.kill(pid, signal.SIGKILL)

        def noticed() -> bool:
            with self._lock:
                return any(e.kind == "standby_gone" and e.pid == pid for e in self._events)

        self.wait(noticed, timeout_s, f"the supervisor noticing the end of {service}'s standby")

    def wait_backoff_reset(self, service: str) -> None:
        """If ``service`` crashed before, wait until its current process has run
        ``BACKOFF_RESET_S``: its next crash is then a first one (0.5 s backoff), not a crash
        loop's."""
        started_at, _ = self.started[service]
        with self._lock:
            crashed_before = any(e.kind == "exited" and e.name == service for e in self._events)
        if crashed_before:
            time.sleep(max(0.0, BACKOFF_RESET_S - (time.time() - started_at)))

    def stored(self) -> Stored:
        """What the gateway's SQLite database holds now (read-only)."""
        path = self.gateway_dir / "gateway.sqlite3"
        if not path.is_file():
            raise FileNotFoundError(f"no gateway database at {path}")
        connection = sqlite3.connect(f"file:{path}?mode=ro", uri=True, timeout=10.0)
        try:
            (points,) = connection.execute("SELECT count(*) FROM track_points").fetchone()
            track_ids = {
                row[0] for row in connection.execute("SELECT DISTINCT track_id FROM track_points")
            }
            alert_ids = {row[0] for row in connection.execute("SELECT alert_id FROM alerts")}
        finally:
            connection.close()
        return Stored(int(points), track_ids, alert_ids)

    # --- a kill -------------------------------------------------------------------------------

    def kill(self, service: str, timeout_s: float = RECOVERY_TIMEOUT_S) -> Recovery:
        """SIGKILL ``service``'s process now; measure what follows (see the module)."""
        _, old_pid = self.started[service]
        killed_at = time.time()
        os.kill(old_pid, signal.SIGKILL)
        deadline = time.monotonic() + timeout_s

        def restarted() -> SupervisorEvent | None:
            with self._lock:
                return next(
                    (
                        e
                        for e in self._events
                        if e.kind == "started"
                        and e.name == service
                        and e.pid != old_pid
                        and e.ts >= killed_at - 0.01
                    ),
                    None,
                )

        while (start := restarted()) is None:
            self.check_alive()
            if time.monotonic() > deadline:
                raise TimeoutError(f"{service} was not restarted within {timeout_s:.0f} s")
            time.sleep(0.02)
        with self._lock:
            exit_event = next(
                (e for e in self._events if e.kind == "exited" and e.pid == old_pid), None
            )
        restart_at = start.ts
        sensor = SENSOR_OF.get(service)
        pipeline_at: float | None = None
        batch_stamp: float | None = None
        batch_tracks = 0
        while time.monotonic() < deadline:
            self.check_alive()
            status_at = self.status_since(service, start.pid, restart_at)
            devices_at = self.devices_since(restart_at) if service == "alert-service" else 0.0
            if pipeline_at is None and (live := self.live()) is not None:
                received_at, batch = live
                fresh = [
                    t
                    for t in batch["tracks"]
                    if t["sources"] and (sensor is None or sensor in t["sources"])
                ]
                if received_at >= restart_at and fresh:
                    pipeline_at = time.time()
                    batch_stamp, batch_tracks = float(batch["stamp"]), len(batch["tracks"])
            if pipeline_at is not None and status_at is not None and devices_at is not None:
                break
            time.sleep(POLL_PERIOD_S)
        status_at = self.status_since(service, start.pid, restart_at)

        def since_kill(t: float | None) -> float | None:
            return None if t is None else round(t - killed_at, 3)

        recovery = Recovery(
            service=service,
            killed_pid=old_pid,
            new_pid=start.pid,
            exit_seen=exit_event.how if exit_event else "",
            backoff_s=exit_event.delay_s if exit_event else float("nan"),
            from_standby=start.standby,
            restart_s=round(restart_at - killed_at, 3),
            status_s=since_kill(status_at),
            pipeline_s=since_kill(pipeline_at),
            devices_s=(
                since_kill(self.devices_since(restart_at)) if service == "alert-service" else None
            ),
            batch_stamp=batch_stamp,
            batch_tracks=batch_tracks,
        )
        log.info("recovery: %s", recovery.as_dict())
        return recovery


def one_round(stack: Stack, *, plain: bool = False) -> tuple[list[Recovery], dict[str, Any]]:
    """Kill every service once, in :data:`SERVICES` order, each when the pipeline is steady
    and its warm standby ready (``plain``: with its standby dropped first, so that it restarts
    as a new interpreter); the recoveries and the gateway's stored data before its kill and
    after its restart."""
    recoveries: list[Recovery] = []
    check: dict[str, Any] = {}
    for service in SERVICES:
        stack.wait_backoff_reset(service)
        stack.wait_steady(standby_of=None if plain else service)
        if plain:
            stack.drop_standby(service)
        if service == "gateway":
            # Something of each kind for the check to hold on: alerts come with traffic.
            stack.wait(
                lambda: bool(stack.stored().alert_ids),
                ALERT_TIMEOUT_S,
                "an alert stored by the gateway",
            )
            stack.wait_steady(standby_of=None if plain else service)
            before = stack.stored()
        recoveries.append(stack.kill(service))
        if service == "gateway":
            stack.wait_steady()  # the new gateway stores what the bus brings again
            after = stack.stored()
            check = {
                "before": {
                    "track_points": before.track_points,
                    "track_ids": len(before.track_ids),
                    "alert_ids": len(before.alert_ids),
                },
                "after": {
                    "track_points": after.track_points,
                    "track_ids": len(after.track_ids),
                    "alert_ids": len(after.alert_ids),
                },
                "lost": before.missing_from(after),
            }
    return recoveries, check


def _median(values: list[float | None]) -> float | None:
    present = [v for v in values if v is not None]
    return statistics.median(present) if present else None


def run(quick: bool) -> dict[str, Any]:
    """Three rounds (one quick) on one stack; per service the median of each time."""
    import tempfile

    logging.getLogger("httpx").setLevel(logging.WARNING)  # a line per poll otherwise
    rounds = 1 if quick else 3
    with tempfile.TemporaryDirectory(prefix="wz-recovery-") as tmp:
        work_dir = Path(tmp)
        started = time.monotonic()
        with Stack(work_dir) as stack:
            stack.wait_steady(READY_TIMEOUT_S)
            ready_s = time.monotonic() - started
            log.info("recovery: the stack is steady after %.1f s", ready_s)
            all_rounds: list[list[dict[str, Any]]] = []
            checks: list[dict[str, Any]] = []
            for index in range(rounds):
                log.info("recovery: round %d of %d", index + 1, rounds)
                recoveries, check = one_round(stack)
                all_rounds.append([r.as_dict() for r in recoveries])
                checks.append(check)
            log.info("recovery: a round without the standbys")
            plain, plain_check = one_round(stack, plain=True)
            exit_code = stack.close()
    services: dict[str, Any] = {}
    for position, service in enumerate(SERVICES):
        samples = [round_[position] for round_ in all_rounds]
        services[service] = {
            name: {
                "median": _median([s[name] for s in samples]),
                "values": [s[name] for s in samples],
            }
            for name in ("restart_s", "status_s", "pipeline_s", "devices_s", "recovered_s")
        }
        services[service]["backoff_s"] = [s["backoff_s"] for s in samples]
        services[service]["exit_seen"] = sorted({s["exit_seen"] for s in samples})
        services[service]["from_standby"] = [s["from_standby"] for s in samples]
    worst = [s["recovered_s"] for round_ in all_rounds for s in round_]
    return {
        "rounds": rounds,
        "seed": SEED,
        "status_period_s": STATUS_PERIOD_S,
        "poll_period_s": POLL_PERIOD_S,
        "target_s": TARGET_S,
        "ready_s": round(ready_s, 1),
        "services": services,
        "all_within_target": all(v is not None and v <= TARGET_S for v in worst),
        "gateway_lost": [c.get("lost", {}) for c in [*checks, plain_check]],
        "gateway_stored": [*checks, plain_check],
        "raw": all_rounds,
        "without_standby": [r.as_dict() for r in plain],
        "wz_up_exit_code": exit_code,
    }


def main(argv: list[str] | None = None) -> int:
    """``python -m benchmarks.recovery [--quick]``: the measurement alone, a table on stdout
    (``python -m benchmarks.run --only recovery`` records it in BENCHMARKS.md)."""
    import argparse

    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.recovery",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--quick", action="store_true", help="one round instead of three")
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.INFO, format="%(asctime)s %(levelname)s %(message)s", stream=sys.stderr
    )
    result = run(args.quick)
    header = f"{'service':<16} {'restart':>8} {'status':>8} {'pipeline':>9} {'recovered':>10}"
    lines = [f"median of {result['rounds']} round(s), seconds after the SIGKILL", header]
    for service, times in result["services"].items():
        cells = [
            times[name]["median"] for name in ("restart_s", "status_s", "pipeline_s", "recovered_s")
        ]
        lines.append(
            f"{service:<16} "
            + " ".join(
                f"{'-' if v is None else f'{v:.2f}':>{w}}"
                for v, w in zip(cells, (8, 8, 9, 10), strict=True)
            )
        )
    lines.append(f"gateway lost: {result['gateway_lost']}")
    sys.stdout.write("\n".join(lines) + "\n")
    return 0 if result["all_within_target"] and not any(result["gateway_lost"]) else 1


if __name__ == "__main__":
    sys.exit(main())
