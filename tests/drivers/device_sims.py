"""The roadside device simulators as the tests run them: real processes on loopback ports.

:class:`Sign` is ``wz_drivers.sign_sim`` (an NTCIP 1203 SNMP agent), :class:`RelayModule` is
``wz_drivers.beacon_sim`` (a Modbus TCP server whose coil 0 switches the beacon). Each prints a
line when it listens and one per change of what it shows, with the wall-clock time; those
changes are queued here, so a test waits for the next one (no sleeps) and measures delays.
"""

from __future__ import annotations

import queue
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


class SimProcess:
    """A simulator process; each change its stdout reports (``event`` matched: its first group,
    and its time, the second), queued in order.

    Parameters
    ----------
    module, args : str, list of str
        ``python -m module *args``.
    listening : str
        The start of the line it prints once it answers.
    event : re.Pattern
        A change line: group 1 what, group 2 the Unix time.
    what : str
        What a failure calls it ("the sign").
    """

    def __init__(
        self, module: str, args: list[str], listening: str, event: re.Pattern[str], what: str
    ) -> None:
        self.what = what
        self._listening_line = listening
        self._event = event
        self.process = subprocess.Popen(
            [sys.executable, "-m", module, *args],
            cwd=ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
        )
        self.changes: queue.Queue[tuple[str, float]] = queue.Queue()
        self.listening = threading.Event()
        threading.Thread(target=self._read, daemon=True).start()
        assert self.listening.wait(20.0), f"{what} did not start"

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            if line.startswith(self._listening_line):
                self.listening.set()
            elif match := self._event.match(line.strip()):
                self.changes.put((match.group(1), float(match.group(2))))

    def next_change(self, timeout_s: float = 10.0) -> tuple[str, float]:
        """The next change it reports, and when; fails the test after ``timeout_s``."""
        try:
            return self.changes.get(timeout=timeout_s)
        except queue.Empty:
            pytest.fail(f"{self.what} did not change within {timeout_s:.0f} s")

    def pause(self) -> None:
        """SIGSTOP: the kernel still accepts connections, the process answers nothing (a
        hung controller); :meth:`resume` lets it go on. Returns once it is stopped."""
        self.process.send_signal(signal.SIGSTOP)
        stat = Path(f"/proc/{self.process.pid}/stat")
        deadline = time.monotonic() + 5.0
        while stat.read_text().rsplit(")", 1)[1].split()[0] != "T":
            assert time.monotonic() < deadline, f"{self.what} did not stop"
            time.sleep(0.001)

    def resume(self) -> None:
        self.process.send_signal(signal.SIGCONT)

    def kill(self) -> None:
        """SIGKILL (also when paused): gone, as after a loss of power."""
        self.process.send_signal(signal.SIGKILL)
        self.process.wait(10.0)


class Sign(SimProcess):
    """The sign simulator on UDP ``port``; its changes are faces (MULTI strings)."""

    def __init__(self, port: int) -> None:
        self.port = port
        super().__init__(
            "wz_drivers.sign_sim",
            ["--port", str(port)],
            "NTCIP 1203 sign listening",
            re.compile(r"^showing '(.*)' at ([0-9.]+)$"),
            "the sign",
        )

    def next_face(self, timeout_s: float = 10.0) -> tuple[str, float]:
        return self.next_change(timeout_s)


class RelayModule(SimProcess):
    """The relay module simulator on TCP ``port`` (unit 1, coil 0 the beacon's); its changes
    are the beacon's relay: ``on`` or ``off``."""

    def __init__(self, port: int) -> None:
        self.port = port
        super().__init__(
            "wz_drivers.beacon_sim",
            ["--port", str(port)],
            "Modbus TCP relay module listening",
            re.compile(r"^beacon (on|off) at ([0-9.]+)$"),
            "the beacon's relay",
        )

    def next_switch(self, timeout_s: float = 10.0) -> tuple[bool, float]:
        """The relay's next change: closed (True, the beacon flashes) or open, and when."""
        state, at = self.next_change(timeout_s)
        return state == "on", at
