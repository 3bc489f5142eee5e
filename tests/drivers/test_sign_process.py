"""The message sign driven from an alert, over NTCIP 1203 on real SNMP, by real processes:
the sign simulator (an SNMP agent, ``wz_drivers.sign_sim``), the alert service and the device
driver on a real Zenoh bus. The sign changes within 1 s of the alert; with the sign's agent
killed, alerts still flow, the driver's status says the sign does not answer and the WZDx
device feed shows it as ``error``; the agent back (blank, as after a power cycle), the driver
puts the message on it again."""

from __future__ import annotations

from tests.alert_service.helpers import batch
from tests.alert_service.test_node_process import speeder_batches, wait_for
from tests.drivers.device_sims import Sign, alert_service_and_driver, free_udp_port, sign_settings
from wz_shared.messages import SIGN_DEVICE, Alert, ServiceState


def test_an_alert_changes_the_sign_within_a_second_and_a_dead_sign_blocks_nothing() -> None:
    sign_port = free_udp_port()
    sign = Sign(sign_port)
    try:
        with alert_service_and_driver(**sign_settings(sign_port)) as rig:
            alerts, driver_status = rig.alerts, rig.driver_status
            # The driver up and talking to the (blank) sign before the first alert.
            wait_for(
                driver_status,
                lambda s: SIGN_DEVICE in s.devices and s.devices[SIGN_DEVICE].reachable is True,
                "the driver's first exchange with the sign",
            )
            alert_sent_at = rig.speeder(1, 0.0, 0)
            face, shown_at = sign.next_text()
            assert face == "SLOW[nl]DOWN"
            delay_s = shown_at - alert_sent_at
            assert 0.0 < delay_s < 1.0, f"the sign changed {delay_s:.3f} s after the alert"

            # The sign's agent dies. A second car: alerts still flow, at once.
            sign.kill()
            rig.send(speeder_batches(2, 2.0, 2.0, 20))
            rig.tracks.put(batch(4.0, [], 40))  # both cars gone: their episodes clear
            seen: list[Alert] = []
            wait_for(
                alerts,
                lambda a: a.track_id == 2 and a.phase == "start",
                "the second car's start, the sign dead",
                seen,
                timeout_s=5.0,
            )
            wait_for(alerts, lambda a: a.phase == "clear", "a clear, the sign dead", seen)
            link = rig.device_down(SIGN_DEVICE).devices[SIGN_DEVICE]
            assert f"127.0.0.1:{sign_port}" in link.address and "timeout" in link.detail

            # Back (blank, after a power cycle): the driver sets what the alerts want now.
            rig.send(speeder_batches(3, 5.0, 2.0, 50))
            sign = Sign(sign_port)
            face, _ = sign.next_face(timeout_s=10.0)
            assert face == "SLOW[nl]DOWN"
            wait_for(
                driver_status,
                lambda s: (
                    s.state is ServiceState.RUNNING and s.devices[SIGN_DEVICE].shows == "SLOW DOWN"
                ),
                "the driver reporting the sign back",
            )
    finally:
        sign.kill()
