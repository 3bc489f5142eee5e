"""The device driver: the alert service's roadside state onto a real message sign (NTCIP 1203)
and a flashing beacon's relay (Modbus TCP).

``python -m wz_drivers.device_driver`` (service ``device-driver``) follows
``wz/<site>/devices/state`` (and, at start, the alert service's ``alerts/active`` answer, for
the state it missed) and keeps

- the sign at ``WZ_SIGN_HOST:WZ_SIGN_PORT`` showing its ``sign_text``: words filled into the
  face's lines (``WZ_SIGN_LINES`` x ``WZ_SIGN_CHARS``, pages as needed), put on with
  :class:`~wz_drivers.dms.DmsClient`;
- if ``WZ_BEACON_HOST`` is set, the beacon's relay (coil ``WZ_BEACON_COIL`` of unit
  ``WZ_BEACON_UNIT`` of the Modbus TCP I/O module at ``WZ_BEACON_HOST:WZ_BEACON_PORT``) closed
  while ``beacon_on``: the beacon's own flasher flashes it while the relay is closed
  (:mod:`wz_drivers.beacon`).

Only the newest state counts: states that arrive while a device is being talked to are
skipped for the last.

The devices are a separate process's business on purpose: one that does not answer delays
nothing but this driver, and within it nothing but itself (each is talked to in a thread of
its own, :class:`~wz_drivers.field_device.DeviceWorker`). Each is tried again every
``WZ_SIGN_RETRY_S`` and read back every ``WZ_SIGN_CHECK_S`` (a sign restarted by its own
controller comes back blank, a relay module power-cycled comes back open: they are set again),
and its link is in the status (``devices["dynamic-message-sign"]``,
``devices["flashing-beacon"]``: reachable or not, why, what the device said it shows, how long
since it answered). A device it cannot reach makes its state ``degraded``; the gateway shows
that device's ``device_status`` as ``error`` in the WZDx device feed.
"""

from __future__ import annotations

import logging
import time
from typing import Annotated, Any

from pydantic import Field, field_validator
from pydantic_settings import SettingsConfigDict

from wz_drivers.beacon import BeaconClient, BeaconSettings
from wz_drivers.dms import DmsClient, SignSettings
from wz_drivers.field_device import DeviceWorker, FieldDevice
from wz_drivers.ntcip1203 import multi_to_text, text_to_multi
from wz_shared.messages import BEACON_DEVICE, SIGN_DEVICE, ActiveAlerts, RoadsideDeviceState
from wz_shared.service import NodeApp, ServiceRuntime
from wz_shared.settings import ServiceSettings

SERVICE = "device-driver"
#: At stop, how long to wait for each device's thread to end its exchange [s].
STOP_WAIT_S = 3.0
log = logging.getLogger("wz_drivers.device_driver")


class DeviceDriverSettings(ServiceSettings):
    """``WZ_SIGN_*``: where the sign is and how big its face is; ``WZ_BEACON_*``: where the
    beacon's relay is (none if ``WZ_BEACON_HOST`` is unset or empty)."""

    model_config = SettingsConfigDict(env_prefix="WZ_SIGN_", extra="ignore")

    host: Annotated[str, Field(min_length=1, max_length=253)]
    port: Annotated[int, Field(ge=1, le=65535)] = 161
    read_community: Annotated[str, Field(min_length=1, max_length=64)] = "public"
    write_community: Annotated[str, Field(min_length=1, max_length=64)] = "administrator"
    #: A portable changeable message sign: 3 lines of 8 characters (NCHRP/MUTCD PCMS).
    lines: Annotated[int, Field(ge=1, le=16)] = 3
    chars: Annotated[int, Field(ge=1, le=64)] = 8
    timeout_s: Annotated[float, Field(gt=0.0, le=10.0)] = 0.4
    retries: Annotated[int, Field(ge=0, le=5)] = 1
    #: After a failed exchange, the next try [s] (the sign's and the beacon's).
    retry_s: Annotated[float, Field(gt=0.0, le=600.0)] = 1.0
    #: What the sign shows and the beacon's relay are read back this often [s].
    check_s: Annotated[float, Field(gt=0.0, le=3600.0)] = 5.0
    #: The Modbus TCP I/O module switching the beacon; None: no beacon driven.
    beacon_host: Annotated[str | None, Field(max_length=253, validation_alias="WZ_BEACON_HOST")] = (
        None
    )
    beacon_port: Annotated[int, Field(ge=1, le=65535, validation_alias="WZ_BEACON_PORT")] = 502
    #: Its unit identifier (Modbus device id; a serial module's address behind a gateway).
    beacon_unit: Annotated[int, Field(ge=0, le=255, validation_alias="WZ_BEACON_UNIT")] = 1
    #: The coil (relay output) the beacon is wired to, from 0 as on the wire.
    beacon_coil: Annotated[int, Field(ge=0, le=65535, validation_alias="WZ_BEACON_COIL")] = 0
    #: One Modbus request's timeout [s] (2 tries): the module is on the trailer's network.
    beacon_timeout_s: Annotated[
        float, Field(gt=0.0, le=10.0, validation_alias="WZ_BEACON_TIMEOUT_S")
    ] = 0.4

    @field_validator("beacon_host", mode="before")
    @classmethod
    def _no_beacon_if_empty(cls, value: object) -> object:
        return None if isinstance(value, str) and not value.strip() else value


