"""The central system's side of NTCIP 1203: put a message on a sign over SNMP (pysnmp).

:class:`DmsClient` keeps one SNMP engine and event loop and does, for each message, the
standard's sequence (:mod:`wz_drivers.ntcip1203`): ``modifyReq`` on its changeable row; the
MULTI string, owner, priority, beacon and pixel service written with ``validateReq`` in one
SET; the row's status and CRC read back; the activation code with that CRC set on
``dmsActivateMessage``; ``dmsMsgTableSource`` and the current buffer read back, so that what
is reported as shown is what the sign says it shows. A blank sign is an activation of the
``blank`` memory type. Every exchange has a timeout; nothing waits on an absent sign for long.
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass
from typing import Any

from pysnmp.hlapi.v3arch.asyncio import (
    CommunityData,
    ContextData,
    ObjectIdentity,
    ObjectType,
    SnmpEngine,
    UdpTransportTarget,
    get_cmd,
    set_cmd,
)
from pysnmp.proto import rfc1902, rfc1905

from wz_drivers.field_device import DeviceError
from wz_drivers.ntcip1203 import (
    ACTIVATE_MESSAGE,
    ACTIVATE_MSG_ERROR,
    MSG_TABLE_SOURCE,
    MULTI_SYNTAX_ERROR,
    ActivateError,
    ActivationCode,
    Column,
    MemoryType,
    MessageStatus,
    MultiError,
    message_crc,
    message_oid,
    parse_message_id_code,
)

_ABSENT = (rfc1905.noSuchObject.tagSet, rfc1905.noSuchInstance.tagSet, rfc1905.endOfMibView.tagSet)


class SignError(DeviceError):
    """The sign did not answer (``answered`` False), or refused a step (the message says
    which and why)."""


@dataclass(frozen=True)
class SignSettings:
    host: str
    port: int = 161
    read_community: str = "public"
    write_community: str = "administrator"
    #: One SNMP request's timeout [s] and retries: a sign on a cellular modem answers in
    #: ~100-300 ms; two tries of 0.4 s keep a whole change under ~2 s when it is gone.
    timeout_s: float = 0.4
    retries: int = 1
    #: The changeable row this system owns.
    message_number: int = 1
    owner: str = "wz device-driver"
    priority: int = 255

    @property
    def address(self) -> str:
        return f"udp {self.host}:{self.port}"


class DmsClient:
    """Synchronous front of an asyncio SNMP manager (one engine, one loop, reused)."""

    def __init__(self, settings: SignSettings) -> None:
        self.settings = settings
        self._loop = asyncio.new_event_loop()
        self._engine = SnmpEngine()
        self._target: Any = None

    def close(self) -> None:
        try:
            self._engine.close_dispatcher()
            pending = asyncio.all_tasks(self._loop)  # the dispatcher's timer task
            for task in pending:
                task.cancel()
            self._loop.run_until_complete(asyncio.gather(*pending, return_exceptions=True))
        finally:
            self._loop.close()

    def _run(self, coroutine: Any) -> Any:
        return self._loop.run_until_complete(coroutine)

    async def _transport(self) -> Any:
        if self._target is None:
            s = self.settings
            self._target = await UdpTransportTarget.create(
                (s.host, s.port), timeout=s.timeout_s, retries=s.retries
            )
        return self._target

    async def _get(self, *oids: tuple[int, ...]) -> list[Any]:
        target = await self._transport()
        error, status, index, binds = await get_cmd(
            self._engine,
            CommunityData(self.settings.read_community, mpModel=1),
            target,
            ContextData(),
            *(ObjectType(ObjectIdentity(oid)) for oid in oids),
            lookupMib=False,
        )
        self._check(error, status, index, "GET")
        values = [value for _, value in binds]
        missing = [oid for oid, v in zip(oids, values, strict=True) if v.tagSet in _ABSENT]
        if missing:
            raise SignError(f"{self.settings.address}: the sign has no object {missing[0]}")
        return values

    async def _set(self, *binds: tuple[tuple[int, ...], Any]) -> None:
        target = await self._transport()
        error, status, index, _ = await set_cmd(
            self._engine,
            CommunityData(self.settings.write_community, mpModel=1),
            target,
            ContextData(),
            *(ObjectType(ObjectIdentity(oid), value) for oid, value in binds),
            lookupMib=False,
        )
        self._check(error, status, index, "SET")

    def _check(self, error: Any, status: Any, index: Any, what: str) -> None:
        if error:
            raise SignError(f"{self.settings.address}: {error}", answered=False)
        if status:
            raise SignError(
                f"{self.settings.address}: {what} refused: {status.prettyPrint()} at "
                f"variable {int(index)}"
            )

    # --- the sequence -------------------------------------------------------------------------

    def show(self, multi: str) -> str:
        """Put ``multi`` on the sign (empty: blank it); returns what the sign then shows.

        Raises
        ------
        SignError
            No answer (timeout), or the sign refused a step (its reason read back).
        """
        return str(self._run(self._show(multi)))

    def showing(self) -> str:
        """The MULTI string the sign shows now (its current buffer); raises SignError."""
        return str(self._run(self._showing()))

    async def _showing(self) -> str:
        (multi,) = await self._get(message_oid(Column.MULTI, MemoryType.CURRENT_BUFFER, 1))
        return bytes(multi.asOctets()).decode("ascii", errors="replace")

    async def _show(self, multi: str) -> str:
        s = self.settings
        if not multi:
            code = ActivationCode(MemoryType.BLANK, 1, 0, priority=s.priority)
            await self._activate(code)
            return await self._showing()
        row = (MemoryType.CHANGEABLE, s.message_number)
        await self._set(
            (message_oid(Column.STATUS, *row), rfc1902.Integer32(MessageStatus.MODIFY_REQ))
        )
        await self._set(
            (message_oid(Column.MULTI, *row), rfc1902.OctetString(multi.encode("ascii"))),
            (message_oid(Column.OWNER, *row), rfc1902.OctetString(s.owner.encode("ascii"))),
            (message_oid(Column.PRIORITY, *row), rfc1902.Integer32(s.priority)),
            (message_oid(Column.BEACON, *row), rfc1902.Integer32(0)),
            (message_oid(Column.PIXEL_SERVICE, *row), rfc1902.Integer32(0)),
            (message_oid(Column.STATUS, *row), rfc1902.Integer32(MessageStatus.VALIDATE_REQ)),
        )
        status, crc = await self._get(
            message_oid(Column.STATUS, *row), message_oid(Column.CRC, *row)
        )
        if int(status) != MessageStatus.VALID:
            (why,) = await self._get(MULTI_SYNTAX_ERROR)
            raise SignError(
                f"{s.address}: the sign finds {multi!r} invalid ({_name(MultiError, why)})"
            )
        expected = message_crc(multi)
        if int(crc) != expected:
            raise SignError(f"{s.address}: CRC {int(crc):#06x} read back, {expected:#06x} computed")
        await self._activate(ActivationCode(*row, int(crc), priority=s.priority))
        (source,) = await self._get(MSG_TABLE_SOURCE)
        memory, number, _ = parse_message_id_code(bytes(source.asOctets()))
        if (memory, number) != row:
            raise SignError(f"{s.address}: the sign shows {memory.name} {number}, not ours")
        return await self._showing()

    async def _activate(self, code: ActivationCode) -> None:
        try:
            await self._set((ACTIVATE_MESSAGE, rfc1902.OctetString(code.encode())))
        except SignError as exc:
            try:
                (why,) = await self._get(ACTIVATE_MSG_ERROR)
            except SignError:
                raise exc from None
            raise SignError(f"{exc} (dmsActivateMsgError {_name(ActivateError, why)})") from None


def _name(kind: Any, value: Any) -> str:
    try:
        return str(kind(int(value)).name)
    except ValueError:
        return str(int(value))
