"""The beacon's relay over Modbus TCP: :class:`~wz_drivers.beacon.BeaconClient` and the device
driver's core (``BeaconDriver``) in this process against the relay module simulator's process
(``wz_drivers.beacon_sim``, pymodbus's server) on loopback.

The relay switched and read back; a unit or coil the module lacks refused with the Modbus
exception in words; a module that hangs (SIGSTOP) is a timeout within the client's budget, one
that is gone (SIGKILL) a refused connection at once, and neither is mistaken for an answer
later; the driver sets the relay again when a check finds it otherwise (switched by hand,
module power-cycled), and its settings come from ``WZ_BEACON_*``.
"""

from __future__ import annotations

import time

import pytest
from pydantic import ValidationError

from tests.cli.procs import free_port
from tests.drivers.device_sims import RelayModule
from wz_drivers.beacon import BeaconClient, BeaconError, BeaconSettings
from wz_drivers.beacon_sim import RelayModule as RelayModel
from wz_drivers.device_driver import BeaconDriver, DeviceDriverSettings, beacon_settings

#: One try of 0.2 s: a dead module costs an exchange 0.2 s.
TIMEOUT_S = 0.2


def client(port: int, **changes: int) -> BeaconClient:
    return BeaconClient(
        BeaconSettings("127.0.0.1", port, timeout_s=TIMEOUT_S, retries=0, **changes)
    )


@pytest.fixture
def module() -> RelayModule:
    return RelayModule(free_port())


def test_the_relay_is_switched_and_read_back(module: RelayModule) -> None:
    beacon = client(module.port)
    try:
        assert beacon.relay() is False  # a module starts with its relays open
        sent = time.time()
        assert beacon.set_relay(True) is True
        closed, at = module.next_switch()
        assert closed and -0.001 <= at - sent < 1.0  # (its time is printed to the ms)
        assert beacon.relay() is True
        assert beacon.set_relay(True) is True  # again: no change, and none printed
        assert beacon.set_relay(False) is False
        assert module.next_switch()[0] is False  # the next change is the opening
        assert beacon.relay() is False
    finally:
        beacon.close()
        module.kill()


def test_a_unit_or_coil_the_module_lacks_is_refused_in_words(module: RelayModule) -> None:
    port = module.port
    wrong_unit, wrong_coil, right = client(port, unit=9), client(port, coil=16), client(port)
    try:
        with pytest.raises(BeaconError) as refused:
            wrong_unit.set_relay(True)
        assert refused.value.answered
        assert str(refused.value) == (
            f"tcp 127.0.0.1:{port} unit 9 coil 0: write refused: Modbus exception 11, gateway "
            "target device failed to respond: no such unit, or it is off"
        )
        with pytest.raises(BeaconError, match="Modbus exception 2, illegal data address: no"):
            wrong_coil.relay()
        with pytest.raises(BeaconError, match="unit 1 coil 16: write refused"):
            wrong_coil.set_relay(True)
        assert right.relay() is False  # the beacon's relay was not touched
    finally:
        for each in (wrong_unit, wrong_coil, right):
            each.close()
        module.kill()


def test_a_hung_or_dead_module_is_a_quick_error_and_no_late_answer_is_taken(
    module: RelayModule,
) -> None:
    port = module.port
    beacon = client(port)
    try:
        assert beacon.set_relay(True)
        assert module.next_switch()[0] is True
        module.pause()  # hung: connections accepted, nothing answered
        started = time.monotonic()
        with pytest.raises(BeaconError) as hung:
            beacon.set_relay(False)
        took_s = time.monotonic() - started
        assert not hung.value.answered and TIMEOUT_S <= took_s < TIMEOUT_S + 0.3
        assert "timeout, no answer to the write in 1 x 0.2 s" in str(hung.value)

        module.resume()  # it now answers the write it had queued (the relay opens) ...
        assert module.next_switch()[0] is False
        # ... on the connection the client dropped: this exchange is answered on its own.
        assert beacon.relay() is False
        assert beacon.set_relay(True) is True

        module.kill()
        started = time.monotonic()
        for _ in range(2):  # the connection the module dropped, then no module at all
            with pytest.raises(BeaconError) as gone:
                beacon.relay()
            assert not gone.value.answered
        assert time.monotonic() - started < TIMEOUT_S
        assert (
            str(gone.value)
            == f"tcp 127.0.0.1:{port} unit 1 coil 0: no connection (Connection refused)"
        )
    finally:
        beacon.close()
        module.kill()


