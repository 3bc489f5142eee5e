"""A portable message sign as an SNMP agent: NTCIP 1203 on UDP, for the bench and the tests.

``python -m wz_drivers.sign_sim --port 1161`` answers SNMPv1/v2c GET, GETNEXT, GETBULK and SET
(community ``public`` reads, ``administrator`` writes, as NTCIP signs ship) on the objects of
:mod:`wz_drivers.ntcip1203`, and behaves as a sign does: a changeable row is written only
while ``modifying``, validated against the face's size (``--lines`` x ``--chars``, pages up to
``--pages``), given its CRC; an activation with a wrong CRC or of a row not ``valid`` is
refused with ``genErr`` and ``dmsActivateMsgError`` says why; an accepted one puts the row in
the current buffer (memory type 5, number 1) and ``dmsMsgTableSource``. Each change of the
face is logged (``showing 'SLOW[nl]DOWN'``) with the wall-clock time, for a technician's
bench and for the tests' timing.

It is the sign's side only; :mod:`wz_drivers.dms` is the central system's.
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import time
from typing import Any

from pysnmp.carrier.asyncio.dgram import udp
from pysnmp.entity import config, engine
from pysnmp.entity.rfc3413 import cmdrsp, context
from pysnmp.proto import rfc1902, rfc1905
from pysnmp.smi import error as smi_error
from pysnmp.smi.instrum import AbstractMibInstrumController

from wz_drivers.ntcip1203 import (
    ACTIVATE_MESSAGE,
    ACTIVATE_MSG_ERROR,
    CONTROL_CENTRAL,
    CONTROL_MODE,
    MAX_CHANGEABLE,
    MESSAGE_ENTRY,
    MSG_TABLE_SOURCE,
    MULTI_SYNTAX_ERROR,
    NUM_CHANGEABLE,
    SYS_DESCR,
    ActivateError,
    ActivationCode,
    Column,
    MemoryType,
    MessageStatus,
    MultiError,
    check_multi,
    message_crc,
    message_id_code,
    message_oid,
)

log = logging.getLogger("wz_drivers.sign_sim")

Oid = tuple[int, ...]
#: The security names of the two communities (write access is checked here by name: the
#: SETs' checks are this controller's own).
READER, WRITER = "reader", "writer"
_OCTETS = (Column.MULTI, Column.OWNER)
_WRITABLE = (Column.MULTI, Column.OWNER, Column.BEACON, Column.PIXEL_SERVICE, Column.PRIORITY)


class SignModel:
    """The sign's state and rules, no SNMP: values are ``int`` or ``bytes`` by OID."""

    def __init__(self, lines: int, chars: int, pages: int, changeable: int) -> None:
        self.lines, self.chars, self.pages = lines, chars, pages
        self.changeable = changeable
        self.values: dict[Oid, int | bytes] = {
            SYS_DESCR: f"wz sign simulator: NTCIP 1203 DMS, {lines} x {chars}".encode(),
            NUM_CHANGEABLE: 0,
            MAX_CHANGEABLE: changeable,
            CONTROL_MODE: CONTROL_CENTRAL,
            ACTIVATE_MESSAGE: ActivationCode(MemoryType.BLANK, 1, 0).encode(),
            MSG_TABLE_SOURCE: message_id_code(MemoryType.BLANK, 1, 0),
            ACTIVATE_MSG_ERROR: int(ActivateError.NONE),
            MULTI_SYNTAX_ERROR: int(MultiError.NONE),
        }
        for number in range(1, changeable + 1):
            self._set_row(MemoryType.CHANGEABLE, number, b"", MessageStatus.NOT_USED)
        self._set_row(MemoryType.CURRENT_BUFFER, 1, b"", MessageStatus.VALID)
        self.changes = 0

    def _set_row(self, memory: MemoryType, number: int, multi: bytes, status: int) -> None:
        for column, value in (
            (Column.MULTI, multi),
            (Column.OWNER, b""),
            (Column.CRC, message_crc(multi.decode("ascii"))),
            (Column.BEACON, 0),
            (Column.PIXEL_SERVICE, 0),
            (Column.PRIORITY, 255),
            (Column.STATUS, int(status)),
        ):
            self.values[message_oid(column, memory, number)] = value

    def showing(self) -> str:
        """The MULTI string on the face now (empty: blank)."""
        value = self.values[message_oid(Column.MULTI, MemoryType.CURRENT_BUFFER, 1)]
        return value.decode("ascii") if isinstance(value, bytes) else ""

    # --- SET ------------------------------------------------------------------------------

    def check_write(self, oid: Oid, value: int | bytes) -> None:
        """Raise the SMI error a sign answers for writing ``value`` to ``oid`` (phase 1)."""
        if oid == ACTIVATE_MESSAGE:
            if not isinstance(value, bytes):
                raise smi_error.WrongTypeError()
            return
        row = self._row(oid)
        if row is None or oid not in self.values:
            raise smi_error.NotWritableError()
        column, memory, number = row
        if memory != MemoryType.CHANGEABLE:
            raise smi_error.NotWritableError()
        if (column in _OCTETS) != isinstance(value, bytes):
            raise smi_error.WrongTypeError()
        if column == Column.STATUS:
            if value not in (
                MessageStatus.MODIFY_REQ,
                MessageStatus.VALIDATE_REQ,
                MessageStatus.NOT_USED_REQ,
            ):
                raise smi_error.WrongValueError()
        elif column in _WRITABLE:
            status = self.values[message_oid(Column.STATUS, memory, number)]
            if status != MessageStatus.MODIFYING:
                raise smi_error.InconsistentValueError()  # a row is written only while modifying
        else:
            raise smi_error.NotWritableError()

    def write(self, oid: Oid, value: int | bytes) -> None:
        """Apply a write :meth:`check_write` accepted (phase 2); activation errors raise."""
        if oid == ACTIVATE_MESSAGE:
            self._activate(value if isinstance(value, bytes) else b"")
            return
        row = self._row(oid)
        assert row is not None
        column, memory, number = row
        if column != Column.STATUS:
            self.values[oid] = value
            return
        status_oid = message_oid(Column.STATUS, memory, number)
        if value == MessageStatus.MODIFY_REQ:
            self.values[status_oid] = int(MessageStatus.MODIFYING)
        elif value == MessageStatus.NOT_USED_REQ:
            self._set_row(memory, number, b"", MessageStatus.NOT_USED)
        elif value == MessageStatus.VALIDATE_REQ:
            self._validate(memory, number)
        self.values[NUM_CHANGEABLE] = sum(
            1
            for n in range(1, self.changeable + 1)
            if self.values[message_oid(Column.STATUS, MemoryType.CHANGEABLE, n)]
            != MessageStatus.NOT_USED
        )

    def _validate(self, memory: MemoryType, number: int) -> None:
        multi = self.values[message_oid(Column.MULTI, memory, number)]
        assert isinstance(multi, bytes)
        try:
            text = multi.decode("ascii")
        except UnicodeDecodeError:
            verdict = MultiError.OTHER
        else:
            verdict = check_multi(text, self.chars, self.lines, self.pages)
        self.values[MULTI_SYNTAX_ERROR] = int(verdict)
        ok = verdict == MultiError.NONE
        self.values[message_oid(Column.STATUS, memory, number)] = int(
            MessageStatus.VALID if ok else MessageStatus.ERROR
        )
        if ok:
            beacon = self.values[message_oid(Column.BEACON, memory, number)]
            pixel = self.values[message_oid(Column.PIXEL_SERVICE, memory, number)]
            assert isinstance(beacon, int) and isinstance(pixel, int)
            self.values[message_oid(Column.CRC, memory, number)] = message_crc(text, beacon, pixel)

    def _activate(self, data: bytes) -> None:
        try:
            code = ActivationCode.decode(data)
        except ValueError:
            self._refuse(ActivateError.OTHER)
        if code.memory == MemoryType.BLANK:
            self._show(MemoryType.BLANK, code.number, b"", 0)
            return
        if code.memory != MemoryType.CHANGEABLE:
            self._refuse(ActivateError.MESSAGE_MEMORY_TYPE)
        if not 1 <= code.number <= self.changeable:
            self._refuse(ActivateError.MESSAGE_NUMBER)
        if self.values[message_oid(Column.STATUS, code.memory, code.number)] != MessageStatus.VALID:
            self._refuse(ActivateError.MESSAGE_STATUS)
        crc = self.values[message_oid(Column.CRC, code.memory, code.number)]
        if crc != code.crc:
            self._refuse(ActivateError.MESSAGE_CRC)
        multi = self.values[message_oid(Column.MULTI, code.memory, code.number)]
        assert isinstance(multi, bytes) and isinstance(crc, int)
        self.values[ACTIVATE_MESSAGE] = data
        self._show(code.memory, code.number, multi, crc)

    def _refuse(self, why: ActivateError) -> None:
        self.values[ACTIVATE_MSG_ERROR] = int(why)
        log.warning("activation refused: %s", why.name)
        raise smi_error.GenError()

    def _show(self, memory: MemoryType, number: int, multi: bytes, crc: int) -> None:
        self.values[ACTIVATE_MSG_ERROR] = int(ActivateError.NONE)
        self.values[MSG_TABLE_SOURCE] = message_id_code(memory, number, crc)
        self._set_row(MemoryType.CURRENT_BUFFER, 1, multi, MessageStatus.VALID)
        self.changes += 1
        sys.stdout.write(f"showing {multi.decode('ascii')!r} at {time.time():.3f}\n")
        sys.stdout.flush()

    @staticmethod
    def _row(oid: Oid) -> tuple[Column, MemoryType, int] | None:
        n = len(MESSAGE_ENTRY)
        if len(oid) != n + 3 or oid[:n] != MESSAGE_ENTRY:
            return None
        try:
            return Column(oid[n]), MemoryType(oid[n + 1]), oid[n + 2]
        except ValueError:
            return None


