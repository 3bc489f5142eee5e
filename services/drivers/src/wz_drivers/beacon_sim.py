"""A relay module as a Modbus TCP server, for the bench and the tests: the beacon's relay.

``python -m wz_drivers.beacon_sim --port 1502`` is an industrial I/O module with relay outputs
(``--coils``, 16), answering Modbus TCP with pymodbus's server: read coils (function 1), write
single coil (5), write multiple coils (15). The relay the flashing beacon is wired to
(``--beacon-coil``, 0) is printed on each change, ``beacon on at T`` / ``beacon off at T``
with the wall-clock time, for a technician's bench and for the tests' timing; the other relays
print ``coil N on at T``. It starts with every relay open, as a module does after a power
cycle.

It answers as a module behind a gateway does: a request for another unit gets exception 0x0B
(gateway target device failed to respond), one for a coil it lacks exception 0x02 (illegal
data address). It is the module's side only; :mod:`wz_drivers.beacon` is the driver's.
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import signal
import sys
import time

from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

#: pymodbus's simulator keeps coils in 16-bit words: a module has a multiple of 16.
COILS_PER_WORD = 16
#: The Modbus address space, every coil and register of it (the other units' catch-all).
ADDRESSES = 65536
#: Function codes that write coils: write single coil, write multiple coils.
WRITE_COILS = (5, 15)


class RelayModule:
    """The relays' states, as the writes the server applies leave them; each change printed.

    Parameters
    ----------
    coils : int
        How many relay outputs (coils 0 to ``coils - 1``); a multiple of 16.
    beacon_coil : int
        The one the beacon is wired to.
    """

    def __init__(self, coils: int, beacon_coil: int) -> None:
        if coils < 1 or coils % COILS_PER_WORD:
            raise ValueError(f"{coils} coils: a multiple of {COILS_PER_WORD} is needed")
        if not 0 <= beacon_coil < coils:
            raise ValueError(f"beacon coil {beacon_coil} is not one of coils 0 to {coils - 1}")
        self.closed = [False] * coils
        self.beacon_coil = beacon_coil

    async def on_access(
        self,
        function_code: int,
        start_address: int,
        address: int,
        count: int,
        registers: list[int],
        set_values: list[int] | list[bool] | None,
    ) -> ExcCodes | None:
        """pymodbus's hook on every access the server has checked (address in range): a
        write of coils is noted (the server then applies it); nothing is refused."""
        if function_code in WRITE_COILS and set_values is not None:
            for offset, value in enumerate(set_values):
                self.switch(address + offset, bool(value))
        return None

    def switch(self, coil: int, on: bool) -> None:
        """Relay ``coil`` to ``on``; a change printed with the time."""
        if self.closed[coil] == on:
            return
        self.closed[coil] = on
        state = "on" if on else "off"
        what = "beacon" if coil == self.beacon_coil else f"coil {coil}"
        sys.stdout.write(f"{what} {state} at {time.time():.3f}\n")
        sys.stdout.flush()


async def _no_such_unit(*_access: object) -> ExcCodes | None:
    """pymodbus's hook for any other unit: refused as a gateway refuses an absent device."""
    return ExcCodes.GATEWAY_NO_RESPONSE


#: A device's four tables: coils, discrete inputs, holding and input registers.
Tables = tuple[list[SimData], list[SimData], list[SimData], list[SimData]]


def _tables(coils: int, registers: int) -> Tables:
    """``coils`` coils and discrete inputs, ``registers`` registers of each kind, from 0."""
    return (
        [SimData(0, values=[False] * coils, datatype=DataType.BITS)],
        [SimData(0, values=[False] * coils, datatype=DataType.BITS)],
        [SimData(0, count=registers, datatype=DataType.REGISTERS)],
        [SimData(0, count=registers, datatype=DataType.REGISTERS)],
    )


def devices(module: RelayModule, unit: int) -> list[SimDevice]:
    """The module as unit ``unit``, and every other unit (id 0: pymodbus's catch-all) as a
    gateway's absent device."""
    return [
        SimDevice(unit, simdata=_tables(len(module.closed), 1), action=module.on_access),
        SimDevice(0, simdata=_tables(ADDRESSES, ADDRESSES), action=_no_such_unit),
    ]


async def serve(module: RelayModule, host: str, port: int, unit: int) -> None:
    """Answer Modbus TCP on ``host:port`` until SIGTERM or SIGINT."""
    server = ModbusTcpServer(devices(module, unit), address=(host, port))
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for signum in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(signum, stop.set)
    await server.serve_forever(background=True)
    sys.stdout.write(f"Modbus TCP relay module listening on tcp {host}:{port} unit {unit}\n")
    sys.stdout.flush()
    try:
        await stop.wait()
    finally:
        await server.shutdown()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m wz_drivers.beacon_sim", description=__doc__.split("\n")[0]
    )
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, default=502)
    parser.add_argument("--unit", type=int, default=1, help="its unit id (1 to 247)")
    parser.add_argument("--coils", type=int, default=16, help="relay outputs, a multiple of 16")
    parser.add_argument("--beacon-coil", type=int, default=0, help="the beacon's relay")
    args = parser.parse_args(argv)
    if not 0 < args.port < 65536:
        parser.error("--port must be 1 to 65535")
    if not 1 <= args.unit <= 247:
        parser.error("--unit must be 1 to 247 (0 is broadcast)")
    if not COILS_PER_WORD <= args.coils <= 1024:
        parser.error(f"--coils must be {COILS_PER_WORD} to 1024")
    try:
        module = RelayModule(args.coils, args.beacon_coil)
    except ValueError as exc:
        parser.error(str(exc))
    # pymodbus logs a client that goes away as an error, with the last frames: not news here.
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    try:
        asyncio.run(serve(module, args.host, args.port, args.unit))
    except (OSError, RuntimeError) as exc:  # pymodbus: "Could not start listen"
        parser.exit(1, f"cannot listen on tcp {args.host}:{args.port}: {exc}\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
