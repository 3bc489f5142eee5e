"""``wz up``: run the local stack, one process per service, and keep it running.

The router starts first; the services start once its port accepts connections. Each child's
stdout and stderr lines are re-emitted on the supervisor's stdout, prefixed with its name
(``simulator | {...}``). A child that exits while the stack is up (a crash, ``kill -9``) is
restarted after an exponential backoff: 0.5 s, doubling up to 30 s, back to 0.5 s once a run
has lasted 30 s. SIGINT or SIGTERM stops the stack: SIGTERM to every service, up to 5 s for them
to exit, then SIGKILL; then the router the same way.

Warm standbys. A service whose spec asks for it (``ServiceSpec.standby``: every service of the
stack) gets a standby process (:mod:`wz_cli.standby`) once its child has run
``STANDBY_AFTER_S``: the same command and environment, its module imported, waiting. A restart
then wakes the standby instead of starting a new interpreter, so it does not wait for the
imports (FastAPI and SQLAlchemy for the gateway, open3d and SUMO for the simulator: one to
three seconds of CPU each, twice that on two cores busy with the rest of the stack); the
restarted service is still a new process that runs its ``main()`` from the start. Standbys are
started one at a time, ``STANDBY_STAGGER_S`` apart, not to take the CPU from the running stack
all at once; a standby that exits by itself is not replaced (the service restarts the plain
way); they are stopped with the stack.

Stalled loops. Each service of a run with a state folder has a health file
(``WZ_HEALTH_FILE``, :mod:`wz_shared.health`) whose modification time is its loop's last
round. A child whose file is older than ``STALL_RESTART_S`` (its loop blocked while the process
lives: a hung call, a lock never released) is killed (SIGKILL: a blocked loop cannot honour
SIGTERM) and restarted like a crashed one, with the reason in the log. A child's stale file is
removed when it starts, and a child is not judged before its first file (start-up).

No child outlives the supervisor: on Linux each child (standbys too) asks the kernel for SIGTERM
when its parent dies (``PR_SET_PDEATHSIG``), so even ``kill -9`` of the supervisor stops the
stack. The signal is tied to the thread that started the child: children are started from the
main thread only.
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

from wz_cli.common import CliError, emit, port_accepts, tcp_address, wait_for_port
from wz_cli.stack import ROUTER, ServiceSpec, StackOptions
from wz_cli.standby import READY as STANDBY_READY

log = logging.getLogger(__name__)

#: How long the router may take to accept connections [s] (it opens in about 0.5 s).
ROUTER_READY_TIMEOUT_S = 15.0
#: How long children get between SIGTERM and SIGKILL on shutdown [s].
STOP_GRACE_S = 5.0
#: How often the supervisor looks at its children [s].
POLL_PERIOD_S = 0.1
#: A service gets its warm standby once its child has run this long [s]: after the stack's
#: start-up, whose imports already keep the cores busy.
STANDBY_AFTER_S = 20.0
#: At most one standby is started per this long [s].
STANDBY_STAGGER_S = 2.0
#: A child whose loop has not gone round for this long is killed and restarted [s]: twice
#: the services' own stall limit (5 s), so a loop that is only slow is not killed for it.
STALL_RESTART_S = 10.0

_PR_SET_PDEATHSIG = 1


@dataclass
class Backoff:
    """Delay before restarting a child that exited: doubles per crash, resets after a good run.

    The first restart waits ``initial_s``; each next one twice the previous, at most ``cap_s``.
    A run that lasted ``reset_after_s`` or more counts as healthy: the next delay is
    ``initial_s`` again.
    """

    initial_s: float = 0.5
    cap_s: float = 30.0
    reset_after_s: float = 30.0
    _next_s: float = field(default=-1.0, repr=False)

    def delay_after_exit(self, uptime_s: float) -> float:
        """The delay [s] before restarting a child that ran ``uptime_s`` seconds."""
        if self._next_s < 0 or uptime_s >= self.reset_after_s:
            self._next_s = self.initial_s
        delay = self._next_s
        self._next_s = min(self._next_s * 2.0, self.cap_s)
        return delay


def describe_exit(returncode: int) -> str:
    """``exited with code 1`` or ``killed by SIGKILL (signal 9)``."""
    if returncode < 0:
        try:
            name = signal.Signals(-returncode).name
        except ValueError:
            name = "an unknown signal"
        return f"killed by {name} (signal {-returncode})"
    return f"exited with code {returncode}"


def _die_with_parent_hook() -> Callable[[], None] | None:
    """A ``preexec_fn`` that makes the child get SIGTERM when the supervisor dies (Linux)."""
    if not sys.platform.startswith("linux"):
        return None
    # Resolved here, in the parent: the hook runs between fork and exec, where it should do as
    # little as possible (no imports, no library loading).
    prctl = ctypes.CDLL(None, use_errno=True).prctl
    parent_pid = os.getpid()

    def die_with_parent() -> None:
        prctl(_PR_SET_PDEATHSIG, signal.SIGTERM.value, 0, 0, 0)
        if os.getppid() != parent_pid:  # the parent died before prctl took effect
            os.kill(os.getpid(), signal.SIGTERM)

    return die_with_parent


class PrefixedOutput:
    """Re-emits children's lines on stdout as ``name | line``, names aligned."""

    def __init__(self, names: Sequence[str]) -> None:
        self.width = max((len(name) for name in names), default=0)

    def write(self, name: str, line: str) -> None:
        # When stdout is closed the lines have nowhere to go; the children run on.
        with contextlib.suppress(BrokenPipeError, ValueError):
            emit(f"{name:<{self.width}} | {line}")