class SignInstrumentation(AbstractMibInstrumController):  # type: ignore[misc]
    """The pysnmp command responders' view of a :class:`SignModel`."""

    def __init__(self, model: SignModel) -> None:
        self.model = model

    def _encode(self, value: int | bytes) -> Any:
        return rfc1902.OctetString(value) if isinstance(value, bytes) else rfc1902.Integer32(value)

    def read_variables(self, *var_binds: Any, **ctx: Any) -> list[Any]:
        out = []
        for name, _ in var_binds:
            oid: Oid = tuple(name)
            value = self.model.values.get(oid)
            out.append((name, rfc1905.noSuchInstance if value is None else self._encode(value)))
        return out

    def read_next_variables(self, *var_binds: Any, **ctx: Any) -> list[Any]:
        out = []
        ordered = sorted(self.model.values)
        for name, _ in var_binds:
            after = [oid for oid in ordered if oid > tuple(name)]
            if not after:
                out.append((name, rfc1905.endOfMibView))
            else:
                oid = after[0]
                out.append((rfc1902.ObjectName(oid), self._encode(self.model.values[oid])))
        return out

    def write_variables(self, *var_binds: Any, **ctx: Any) -> list[Any]:
        checked: list[tuple[Oid, int | bytes]] = []
        engine_ = ctx["snmpEngine"]
        request = engine_.observer.get_execution_context("rfc3412.receiveMessage:request")
        writer = bytes(request["securityName"]) == WRITER.encode()
        for idx, (name, value) in enumerate(var_binds):
            if not writer:  # the read community may not write
                raise smi_error.NoAccessError(name=name, idx=idx)
            oid = tuple(name)
            raw: int | bytes = value.asOctets() if hasattr(value, "asOctets") else int(value)
            try:
                self.model.check_write(oid, raw)
            except smi_error.SmiError as exc:
                exc.update({"name": name, "idx": idx})
                raise
            checked.append((oid, raw))
        # Row writes first, then requests on the status, then the activation: a SET carrying
        # a row and its validateReq validates what it wrote.
        order: dict[Oid, int] = {ACTIVATE_MESSAGE: 2}
        for oid, raw in sorted(
            checked, key=lambda c: order.get(c[0], 1 if self._is_status(c[0]) else 0)
        ):
            self.model.write(oid, raw)
        return list(var_binds)

    @staticmethod
    def _is_status(oid: Oid) -> bool:
        return len(oid) == len(MESSAGE_ENTRY) + 3 and oid[len(MESSAGE_ENTRY)] == Column.STATUS


