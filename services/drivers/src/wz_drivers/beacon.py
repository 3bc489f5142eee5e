"""The flashing beacon's relay over Modbus TCP: one coil of an industrial I/O module (pymodbus).

A work-zone flashing beacon is usually a lamp with its own flasher: it flashes for as long as
its supply is switched on. The trailer switches it with a relay output of a Modbus TCP I/O
module, and that relay is a *coil* (Modbus data model: a read-write bit): **coil on = relay
closed = the beacon flashes**, off = dark. Which coil and which unit (the Modbus "slave" or
device id, for modules behind a gateway) are settings.

:class:`BeaconClient` writes the coil (function 5, *write single coil*) and reads it back
(function 1, *read coils*) so that what is reported is what the module says. Every exchange
has a timeout; a module that does not answer, or answers with a Modbus exception (no such
coil, no such unit behind a gateway), raises :class:`BeaconError` with what happened in words.
"""

from __future__ import annotations

import socket
from collections.abc import Callable
from dataclasses import dataclass

from pymodbus.client import ModbusTcpClient
from pymodbus.exceptions import ConnectionException, ModbusException
from pymodbus.pdu import ModbusPDU

from wz_drivers.field_device import DeviceError

#: Modbus exception codes (Modbus Application Protocol v1.1b3, section 7) in words.
EXCEPTION_CODES = {
    0x01: "illegal function: the module has no coils",
    0x02: "illegal data address: no such coil",
    0x03: "illegal data value",
    0x04: "server device failure",
    0x05: "acknowledge: still working on it",
    0x06: "server device busy",
    0x08: "memory parity error",
    0x0A: "gateway path unavailable: no such unit behind the gateway",
    0x0B: "gateway target device failed to respond: no such unit, or it is off",
}


class BeaconError(DeviceError):
    """The relay module did not answer (``answered`` False), or refused (the message says
    which exception, in words)."""


@dataclass(frozen=True)
class BeaconSettings:
    """Where the beacon's relay is and how long to wait for it.

    Attributes
    ----------
    host, port : str, int
        The I/O module's Modbus TCP server (port 502 by the standard).
    unit : int
        Its unit identifier (device id): 1 for most modules; the serial device's address for
        one behind a Modbus TCP gateway.
    coil : int
        The coil (relay output) the beacon is wired to, from 0 as on the wire (a manual's
        "coil 00001" or "DO 1" is usually 0).
    timeout_s, retries : float, int
        One request's timeout [s] and its retries. The module is on the trailer's network: it
        answers in milliseconds; two tries of 0.4 s keep a dead one under ~1 s an exchange.
    """

    host: str
    port: int = 502
    unit: int = 1
    coil: int = 0
    timeout_s: float = 0.4
    retries: int = 1

    def __post_init__(self) -> None:
        if not self.host:
            raise ValueError("the beacon's relay module needs a host")
        for name, value, low, high in (
            ("port", self.port, 1, 65535),
            ("unit", self.unit, 0, 255),
            ("coil", self.coil, 0, 65535),
            ("retries", self.retries, 0, 10),
        ):
            if not low <= value <= high:
                raise ValueError(f"beacon {name} {value} is not within {low} to {high}")
        if not 0.0 < self.timeout_s <= 30.0:
            raise ValueError(f"beacon timeout {self.timeout_s} s is not within 0 to 30 s")

    @property
    def address(self) -> str:
        return f"tcp {self.host}:{self.port} unit {self.unit} coil {self.coil}"


class _TcpClient(ModbusTcpClient):
    """pymodbus's synchronous TCP client, keeping why the last connection failed (pymodbus
    only logs it)."""

    connect_error: OSError | None = None

    def connect(self) -> bool:
        if self.socket is None:
            params = self.comm_params
            try:
                self.socket = socket.create_connection(
                    (str(params.host), int(params.port)), timeout=params.timeout_connect
                )
            except OSError as exc:
                self.connect_error = exc
                return False
        return True


class BeaconClient:
    """Switches the beacon's relay (one coil) and reads it back; synchronous.

    One TCP connection, opened at the first exchange and kept; after an exchange that got no
    answer it is closed, so that the next one starts clean (no late answer mistaken for its
    own).
    """

    def __init__(self, settings: BeaconSettings) -> None:
        self.settings = settings
        self._client = _TcpClient(
            settings.host,
            port=settings.port,
            timeout=settings.timeout_s,
            retries=settings.retries,
            name="beacon",
        )

    @property
    def address(self) -> str:
        return self.settings.address

    def close(self) -> None:
        self._client.close()

    def set_relay(self, on: bool) -> bool:
        """Close (``on``: the beacon flashes) or open the relay; what it then reads back.

        Raises
        ------
        BeaconError
            No answer (no connection, timeout), a Modbus exception, or a coil that reads back
            otherwise than written (an output forced by hand, or one the module ignores).
        """
        s = self.settings
        self._exchange("write", lambda: self._client.write_coil(s.coil, on, device_id=s.unit))
        now = self.relay()
        if now != on:
            raise BeaconError(
                f"{self.address}: wrote {_word(on)}, reads back {_word(now)} "
                "(output forced or not driven by Modbus?)"
            )
        return now

    def relay(self) -> bool:
        """Whether the relay is closed (the beacon flashes), as the module says.

        Raises
        ------
        BeaconError
            No answer, a Modbus exception, or an answer without the coil.
        """
        s = self.settings
        response = self._exchange(
            "read", lambda: self._client.read_coils(s.coil, count=1, device_id=s.unit)
        )
        bits = getattr(response, "bits", None)
        if not bits:
            raise BeaconError(f"{self.address}: the read of the coil came back without it")
        return bool(bits[0])

    def _exchange(self, what: str, request: Callable[[], ModbusPDU]) -> ModbusPDU:
        s = self.settings
        try:
            response = request()
        except ConnectionException:
            self._client.close()
            why = self._client.connect_error
            self._client.connect_error = None
            reason = "the module closed it" if why is None else _reason(why)
            raise BeaconError(f"{self.address}: no connection ({reason})", answered=False) from None
        except OSError as exc:  # the connection reset under the exchange
            self._client.close()
            raise BeaconError(
                f"{self.address}: no connection ({_reason(exc)})", answered=False
            ) from None
        except ModbusException as exc:  # no answer in time (pymodbus: ModbusIOException)
            self._client.close()
            tries = s.retries + 1
            raise BeaconError(
                f"{self.address}: timeout, no answer to the {what} in {tries} x {s.timeout_s:g} s",
                answered=False,
            ) from exc
        if response.isError():
            code = int(getattr(response, "exception_code", 0))
            words = EXCEPTION_CODES.get(code, "unknown exception")
            raise BeaconError(f"{self.address}: {what} refused: Modbus exception {code}, {words}")
        return response


def _reason(exc: OSError) -> str:
    if isinstance(exc, TimeoutError):
        return "timeout connecting"
    return exc.strerror or str(exc)


def _word(on: bool) -> str:
    return "on" if on else "off"
