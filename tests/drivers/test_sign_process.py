"""The message sign driven from an alert, over NTCIP 1203 on real SNMP, by real processes:
the sign simulator (an SNMP agent, ``wz_drivers.sign_sim``), the alert service and the device
driver on a real Zenoh bus. The sign changes within 1 s of the alert; with the sign's agent
killed, alerts still flow, the driver's status says the sign does not answer and the WZDx
device feed shows it as ``error``; the agent back (blank, as after a power cycle), the driver
puts the message on it again. A queue that forms reads STOPPED TRAFFIC AHEAD on the sign within
2 s of its detection, and the sign changes and clears with its hysteresis, never flickering."""

from __future__ import annotations

import itertools
import time

from tests.alert_service.helpers import SITE, batch, make_track
from tests.alert_service.test_node_process import PERIOD_S, speeder_batches, wait_for
from tests.drivers.device_sims import Sign, alert_service_and_driver, free_udp_port, sign_settings
from wz_shared.messages import (
    SIGN_DEVICE,
    Alert,
    AlertType,
    QueueCondition,
    QueueState,
    RoadsideDeviceState,
    ServiceState,
    TrackBatch,
)


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


def queue_batches(
    start_s: float, end_s: float, speed_mps: float, first_cycle: int
) -> list[TrackBatch]:
    """Five vehicles of the open lane at ``speed_mps``, 900-948 m (0.25 mi past the sign at
    500 m), in 10 Hz batches over ``[start_s, end_s)`` (stamps)."""
    count = round((end_s - start_s) / PERIOD_S)
    return [
        batch(
            start_s + k * PERIOD_S,
            [make_track(i + 1, 900.0 + 12.0 * i, speed_mps) for i in range(5)],
            first_cycle + k,
        )
        for k in range(count)
    ]


def test_a_queue_reads_stopped_traffic_within_2_s_and_clears_with_hysteresis() -> None:
    rules = SITE.alerts
    hold_s, clear_s = rules.devices.message_hold_s, rules.queue.clear_s
    sign_port = free_udp_port()
    sign = Sign(sign_port)
    try:
        with alert_service_and_driver(**sign_settings(sign_port)) as rig:
            wait_for(
                rig.driver_status,
                lambda s: SIGN_DEVICE in s.devices and s.devices[SIGN_DEVICE].reachable is True,
                "the driver's first exchange with the sign",
            )
            # 0-8 s stopped: the queue opens after its 3 s hold
            rig.send(queue_batches(0.0, 8.0, 0.5, 0))
            start = wait_for(
                rig.alerts,
                lambda a: a.alert_type is AlertType.QUEUE and a.phase == "start",
                "the queue's start",
                timeout_s=5.0,
            )
            detected_at = time.time()  # at the latest: the start is already here
            face, shown_at = sign.next_text()
            assert face == "STOPPED[nl]TRAFFIC[nl]AHEAD"
            assert shown_at - detected_at < 2.0, f"the sign {shown_at - detected_at:.2f} s late"
            # 8-16 s: the queue creeps at 6 m/s (slow, not stopped); 16-30 s: gone
            rig.send(queue_batches(8.0, 16.0, 6.0, 80))
            rig.send([batch(16.0 + k * PERIOD_S, [], 160 + k) for k in range(140)])
            slow, _ = sign.next_face()
            assert slow == "SLOW[nl]TRAFFIC[nl]0.2 MI"  # 400 m = 0.25 mi: 0.2
            blank, _ = sign.next_face()
            assert blank == ""

            # What the alert service decided, by stamp: stopped with the queue's start; slow
            # only once it had held 5 s; blank only 10 s after the last queued vehicle.
            seen: list[RoadsideDeviceState] = []
            wait_for(rig.devices, lambda d: d.sign_text == "" and d.stamp > 16.0, "the blank", seen)
            texts = [(d.stamp, d.sign_text) for d in seen]
            changes = [texts[0]] + [b for a, b in itertools.pairwise(texts) if b[1] != a[1]]
            stopped_at = next(t for t, text in changes if text == "STOPPED TRAFFIC AHEAD")
            slow_at = next(t for t, text in changes if text.startswith("SLOW TRAFFIC"))
            blank_at = next(t for t, text in changes if text == "" and t > slow_at)
            assert stopped_at == start.stamp
            assert slow_at >= 8.0 + hold_s - 1e-6
            assert blank_at >= 16.0 + clear_s - PERIOD_S - 1e-6
            assert [text for t, text in changes if t >= start.stamp] == [
                "STOPPED TRAFFIC AHEAD",
                "SLOW TRAFFIC 0.2 MI",
                "",
            ]
            # Each lane's queue on the bus, about once a second of stamps
            states: list[QueueState] = []
            wait_for(rig.queue, lambda q: q.stamp >= 29.0, "the queue state at 29 s", states)
            queued = [q for q in states if q.lanes[0].condition is not QueueCondition.FREE]
            assert queued and queued[0].lanes[0].back_station_m == 900.0
            assert {q.lanes[0].condition for q in queued} == {
                QueueCondition.STOPPED,
                QueueCondition.SLOW,
            }
            gaps = [b.stamp - a.stamp for a, b in itertools.pairwise(states)]
            assert max(gaps) <= 1.0 + 1e-6 and len(states) >= 29
    finally:
        sign.kill()