class Child:
    """One supervised process: started, watched, restarted with backoff, stopped."""

    def __init__(
        self,
        spec: ServiceSpec,
        argv: list[str],
        env: dict[str, str],
        output: PrefixedOutput,
        backoff: Backoff | None = None,
    ) -> None:
        self.spec = spec
        self.name = spec.name
        self.argv = argv
        self.env = env
        self.output = output
        self.backoff = backoff or Backoff()
        self.process: subprocess.Popen[bytes] | None = None
        self.started_at = 0.0
        self.restart_at: float | None = None
        self.restarts = 0
        self._readers: list[threading.Thread] = []
        #: The warm standby (see the module), when the spec asks for one and it is up.
        self.spare: subprocess.Popen[bytes] | None = None
        self._spare_readers: list[threading.Thread] = []
        self._spare_failed = not spec.standby
        #: Set once the standby has imported its module (its reader saw the line).
        self.spare_ready = threading.Event()
        #: The child's health file (its loop's last round), when it has one.
        health = env.get("WZ_HEALTH_FILE")
        self.health_file = Path(health) if health else None
        self.stalls = 0

    @property
    def running(self) -> bool:
        return self.process is not None and self.process.poll() is None

    def _spawn(
        self, argv: list[str], stdin: int, *, standby: bool = False
    ) -> tuple[subprocess.Popen[bytes], list[threading.Thread]]:
        process = subprocess.Popen(
            argv,
            env=self.env,
            stdin=stdin,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            start_new_session=False,
            # Runs between fork and exec; it only calls prctl (resolved beforehand).
            preexec_fn=_die_with_parent_hook(),
        )
        assert process.stdout is not None and process.stderr is not None
        readers = [
            threading.Thread(
                target=self._pump,
                args=(stream, process.pid if standby and what == "out" else None),
                name=f"{self.name}-{what}",
                daemon=True,
            )
            for what, stream in (("out", process.stdout), ("err", process.stderr))
        ]
        for reader in readers:
            reader.start()
        return process, readers

    def start(self) -> None:
        """Start the process (from the main thread): wake the warm standby if there is one,
        else a new one; on failure schedule a retry."""
        self.restart_at = None
        self.started_at = time.monotonic()
        if self.health_file is not None:  # the last process's, aged: not this one's
            self.health_file.unlink(missing_ok=True)
        if self._wake_spare():
            return
        try:
            self.process, self._readers = self._spawn(self.argv, subprocess.DEVNULL)
        except OSError as exc:
            delay = self.backoff.delay_after_exit(0.0)
            log.error("cannot start %s: %s; retrying in %.1f s", self.name, exc, delay)
            self.process = None
            self.restart_at = time.monotonic() + delay
            return
        log.info(
            "started %s (pid %d)%s",
            self.name,
            self.process.pid,
            f", restart #{self.restarts}" if self.restarts else "",
            extra={"child": self.name, "pid": self.process.pid},
        )

    def _wake_spare(self) -> bool:
        """Make the warm standby the running process; False when there is none to wake."""
        spare, self.spare = self.spare, None
        if spare is None or not self._spare_alive(spare):
            return False
        assert spare.stdin is not None
        try:
            spare.stdin.write(b"run\n")
            spare.stdin.close()
        except OSError as exc:  # it died just now
            log.warning("the standby of %s (pid %d) cannot be woken: %s", self.name, spare.pid, exc)
            self._spare_failed = True
            return False
        self.process, self._readers = spare, self._spare_readers
        self._spare_readers = []
        log.info(
            "started %s (pid %d) from its warm standby%s",
            self.name,
            spare.pid,
            f", restart #{self.restarts}" if self.restarts else "",
            extra={"child": self.name, "pid": spare.pid, "standby": True},
        )
        return True

    def _spare_alive(self, spare: subprocess.Popen[bytes]) -> bool:
        returncode = spare.poll()
        if returncode is None:
            return True
        log.warning(
            "the standby of %s (pid %d) %s; %s restarts without one from now on",
            self.name,
            spare.pid,
            describe_exit(returncode),
            self.name,
        )
        self._spare_failed = True
        return False

    def wants_spare(self, now: float) -> bool:
        """Whether a standby should be started now: asked for, none yet, the child settled."""
        if self._spare_failed:
            return False
        if self.spare is not None:
            if self._spare_alive(self.spare):
                return False
            self.spare = None
            return False
        return self.running and now - self.started_at >= STANDBY_AFTER_S

    def start_spare(self) -> None:
        """Start the warm standby (from the main thread)."""
        argv = [self.argv[0], "-m", "wz_cli.standby", self.spec.module, *self.spec.args]
        self.spare_ready.clear()
        try:
            self.spare, self._spare_readers = self._spawn(argv, subprocess.PIPE, standby=True)
        except OSError as exc:
            log.warning("cannot start a standby of %s: %s", self.name, exc)
            self._spare_failed = True
            return
        log.info(
            "standby of %s (pid %d) importing, for a restart",
            self.name,
            self.spare.pid,
            extra={"child": self.name, "pid": self.spare.pid},
        )

    def release_spare(self) -> subprocess.Popen[bytes] | None:
        """End the standby (SIGTERM: it holds nothing yet) and take no other; the standby, for
        the caller to wait on (:func:`stop_children`)."""
        spare, self.spare = self.spare, None
        self._spare_failed = True
        if spare is not None:
            with contextlib.suppress(OSError):
                assert spare.stdin is not None
                spare.stdin.close()
            with contextlib.suppress(ProcessLookupError):
                spare.send_signal(signal.SIGTERM)
        return spare

    def _pump(self, stream: IO[bytes], standby_pid: int | None = None) -> None:
        """Re-emit the stream's lines; a standby's stdout (``standby_pid``) first says when
        it is ready, which is logged, not re-emitted."""
        with stream:
            for raw in iter(stream.readline, b""):
                line = raw.decode("utf-8", "replace").rstrip("\r\n")
                if standby_pid is not None and line.startswith(STANDBY_READY):
                    log.info(
                        "standby of %s (pid %d) ready: its imports took %s s",
                        self.name,
                        standby_pid,
                        line.removeprefix(STANDBY_READY).strip(),
                        extra={"child": self.name, "pid": standby_pid},
                    )
                    self.spare_ready.set()
                    standby_pid = None
                    continue
                self.output.write(self.name, line)

    def loop_age_s(self) -> float | None:
        """Seconds since the child's loop last went round (its health file), or None."""
        if self.health_file is None:
            return None
        try:
            return time.time() - self.health_file.stat().st_mtime
        except FileNotFoundError:
            return None

    def _kill_if_stalled(self) -> None:
        age_s = self.loop_age_s()
        if age_s is None or age_s <= STALL_RESTART_S or self.process is None:
            return
        self.stalls += 1
        log.warning(
            "%s (pid %d) stalled: its loop has not gone round for %.1f s (limit %.0f s); "
            "killing it to restart",
            self.name,
            self.process.pid,
            age_s,
            STALL_RESTART_S,
            extra={"child": self.name, "pid": self.process.pid, "stalled_s": round(age_s, 1)},
        )
        with contextlib.suppress(ProcessLookupError):
            self.process.kill()
        self.process.wait()

    def supervise(self, now: float) -> None:
        """Notice an exit (or a stalled loop, killed) and schedule the restart; restart when
        its time has come."""
        if self.process is not None:
            returncode = self.process.poll()
            if returncode is None:
                self._kill_if_stalled()
                returncode = self.process.poll()
            if returncode is None:
                return
            uptime_s = now - self.started_at
            delay = self.backoff.delay_after_exit(uptime_s)
            log.warning(
                "%s (pid %d) %s after %.1f s; restarting in %.1f s",
                self.name,
                self.process.pid,
                describe_exit(returncode),
                uptime_s,
                delay,
                extra={"child": self.name, "pid": self.process.pid, "returncode": returncode},
            )
            self.process = None
            self.restart_at = now + delay
        elif self.restart_at is not None and now >= self.restart_at:
            self.restarts += 1
            self.start()

    def join_output(self, timeout_s: float = 1.0) -> None:
        """Wait for the last lines of output to be re-emitted."""
        for reader in self._readers:
            reader.join(timeout_s)