class SignDriver(FieldDevice[str]):
    """Keeps one sign showing the wanted message (MULTI); no bus (the node feeds it)."""

    kind = "sign"

    def __init__(self, settings: DeviceDriverSettings, client: DmsClient) -> None:
        super().__init__(client.settings.address, settings.retry_s, settings.check_s)
        self.settings = settings
        self.client = client

    def want(self, text: str) -> None:
        """Ask for ``text`` (the alert service's sign text; empty: blank)."""
        chars, lines = self.settings.chars, self.settings.lines
        try:
            multi = text_to_multi(text, chars, lines)
        except ValueError as exc:  # a word wider than the face: shown cut, and said
            log.error("%r on a %d x %d sign: %s; words cut to %d", text, lines, chars, exc, chars)
            multi = text_to_multi(" ".join(w[:chars] for w in text.split()), chars, lines)
        super().want(multi)

    def _put(self, value: str) -> str:
        return self.client.show(value)

    def _get(self) -> str:
        return self.client.showing()

    def describe(self, value: str) -> str:
        return multi_to_text(value)

    def close(self) -> None:
        self.client.close()


class BeaconDriver(FieldDevice[bool]):
    """Keeps the beacon's relay closed (flashing) or open as wanted; no bus.

    The read-back every ``check_s`` finds a module that was power-cycled (its relays come
    back open) or switched by hand, and sets the relay again.
    """

    kind = "beacon relay"

    def __init__(self, settings: DeviceDriverSettings, client: BeaconClient) -> None:
        super().__init__(client.address, settings.retry_s, settings.check_s)
        self.client = client

    def _put(self, value: bool) -> bool:
        return self.client.set_relay(value)

    def _get(self) -> bool:
        return self.client.relay()

    def describe(self, value: bool) -> str:
        return "on" if value else "off"

    def close(self) -> None:
        self.client.close()


def sign_settings(settings: DeviceDriverSettings) -> SignSettings:
    """The SNMP client's settings of the service's ``WZ_SIGN_*``."""
    return SignSettings(
        host=settings.host,
        port=settings.port,
        read_community=settings.read_community,
        write_community=settings.write_community,
        timeout_s=settings.timeout_s,
        retries=settings.retries,
    )


def beacon_settings(settings: DeviceDriverSettings) -> BeaconSettings | None:
    """The Modbus client's settings of the service's ``WZ_BEACON_*``; None: no beacon."""
    if settings.beacon_host is None:
        return None
    return BeaconSettings(
        host=settings.beacon_host,
        port=settings.beacon_port,
        unit=settings.beacon_unit,
        coil=settings.beacon_coil,
        timeout_s=settings.beacon_timeout_s,
    )


def run(runtime: ServiceRuntime, settings: DeviceDriverSettings) -> int:
    """Drive the sign (and the beacon's relay, if set) until ``runtime.stop``; the number of
    changes put on them.

    Each device is talked to in a thread of its own (:class:`DeviceWorker`): this loop only
    follows the bus, hands each device the newest wish and reports their links, so a device
    that does not answer delays neither the other nor the status.
    """
    bus = runtime.bus
    states = bus.subscribe(bus.keys.devices_state, RoadsideDeviceState, capacity=64)
    sign_config = sign_settings(settings)
    sign = DeviceWorker(
        SIGN_DEVICE,
        sign_config.address,
        lambda: SignDriver(settings, DmsClient(sign_config)),
        runtime.stop,
    )
    workers: list[DeviceWorker[Any]] = [sign]
    beacon: DeviceWorker[bool] | None = None
    beacon_config = beacon_settings(settings)
    if beacon_config is not None:
        beacon = DeviceWorker(
            BEACON_DEVICE,
            beacon_config.address,
            lambda: BeaconDriver(settings, BeaconClient(beacon_config)),
            runtime.stop,
        )
        workers.append(beacon)
    for worker in workers:
        worker.start()
    known = False  # a state arrived (or the alert service answered)
    next_ask = 0.0
    try:
        while not runtime.stop.is_set():
            newest = states.recv(0.05)
            for later in states.drain():
                newest = later
            now = time.monotonic()
            if newest is None and not known and now >= next_ask:
                # Joined late (or before the alert service): ask it what the devices show now.
                joined = bus.query(bus.keys.alerts_active, ActiveAlerts, timeout_s=0.5)
                newest = joined[0].devices if joined else None
                next_ask = now + settings.check_s
            if newest is not None:
                known = True
                sign.want(newest.sign_text)
                if beacon is not None:
                    beacon.want(newest.beacon_on)
            now = time.monotonic()
            runtime.devices = {worker.name: worker.link(now) for worker in workers}
            runtime.beat(processed=newest is not None)
    finally:
        runtime.stop.set()  # also when this loop failed: the workers end with it
        for worker in workers:
            worker.join(STOP_WAIT_S)
    return sum(worker.changes for worker in workers)


def main() -> None:
    node = NodeApp(SERVICE, DeviceDriverSettings)
    node.load_site()
    # pymodbus logs every unanswered request, with the last frames; the driver says once
    # when the relay module stops (and starts again) answering, and the status says why.
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    changes = node.serve(lambda runtime: run(runtime, node.settings), sim_clock=False)
    log.info("stopped after %d changes of the sign and the beacon", changes)


if __name__ == "__main__":
    main()
