"""Stop on SIGTERM and SIGINT without taking a lock inside the signal handler.

A Python signal handler runs in the main thread between two bytecodes, wherever that thread
is: inside ``Event.wait`` holding the event's lock, or inside another signal's handler. The
obvious handler, ``stop.set()``, takes the event's lock, which is not reentrant. When the
thread it interrupts already holds that lock, the thread waits on itself for good. Seen: a
fusion-tracker node of a ``wz up`` test, run on a loaded machine, hung with three SIGTERM
handlers on its main thread's stack, the last one waiting in ``Event.set``, and outlived the
test.

So the handler here only writes the signal's number to a pipe. ``os.write`` takes no Python
lock. A daemon thread reads the pipe, logs the signal and sets the event. One pipe and one
thread serve the whole process.

Usage, from the main thread::

    stop = stop_on_signals()          # a new event, or stop_on_signals(my_event)
    while not stop.is_set():
        ...
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import threading
from types import FrameType

log = logging.getLogger(__name__)

#: The signals that stop a process.
STOP_SIGNALS = (signal.SIGTERM, signal.SIGINT)

_lock = threading.Lock()
_write_fd: int | None = None
#: The process whose thread reads the pipe (a forked child has the pipe, not the thread).
_owner_pid: int | None = None
#: The event the next signal sets (the last one given to :func:`stop_on_signals`).
_target: threading.Event | None = None


def _watch(read_fd: int) -> None:
    """The signals' thread: each byte on the pipe is a signal to log; then set the event."""
    while data := os.read(read_fd, 64):
        for signum in data:
            log.info("%s: stopping", signal.Signals(signum).name)
        with _lock:
            target = _target
        if target is not None:
            target.set()


def _on_signal(signum: int, _frame: FrameType | None) -> None:
    # No lock, no logging, no Event here (the module docstring says why).
    fd = _write_fd
    if fd is None:
        return
    if os.getpid() != _owner_pid:  # a forked child: its parent's thread would read the byte
        if _target is not None:
            _target.set()  # the plain way, the child's own copy of the event
        return
    with contextlib.suppress(OSError):  # a full pipe: the thread has signals to read already
        os.write(fd, bytes((signum,)))


def _start_watcher() -> int:
    """The pipe's write end; the pipe and its thread are made on the first call."""
    global _write_fd, _owner_pid
    with _lock:
        if _write_fd is None or _owner_pid != os.getpid():
            read_fd, write_fd = os.pipe()
            os.set_blocking(write_fd, False)  # a handler must never block
            threading.Thread(target=_watch, args=(read_fd,), name="signals", daemon=True).start()
            _write_fd, _owner_pid = write_fd, os.getpid()
        return _write_fd


def stop_on_signals(stop: threading.Event | None = None) -> threading.Event:
    """``stop`` (or a new event), set once SIGTERM or SIGINT arrives.

    Installs the handlers, so call it from the main thread (``ValueError`` otherwise, as
    ``signal.signal`` does). A later call points the signals at its own event instead.
    """
    global _target
    if threading.current_thread() is not threading.main_thread():
        raise ValueError("signal handlers can only be installed from the main thread")
    event = threading.Event() if stop is None else stop
    _start_watcher()
    with _lock:
        _target = event
    for signum in STOP_SIGNALS:
        signal.signal(signum, _on_signal)
    return event
