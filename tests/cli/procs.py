"""Helpers of the `wz` tests: run `wz` and helper processes, wait on conditions, free ports."""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TypeVar

import pytest

ROOT = Path(__file__).resolve().parents[2]
P = TypeVar("P", subprocess.Popen[str], subprocess.Popen[bytes])


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def wz_argv(*args: str) -> list[str]:
    """The `wz` command run by this interpreter (no `uv run` layer between test and process)."""
    return [sys.executable, "-m", "wz_cli.main", *args]


def wz_env(**extra: str) -> dict[str, str]:
    """The environment of a `wz` process: this one without WZ_* settings, logs as JSON."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("WZ_")}
    # The terminal's size as pytest (or its xdist worker) set it would cut `wz tap`'s lines.
    for name in ("COLUMNS", "LINES"):
        env.pop(name, None)
    env.update({"WZ_LOG_FORMAT": "json", "PYTHONUNBUFFERED": "1", **extra})
    return env


def run_wz(
    *args: str, timeout_s: float = 60.0, **extra_env: str
) -> subprocess.CompletedProcess[str]:
    """Run `wz ARGS` to completion; stdout and stderr captured as text."""
    return subprocess.run(
        wz_argv(*args),
        cwd=ROOT,
        env=wz_env(**extra_env),
        capture_output=True,
        text=True,
        timeout=timeout_s,
        check=False,
    )


def port_open(port: int) -> bool:
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=0.2):
            return True
    except OSError:
        return False


def wait_for(condition: Callable[[], bool], timeout_s: float, what: str) -> None:
    """Poll ``condition`` until true; fail the test with ``what`` at the deadline."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {timeout_s:.0f} s waiting for {what}")
        time.sleep(0.05)


def stop_process(
    process: subprocess.Popen[bytes] | subprocess.Popen[str], timeout_s: float = 10.0
) -> int:
    """SIGTERM, wait, SIGKILL if needed; return the exit code."""
    if process.poll() is None:
        process.send_signal(signal.SIGTERM)
        try:
            process.wait(timeout_s)
        except subprocess.TimeoutExpired:
            process.kill()
    return process.wait()


def start_helper(endpoint: str, *args: str) -> subprocess.Popen[str]:
    """A `tests.cli.bus_tools` process (see there); stdout piped as text."""
    return subprocess.Popen(
        [sys.executable, "-m", "tests.cli.bus_tools", args[0], endpoint, *args[1:]],
        cwd=ROOT,
        env=wz_env(),
        stdout=subprocess.PIPE,
        text=True,
    )


def start_wz(
    *args: str, stdout: int | None = subprocess.PIPE, **extra_env: str
) -> subprocess.Popen[str]:
    return subprocess.Popen(
        wz_argv(*args),
        cwd=ROOT,
        env=wz_env(**extra_env),
        stdout=stdout,
        stderr=subprocess.PIPE,
        text=True,
    )


def start_wz_up(
    tmp_path: Path, endpoint: str, http_port: int, *args: str
) -> subprocess.Popen[bytes]:
    """`wz up --listen ENDPOINT ARGS...` with its state under ``tmp_path``, the gateway on
    ``http_port`` and every line of its output in ``tmp_path / "up.log"``."""
    log = (tmp_path / "up.log").open("wb")
    return subprocess.Popen(
        wz_argv("up", "--listen", endpoint, *args),
        cwd=ROOT,
        env=wz_env(
            WZ_SIM_WORK_DIR=str(tmp_path / "sim"),
            WZ_STATUS_PERIOD_S="1.0",
            WZ_GATEWAY_PORT=str(http_port),
            WZ_GATEWAY_DATA_DIR=str(tmp_path / "gw"),
        ),
        stdout=log,
        stderr=subprocess.STDOUT,
    )


def communicate_while_publishing(
    process: subprocess.Popen[str], endpoint: str, *mix: str
) -> tuple[str, str]:
    """``process``'s (stdout, stderr) once it has ended, a ``bus_tools publish`` helper
    publishing ``mix`` meanwhile; the helper's session stays open until ``process`` has
    ended (it has seen everything arrive), then the helper is stopped and must exit 0."""
    with running(start_helper(endpoint, "publish", *mix)) as publisher:
        assert publisher.stdout is not None
        assert publisher.stdout.readline() == "published\n", publisher.poll()
        out, err = process.communicate(timeout=60)
        assert stop_process(publisher) == 0
    return out, err


@contextlib.contextmanager
def running(process: P) -> Iterator[P]:
    """Make sure ``process`` is gone when the block ends, whatever happened in it."""
    try:
        yield process
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()


def start_router() -> tuple[str, subprocess.Popen[bytes]]:
    """A `wz router` on a free loopback port, accepting connections; (endpoint, process)."""
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    process = subprocess.Popen(
        wz_argv("router", "--listen", endpoint), cwd=ROOT, env=wz_env(), stderr=subprocess.PIPE
    )
    wait_for(lambda: port_open(port) or process.poll() is not None, 20.0, "the router")
    if process.poll() is not None:
        err = process.stderr.read().decode() if process.stderr else ""
        pytest.fail(f"the router exited: {err}")
    return endpoint, process
