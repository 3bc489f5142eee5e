"""wz_shared.signals: a burst of SIGTERMs stops a process whose main thread holds the stop
event's lock, where a handler that set the event itself hung the process (a fusion-tracker
node outlived its test that way). Real processes, real signals."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time

import pytest

from tests.cli.procs import ROOT
from wz_shared.signals import stop_on_signals

#: SIGTERMs sent in one burst; the handler that set the event hung 5 of 5 such runs.
BURST = 200


def test_a_burst_of_sigterms_stops_a_process_spinning_on_its_stop_event() -> None:
    child = subprocess.Popen(
        [sys.executable, "-m", "tests.shared.signal_child"],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert child.stdout is not None
        assert child.stdout.readline().strip() == "ready"
        for _ in range(BURST):
            os.kill(child.pid, signal.SIGTERM)
            time.sleep(0.0005)
        try:
            child.wait(20.0)
        except subprocess.TimeoutExpired:
            pytest.fail(f"the process hung after {BURST} SIGTERMs")
        assert child.returncode == 0
        assert child.stdout.read().strip() == "stopped"
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
        if child.stdout is not None:
            child.stdout.close()


def test_the_signal_sets_the_event_given_last() -> None:
    previous = {signum: signal.getsignal(signum) for signum in (signal.SIGTERM, signal.SIGINT)}
    try:
        first = stop_on_signals()
        second = stop_on_signals(threading.Event())
        os.kill(os.getpid(), signal.SIGINT)
        assert second.wait(5.0)
        assert not first.is_set()
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def test_handlers_are_installed_from_the_main_thread_only() -> None:
    errors: list[Exception] = []

    def install() -> None:
        try:
            stop_on_signals()
        except ValueError as exc:
            errors.append(exc)

    thread = threading.Thread(target=install)
    thread.start()
    thread.join()
    assert len(errors) == 1 and "main thread" in str(errors[0])


def test_a_forked_child_stops_itself_not_its_parent() -> None:
    previous = {signum: signal.getsignal(signum) for signum in (signal.SIGTERM, signal.SIGINT)}
    try:
        stop = stop_on_signals()
        pid = os.fork()
        if pid == 0:  # the child: its SIGTERM sets its own copy of the event
            code = 1
            try:
                os.kill(os.getpid(), signal.SIGTERM)
                code = 0 if stop.wait(5.0) else 1
            finally:
                os._exit(code)
        _, status = os.waitpid(pid, 0)
        assert os.waitstatus_to_exitcode(status) == 0
        time.sleep(0.2)  # a byte the parent's thread wrongly read would have set it by now
        assert not stop.is_set()
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
