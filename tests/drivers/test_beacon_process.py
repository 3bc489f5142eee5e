"""The flashing beacon driven from an alert over Modbus TCP, by real processes: the relay module
simulator (a pymodbus server, ``wz_drivers.beacon_sim``), the sign simulator, the alert service
and the device driver on a real Zenoh bus.

The relay closes within 1 s of the track batch that opens an alert and opens within 1 s of the
one that clears it. With the module hung (SIGSTOP: connections accepted, nothing answered),
alerts still flow, the sign still changes within 1 s, the driver's status says the beacon's
relay does not answer (service ``degraded``) and the WZDx feed logic calls the beacon
``error``; killed, the status says the connection is refused; back (relays open, as after a
power cycle), the driver closes the relay again for the alert still open.
"""

from __future__ import annotations

import logging
import time

from tests.alert_service.helpers import batch
from tests.alert_service.test_node_process import PERIOD_S, wait_for
from tests.cli.procs import free_port
from tests.drivers.device_sims import (
    RelayModule,
    Sign,
    alert_service_and_driver,
    free_udp_port,
    sign_settings,
)
from wz_gateway.wzdx import device_link_health
from wz_shared.messages import BEACON_DEVICE, SIGN_DEVICE, ServiceState

log = logging.getLogger(__name__)
#: The most a device may lag the track batch that changed what it must show [s].
MUST_FOLLOW_S = 1.0


def test_the_beacon_follows_the_alerts_within_a_second_and_a_hung_relay_blocks_nothing() -> None:
    sign_port, relay_port = free_udp_port(), free_port()
    sign, relay = Sign(sign_port), RelayModule(relay_port)
    try:
        with alert_service_and_driver(
            **sign_settings(sign_port),
            WZ_BEACON_HOST="127.0.0.1",
            WZ_BEACON_PORT=str(relay_port),
            # A hung module then holds each exchange 3 s (2 tries): were the devices talked to
            # in turn, the sign would lag the second alert by more than the second it is allowed.
            WZ_BEACON_TIMEOUT_S="1.5",
        ) as rig:
            alerts, driver_status = rig.alerts, rig.driver_status
            up = wait_for(
                driver_status,
                lambda s: all(
                    name in s.devices and s.devices[name].reachable is True
                    for name in (SIGN_DEVICE, BEACON_DEVICE)
                ),
                "the driver's first exchange with the sign and the relay",
            )
            assert up.devices[BEACON_DEVICE].address == f"tcp 127.0.0.1:{relay_port} unit 1 coil 0"
            assert up.devices[BEACON_DEVICE].shows == "off"

            # A speeder: the alert opens at the batch of 1.0 s; the relay closes.
            alert_sent_at = rig.speeder(1, 0.0, 0)
            closed, closed_at = relay.next_switch()
            assert closed, "the relay opened instead of closing"
            delay_s = closed_at - alert_sent_at
            log.info("relay closed %.0f ms after the alert's batch", 1000 * delay_s)
            assert 0.0 < delay_s < MUST_FOLLOW_S, f"the relay closed {delay_s:.3f} s after"
            assert sign.next_text()[0] == "SLOW[nl]DOWN"

            # The car leaves: the alert clears at the first empty batch; the relay opens.
            cleared_at = rig.send([batch(2.0 + k * PERIOD_S, [], 20 + k) for k in range(3)])
            clear = wait_for(alerts, lambda a: a.phase == "clear", "the speeding clear")
            closed, opened_at = relay.next_switch()
            assert not closed, "the relay did not open"
            delay_s = opened_at - cleared_at[round(clear.stamp, 3)]
            log.info("relay opened %.0f ms after the clearing batch", 1000 * delay_s)
            assert 0.0 < delay_s < MUST_FOLLOW_S, f"the relay opened {delay_s:.3f} s after"

            # The module hangs: the driver's read-back finds it, its status says so.
            relay.pause()
            down = rig.device_down(BEACON_DEVICE)
            link = down.devices[BEACON_DEVICE]
            assert "timeout, no answer" in link.detail and link.shows is None, link
            assert down.devices[SIGN_DEVICE].reachable is True
            now = time.time()
            sign_health = device_link_health("device-driver", (down, now), SIGN_DEVICE, now, 10.0)
            assert sign_health is not None and sign_health.status == "ok"

            # A second car, while the driver keeps trying the hung module: alerts flow, and the
            # sign changes within the second all the same.
            alert_sent_at = rig.speeder(2, 3.0, 30)
            face, shown_at = sign.next_text()
            delay_s = shown_at - alert_sent_at
            log.info("sign changed %.0f ms after the alert, the relay hung", 1000 * delay_s)
            assert face == "SLOW[nl]DOWN" and 0.0 < delay_s < MUST_FOLLOW_S, delay_s

            # Power lost: refused at once. Power back (every relay open): the alert is still
            # open, so the driver closes the relay again.
            relay.kill()
            wait_for(
                driver_status,
                lambda s: "Connection refused" in s.devices[BEACON_DEVICE].detail,
                "the driver reporting the connection refused",
            )
            relay = RelayModule(relay_port)
            closed, _ = relay.next_switch()
            assert closed, "the relay was not closed again"
            wait_for(
                driver_status,
                lambda s: (
                    s.state is ServiceState.RUNNING and s.devices[BEACON_DEVICE].shows == "on"
                ),
                "the driver reporting the relay back and closed",
            )
    finally:
        sign.kill()
        relay.kill()