def stop_children(children: Sequence[Child], grace_s: float = STOP_GRACE_S) -> None:
    """End the standbys; SIGTERM every running child, wait up to ``grace_s`` in all, SIGKILL
    the rest."""
    spares = [spare for child in children if (spare := child.release_spare()) is not None]
    running = [c for c in children if c.process is not None and c.process.poll() is None]
    for child in running:
        assert child.process is not None
        with contextlib.suppress(ProcessLookupError):
            child.process.send_signal(signal.SIGTERM)
    deadline = time.monotonic() + grace_s
    for child in running:
        assert child.process is not None
        try:
            returncode = child.process.wait(max(0.0, deadline - time.monotonic()))
            log.info("%s (pid %d) %s", child.name, child.process.pid, describe_exit(returncode))
        except subprocess.TimeoutExpired:
            log.warning(
                "%s (pid %d) did not stop within %.0f s of SIGTERM: killing it",
                child.name,
                child.process.pid,
                grace_s,
            )
            child.process.kill()
            child.process.wait()
    for spare in spares:
        try:
            spare.wait(max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            spare.kill()
            spare.wait()
    for child in children:
        child.restart_at = None
        child.join_output()


class Supervisor:
    """Starts the router, then the services; restarts what crashes; stops all on ``stop``."""

    def __init__(
        self,
        services: Sequence[ServiceSpec],
        options: StackOptions,
        stop: threading.Event,
        *,
        python: str = sys.executable,
        base_env: dict[str, str] | None = None,
        stop_grace_s: float = STOP_GRACE_S,
    ) -> None:
        address = tcp_address(options.router_endpoint)
        if address is None:
            raise CliError(
                f"the router endpoint must be tcp/ or tls/<host>:<port>, got {options.router_endpoint!r}"
            )
        self.router_address = address
        self.options = options
        self.stop = stop
        self.stop_grace_s = stop_grace_s
        env = dict(os.environ if base_env is None else base_env)
        output = PrefixedOutput([ROUTER.name, *(spec.name for spec in services)])
        router_argv = [*ROUTER.argv(python), "--listen", options.router_endpoint]
        if options.router_config is not None:
            router_argv += ["--config", str(options.router_config)]
        if options.router_connect is not None:
            router_argv += ["--connect", ",".join(options.router_connect)]
        if options.credentials is not None:
            router_argv += ["--tls-dir", str(options.credentials.resolve() / ROUTER.name)]
        self.router = Child(
            ROUTER,
            router_argv,
            ROUTER.child_env(env, options),
            output,
        )
        self.services = [
            Child(spec, spec.argv(python), spec.child_env(env, options), output)
            for spec in services
        ]

    @property
    def children(self) -> list[Child]:
        return [self.router, *self.services]

    def run(self) -> int:
        host, port = self.router_address
        if port_accepts(host, port):
            raise CliError(
                f"something already listens on {self.options.router_endpoint} (another `wz up`?); "
                "stop it, or choose another endpoint with --listen",
                1,
            )
        try:
            if not self._start_router():
                return 0 if self.stop.is_set() else 1
            for child in self.services:
                child.start()
            log.info(
                "stack up: router at %s, services: %s",
                self.options.router_endpoint,
                ", ".join(child.name for child in self.services) or "none",
            )
            next_spare_at = 0.0
            while not self.stop.is_set():
                now = time.monotonic()
                for child in self.children:
                    child.supervise(now)
                if now >= next_spare_at:
                    # The child that has waited longest first (not one just restarted).
                    waiting = min(
                        (c for c in self.services if c.wants_spare(now)),
                        key=lambda c: c.started_at,
                        default=None,
                    )
                    if waiting is not None:
                        waiting.start_spare()
                        next_spare_at = now + STANDBY_STAGGER_S
                self.stop.wait(POLL_PERIOD_S)
        finally:
            log.info("stopping the stack")
            stop_children(self.services, self.stop_grace_s)
            stop_children([self.router], self.stop_grace_s)
        log.info("stack stopped")
        return 0

    def _start_router(self) -> bool:
        self.router.start()
        host, port = self.router_address
        process = self.router.process
        ready = process is not None and wait_for_port(
            host,
            port,
            ROUTER_READY_TIMEOUT_S,
            still_worth_waiting=lambda: process.poll() is None and not self.stop.is_set(),
        )
        if not ready and not self.stop.is_set():
            why = (
                describe_exit(process.returncode)
                if process is not None and process.poll() is not None
                else f"its port did not open within {ROUTER_READY_TIMEOUT_S:.0f} s"
            )
            log.error("the router did not come up at %s: %s", self.options.router_endpoint, why)
        return ready
