"""The message sign driven from an alert, over NTCIP 1203 on real SNMP, by real processes:
the sign simulator (an SNMP agent, ``wz_drivers.sign_sim``), the alert service and the device
driver on a real Zenoh bus. The sign changes within 1 s of the alert; with the sign's agent
killed, alerts still flow, the driver's status says the sign does not answer and the WZDx
device feed shows it as ``error``; the agent back (blank, as after a power cycle), the driver
puts the message on it again."""

from __future__ import annotations

import os
import subprocess
import sys
import time

from tests.alert_service.helpers import SITE, batch
from tests.alert_service.test_node_process import PERIOD_S, speeder_batches, wait_for
from tests.cli.procs import start_router, stop_process
from tests.drivers.device_sims import ROOT, Sign, free_udp_port
from wz_gateway.wzdx import device_link_health
from wz_shared.bus import Bus
from wz_shared.messages import (
    SIGN_DEVICE,
    Alert,
    AlertType,
    ServiceState,
    ServiceStatus,
    TrackBatch,
)
from wz_shared.settings import BusSettings


def test_an_alert_changes_the_sign_within_a_second_and_a_dead_sign_blocks_nothing() -> None:
    sign_port = free_udp_port()
    endpoint, router = start_router()  # the box's router: the services are its clients
    settings = BusSettings(mode="client", listen_endpoints=[], connect_endpoints=[endpoint])
    env = {k: v for k, v in os.environ.items() if not k.startswith("WZ_")}
    env.update(
        WZ_BUS_MODE="client",
        WZ_BUS_CONNECT_ENDPOINTS=endpoint,
        WZ_BUS_LISTEN_ENDPOINTS="",
        WZ_STATUS_PERIOD_S="0.2",
        WZ_LOG_FORMAT="json",
        WZ_SIGN_HOST="127.0.0.1",
        WZ_SIGN_PORT=str(sign_port),
        WZ_SIGN_RETRY_S="0.5",
        WZ_SIGN_CHECK_S="1.0",
    )
    sign = Sign(sign_port)
    processes = []
    with Bus.open(settings, site=SITE.site_id, service="sign-test") as bus:
        tracks = bus.publisher(bus.keys.tracks, TrackBatch)
        alerts = bus.subscribe(bus.keys.alerts_all, Alert)
        driver_status = bus.subscribe(
            bus.keys.status("device-driver"), ServiceStatus, mode="ring", capacity=1
        )
        try:
            for module in ("wz_alert_service.node", "wz_drivers.device_driver"):
                processes.append(
                    subprocess.Popen([sys.executable, "-m", module], cwd=ROOT, env=env)
                )
            assert tracks.wait_for_subscribers(30.0), "the alert service never subscribed"
            # The driver up and talking to the (blank) sign before the first alert.
            wait_for(
                driver_status,
                lambda s: (
                    "dynamic-message-sign" in s.devices
                    and s.devices["dynamic-message-sign"].reachable is True
                ),
                "the driver's first exchange with the sign",
            )
            sent_at: dict[float, float] = {}
            for message in speeder_batches(1, 0.0, 2.0, 0):
                tracks.put(message)
                sent_at[round(message.stamp, 3)] = time.time()
                time.sleep(PERIOD_S / 2)
            start = wait_for(
                alerts,
                lambda a: a.alert_type is AlertType.SPEEDING and a.phase == "start",
                "the speeding start",
            )
            face, shown_at = sign.next_face()
            while face == "":  # the alert service's first state (blank) may come first
                face, shown_at = sign.next_face()
            assert face == "SLOW[nl]DOWN"
            delay_s = shown_at - sent_at[round(start.stamp, 3)]
            assert 0.0 < delay_s < 1.0, f"the sign changed {delay_s:.3f} s after the alert"

            # The sign's agent dies. A second car: alerts still flow, at once.
            sign.kill()
            for message in speeder_batches(2, 2.0, 2.0, 20):
                tracks.put(message)
                time.sleep(PERIOD_S / 2)
            tracks.put(batch(4.0, [], 40))  # both cars gone: their episodes clear
            seen: list[Alert] = []
            wait_for(
                alerts,
                lambda a: a.track_id == 2 and a.phase == "start",
                "the second car's start, the sign dead",
                seen,
                timeout_s=5.0,
            )
            wait_for(alerts, lambda a: a.phase == "clear", "a clear, the sign dead", seen)
            down = wait_for(
                driver_status,
                lambda s: s.devices["dynamic-message-sign"].reachable is False,
                "the driver reporting the sign unreachable",
            )
            assert down.state is ServiceState.DEGRADED
            link = down.devices["dynamic-message-sign"]
            assert f"127.0.0.1:{sign_port}" in link.address and "timeout" in link.detail
            feed = device_link_health(
                "device-driver", (down, time.time()), SIGN_DEVICE, time.time(), 10.0
            )
            assert feed is not None and feed.status == "error"
            assert "not answering" in feed.messages[0]

            # Back (blank, after a power cycle): the driver sets what the alerts want now.
            for message in speeder_batches(3, 5.0, 2.0, 50):
                tracks.put(message)
                time.sleep(PERIOD_S / 2)
            sign = Sign(sign_port)
            face, _ = sign.next_face(timeout_s=10.0)
            assert face == "SLOW[nl]DOWN"
            wait_for(
                driver_status,
                lambda s: (
                    s.state is ServiceState.RUNNING
                    and s.devices["dynamic-message-sign"].shows == "SLOW DOWN"
                ),
                "the driver reporting the sign back",
            )
        finally:
            for process in processes:
                process.terminate()
            for process in processes:
                try:
                    process.wait(10.0)
                except subprocess.TimeoutExpired:
                    process.kill()
            sign.kill()
            stop_process(router)
    for process in processes:
        assert process.returncode == 0, "a service did not stop cleanly"
