"""The device driver's core (``SignDriver``) in this process against the sign simulator's
process over real SNMP: a wanted message put on the sign and read back, the face checked and
set again when the sign shows something else, a word too wide for the face cut and said, a
sign that stops answering reported unreachable (with the message kept for when it is back),
and what the status reports (``DeviceLink``)."""

from __future__ import annotations

import time

from tests.drivers.device_sims import Sign, free_udp_port
from wz_drivers.device_driver import DeviceDriverSettings, SignDriver
from wz_drivers.dms import DmsClient, SignSettings


def settings(port: int) -> DeviceDriverSettings:
    return DeviceDriverSettings(
        host="127.0.0.1", port=port, timeout_s=0.2, retries=0, retry_s=0.3, check_s=0.5
    )


def test_the_driver_keeps_the_sign_showing_what_is_wanted() -> None:
    port = free_udp_port()
    sign = Sign(port)
    config = settings(port)
    client = DmsClient(SignSettings("127.0.0.1", port, timeout_s=0.2, retries=0))
    other = DmsClient(SignSettings("127.0.0.1", port))
    driver = SignDriver(config, client)
    try:
        assert driver.link(0.0).reachable is None and driver.link(0.0).answer_age_s is None
        assert not driver.step(time.monotonic())  # nothing wanted: only a check
        assert driver.reachable is True and driver.shown == ""
        driver.want("QUEUE AHEAD 0.3 MI")
        assert driver.step(time.monotonic())
        assert sign.next_face()[0] == "QUEUE[nl]AHEAD[nl]0.3 MI"
        link = driver.link(time.monotonic())
        assert link.reachable and link.shows == "QUEUE AHEAD 0.3 MI"
        assert not driver.step(time.monotonic())  # shown, not yet time to check

        other.show("SLOW[nl]DOWN")  # someone else changed the face
        assert sign.next_face()[0] == "SLOW[nl]DOWN"
        time.sleep(config.check_s)
        assert driver.step(time.monotonic())  # the check finds it and sets it again
        assert sign.next_face()[0] == "QUEUE[nl]AHEAD[nl]0.3 MI"

        driver.want("CONSTRUCTION AHEAD")  # 12 characters on an 8-character line
        assert driver.step(time.monotonic())
        assert sign.next_face()[0] == "CONSTRUC[nl]AHEAD"

        sign.kill()
        driver.want("SLOW DOWN")
        assert not driver.step(time.monotonic())
        down = driver.link(time.monotonic())
        assert down.reachable is False and "timeout" in down.detail
        assert driver.wanted == "SLOW[nl]DOWN" and driver.shown is None
        assert not driver.step(time.monotonic())  # before retry_s: not even tried

        sign = Sign(port)  # back, blank
        time.sleep(config.retry_s)
        assert driver.step(time.monotonic())
        assert sign.next_face()[0] == "SLOW[nl]DOWN" and driver.reachable is True
    finally:
        client.close()
        other.close()
        sign.kill()