def serve(model: SignModel, host: str, port: int, read: str, write: str) -> None:
    """Answer SNMP on ``host:port`` until SIGTERM or SIGINT."""
    snmp = engine.SnmpEngine()
    config.add_transport(snmp, udp.DOMAIN_NAME, udp.UdpTransport().open_server_mode((host, port)))
    config.add_v1_system(snmp, READER, read)
    config.add_v1_system(snmp, WRITER, write)
    for model_id in (1, 2):  # SNMPv1 and v2c
        config.add_vacm_user(snmp, model_id, READER, "noAuthNoPriv", (1, 3, 6))
        config.add_vacm_user(snmp, model_id, WRITER, "noAuthNoPriv", (1, 3, 6), (1, 3, 6))
    snmp_context = context.SnmpContext(snmp)
    snmp_context.unregister_context_name(b"")
    snmp_context.register_context_name(b"", SignInstrumentation(model))
    for responder in (
        cmdrsp.GetCommandResponder,
        cmdrsp.SetCommandResponder,
        cmdrsp.NextCommandResponder,
        cmdrsp.BulkCommandResponder,
    ):
        responder(snmp, snmp_context)
    dispatcher = snmp.transport_dispatcher
    dispatcher.job_started(1)

    def stop(*_: object) -> None:
        dispatcher.job_finished(1)
        dispatcher.loop.call_soon_threadsafe(dispatcher.loop.stop)

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    sys.stdout.write(f"NTCIP 1203 sign listening on udp {host}:{port}\n")
    sys.stdout.flush()
    try:
        dispatcher.run_dispatcher()
    finally:
        dispatcher.close_dispatcher()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m wz_drivers.sign_sim", description=__doc__.split("\n")[0]
    )
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, default=161)
    parser.add_argument("--lines", type=int, default=3, help="lines per page")
    parser.add_argument("--chars", type=int, default=8, help="characters per line")
    parser.add_argument("--pages", type=int, default=2, help="pages per message")
    parser.add_argument("--changeable", type=int, default=10, help="changeable messages")
    parser.add_argument("--read-community", default="public")
    parser.add_argument("--write-community", default="administrator")
    args = parser.parse_args(argv)
    for name in ("lines", "chars", "pages", "changeable"):
        if not 1 <= getattr(args, name) <= 255:
            parser.error(f"--{name} must be 1 to 255")
    if not 0 < args.port < 65536:
        parser.error("--port must be 1 to 65535")
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    model = SignModel(args.lines, args.chars, args.pages, args.changeable)
    try:
        serve(model, args.host, args.port, args.read_community, args.write_community)
    except OSError as exc:
        parser.exit(1, f"cannot listen on udp {args.host}:{args.port}: {exc}\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