def test_the_driver_keeps_the_relay_as_wanted_through_a_power_cycle(module: RelayModule) -> None:
    port = module.port
    config = DeviceDriverSettings(host="sign", retry_s=0.3, check_s=0.5)
    driver = BeaconDriver(config, client(port))
    by_hand = client(port)
    try:
        assert driver.link(0.0).reachable is None and driver.link(0.0).detail == "not contacted yet"
        assert not driver.step(time.monotonic())  # nothing wanted: only a check
        assert driver.reachable is True and driver.shown is False
        driver.want(True)
        assert driver.step(time.monotonic())
        assert module.next_switch()[0] is True
        link = driver.link(time.monotonic())
        assert link.reachable and link.shows == "on" and link.detail == "showing 'on'"
        assert link.address == f"tcp 127.0.0.1:{port} unit 1 coil 0"
        assert not driver.step(time.monotonic())  # on, not yet time to check

        by_hand.set_relay(False)  # someone switched it off at the module
        assert module.next_switch()[0] is False
        # The check, one period on (the driver is given its time: no sleep), finds it and
        # closes it again.
        assert driver.step(time.monotonic() + config.check_s)
        assert module.next_switch()[0] is True

        module.kill()  # power lost
        driver.want(False)
        assert not driver.step(time.monotonic())
        down = driver.link(time.monotonic())
        assert down.reachable is False and "no connection" in down.detail and down.shows is None
        assert not driver.step(time.monotonic())  # before retry_s: not even tried

        driver.want(True)  # an alert while it is down: kept for when it is back
        module = RelayModule(port)  # power back: every relay open
        assert driver.step(time.monotonic() + config.retry_s)
        closed, _ = module.next_switch()
        assert closed and driver.reachable is True and driver.link(time.monotonic()).shows == "on"
    finally:
        driver.close()
        by_hand.close()
        module.kill()


def test_the_beacon_settings_come_from_wz_beacon(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("WZ_SIGN_HOST", "dms")
    for name in ("WZ_BEACON_HOST", "WZ_BEACON_PORT", "WZ_BEACON_UNIT", "WZ_BEACON_COIL"):
        monkeypatch.delenv(name, raising=False)
    assert beacon_settings(DeviceDriverSettings()) is None  # unset: no beacon driven
    monkeypatch.setenv("WZ_BEACON_HOST", " ")
    assert beacon_settings(DeviceDriverSettings()) is None  # compose's empty default
    monkeypatch.setenv("WZ_BEACON_HOST", "io-module")
    monkeypatch.setenv("WZ_BEACON_UNIT", "3")
    monkeypatch.setenv("WZ_BEACON_COIL", "5")
    assert beacon_settings(DeviceDriverSettings()) == BeaconSettings("io-module", 502, 3, 5)
    monkeypatch.setenv("WZ_BEACON_UNIT", "256")
    with pytest.raises(ValidationError, match="WZ_BEACON_UNIT"):
        DeviceDriverSettings()
    with pytest.raises(ValueError, match="beacon coil 70000 is not within 0 to 65535"):
        BeaconSettings("io-module", coil=70000)


def test_the_simulated_module_reports_each_change_of_the_beacon_only_once(
    capsys: pytest.CaptureFixture[str],
) -> None:
    relays = RelayModel(16, beacon_coil=2)
    relays.switch(2, True)
    relays.switch(2, True)
    relays.switch(3, True)
    relays.switch(2, False)
    lines = [line.rsplit(" at ", 1)[0] for line in capsys.readouterr().out.splitlines()]
    assert lines == ["beacon on", "coil 3 on", "beacon off"]
    with pytest.raises(ValueError, match="multiple of 16"):
        RelayModel(8, beacon_coil=0)
