"""The roadside devices' simulators and the services that drive them, as the tests run them:
real processes on loopback ports.

:class:`Sign` is ``wz_drivers.sign_sim`` (an NTCIP 1203 SNMP agent), :class:`RelayModule` is
``wz_drivers.beacon_sim`` (a Modbus TCP server whose coil 0 switches the beacon). Each prints a
line when it listens and one per change of what it shows, with the wall-clock time; those
changes are queued here, so a test waits for the next one (no sleeps) and measures delays.
:func:`alert_service_and_driver` runs a router, the alert service and the device driver.
"""

from __future__ import annotations

import os
import queue
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.alert_service.helpers import SITE
from tests.alert_service.test_node_process import PERIOD_S, speeder_batches, wait_for
from tests.cli.procs import start_router, stop_process
from wz_gateway.wzdx import device_link_health
from wz_shared.bus import Bus, Publisher, Subscription
from wz_shared.messages import (
    Alert,
    AlertType,
    QueueState,
    RoadsideDeviceState,
    ServiceState,
    ServiceStatus,
    TrackBatch,
)
from wz_shared.settings import BusSettings

ROOT = Path(__file__).resolve().parents[2]
#: The services the device tests run, in start order.
SERVICES = ("wz_alert_service.node", "wz_drivers.device_driver")


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


class SimProcess:
    """A simulator process on ``port``; each change its stdout reports, queued in order.

    Subclasses say which (``module``), the start of the line it prints once it answers
    (``listening``), its change lines (``event``: group 1 what, group 2 the Unix time) and
    what a failure calls it (``what``).
    """

    module: str
    listening_line: str
    event: re.Pattern[str]
    what: str

    def __init__(self, port: int) -> None:
        self.port = port
        self.process = subprocess.Popen(
            [sys.executable, "-m", self.module, "--port", str(port)],
            cwd=ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
        )
        self.changes: queue.Queue[tuple[str, float]] = queue.Queue()
        self.listening = threading.Event()
        threading.Thread(target=self._read, daemon=True).start()
        assert self.listening.wait(20.0), f"{self.what} did not start"

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            if line.startswith(self.listening_line):
                self.listening.set()
            elif match := self.event.match(line.strip()):
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

    module = "wz_drivers.sign_sim"
    listening_line = "NTCIP 1203 sign listening"
    event = re.compile(r"^showing '(.*)' at ([0-9.]+)$")
    what = "the sign"

    def next_face(self, timeout_s: float = 10.0) -> tuple[str, float]:
        return self.next_change(timeout_s)

    def next_text(self) -> tuple[str, float]:
        """The next face that is not blank (the alert service's blank states may come
        first), and when."""
        face, at = self.next_face()
        while face == "":
            face, at = self.next_face()
        return face, at


class RelayModule(SimProcess):
    """The relay module simulator on TCP ``port`` (unit 1, coil 0 the beacon's); its changes
    are the beacon's relay: ``on`` or ``off``."""

    module = "wz_drivers.beacon_sim"
    listening_line = "Modbus TCP relay module listening"
    event = re.compile(r"^beacon (on|off) at ([0-9.]+)$")
    what = "the beacon's relay"

    def next_switch(self, timeout_s: float = 10.0) -> tuple[bool, float]:
        """The relay's next change: closed (True, the beacon flashes) or open, and when."""
        state, at = self.next_change(timeout_s)
        return state == "on", at


@dataclass
class Rig:
    """This test's bus session beside the services: tracks to put, what comes out to follow."""

    tracks: Publisher[TrackBatch]
    alerts: Subscription[Alert]
    #: The device driver's newest status.
    driver_status: Subscription[ServiceStatus]
    #: What the alert service wants the devices to show, each change.
    devices: Subscription[RoadsideDeviceState]
    #: Each lane's queue as the alert service publishes it.
    queue: Subscription[QueueState]

    def send(self, batches: list[TrackBatch]) -> dict[float, float]:
        """Put ``batches`` at twice the tracker's pace; when each went (by stamp, Unix time)."""
        sent_at = {}
        for message in batches:
            self.tracks.put(message)
            sent_at[round(message.stamp, 3)] = time.time()
            time.sleep(PERIOD_S / 2)
        return sent_at

    def speeder(self, track_id: int, start_s: float, first_cycle: int) -> float:
        """A speeding car (2 s of batches from ``start_s``) until its speeding alert opens;
        when the batch that opened it was put (Unix time)."""
        sent_at = self.send(speeder_batches(track_id, start_s, 2.0, first_cycle))
        start = wait_for(
            self.alerts,
            lambda a: (
                a.alert_type is AlertType.SPEEDING and a.phase == "start" and a.track_id == track_id
            ),
            f"car {track_id}'s speeding alert",
            timeout_s=5.0,
        )
        return sent_at[round(start.stamp, 3)]

    def device_down(self, device: str) -> ServiceStatus:
        """The driver's first status reporting ``device`` unreachable; the service is then
        degraded and the WZDx feed logic calls the device ``error``, saying it does not answer."""
        down = wait_for(
            self.driver_status,
            lambda s: device in s.devices and s.devices[device].reachable is False,
            f"the driver reporting the {device} unreachable",
        )
        assert down.state is ServiceState.DEGRADED
        now = time.time()
        health = device_link_health("device-driver", (down, now), device, now, 10.0)
        assert health is not None and health.status == "error"
        address = down.devices[device].address
        assert health.messages[0].startswith(f"{device} at {address} not answering"), health
        return down


def sign_settings(port: int) -> dict[str, str]:
    """The driver's settings for the sign simulator on ``port``: a retry every 0.5 s, a
    read-back every second."""
    return {
        "WZ_SIGN_HOST": "127.0.0.1",
        "WZ_SIGN_PORT": str(port),
        "WZ_SIGN_RETRY_S": "0.5",
        "WZ_SIGN_CHECK_S": "1.0",
    }


@contextmanager
def alert_service_and_driver(**settings: str) -> Iterator[Rig]:
    """A router, the alert service and the device driver (``settings``: its ``WZ_*``) as
    processes, each a client of the router; stopped at the end, where each must exit 0."""
    endpoint, router = start_router()
    env = {k: v for k, v in os.environ.items() if not k.startswith("WZ_")}
    env.update(
        WZ_BUS_MODE="client",
        WZ_BUS_CONNECT_ENDPOINTS=endpoint,
        WZ_BUS_LISTEN_ENDPOINTS="",
        WZ_STATUS_PERIOD_S="0.2",
        WZ_LOG_FORMAT="json",
        **settings,
    )
    bus_settings = BusSettings(mode="client", listen_endpoints=[], connect_endpoints=[endpoint])
    processes: list[subprocess.Popen[bytes]] = []
    try:
        with Bus.open(bus_settings, site=SITE.site_id, service="devices-test") as bus:
            rig = Rig(
                bus.publisher(bus.keys.tracks, TrackBatch),
                bus.subscribe(bus.keys.alerts_all, Alert),
                bus.subscribe(
                    bus.keys.status("device-driver"), ServiceStatus, mode="ring", capacity=1
                ),
                bus.subscribe(bus.keys.devices_state, RoadsideDeviceState),
                bus.subscribe(bus.keys.queue, QueueState),
            )
            try:
                for module in SERVICES:
                    processes.append(
                        subprocess.Popen([sys.executable, "-m", module], cwd=ROOT, env=env)
                    )
                assert rig.tracks.wait_for_subscribers(30.0), "the alert service never subscribed"
                yield rig
            finally:
                for process in processes:
                    process.terminate()
                for process in processes:
                    try:
                        process.wait(10.0)
                    except subprocess.TimeoutExpired:
                        process.kill()
    finally:
        stop_process(router)
    for process in processes:
        assert process.returncode == 0, "a service did not stop cleanly"
