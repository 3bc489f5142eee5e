"""NTCIP 1203 (dynamic message signs) as far as a work-zone sign needs it: no I/O.

The objects, under ``dms`` = 1.3.6.1.4.1.1206.4.2.3 (NTCIP 1203 v03):

- ``dmsMessageTable`` (``dms.5.8.1``), indexed by memory type and message number; its columns
  ``dmsMessageMultiString`` (.3), ``dmsMessageOwner`` (.4), ``dmsMessageCRC`` (.5),
  ``dmsMessageBeacon`` (.6), ``dmsMessagePixelService`` (.7), ``dmsMessageRunTimePriority`` (.8)
  and ``dmsMessageStatus`` (.9). Memory types: ``changeable`` (3) rows a central system
  writes, ``currentBuffer`` (5, number 1) the message shown now, ``blank`` (7).
- ``dmsActivateMessage`` (``dms.6.3.0``): a 12-byte MessageActivationCode that puts a
  message on the face; ``dmsMsgTableSource`` (``dms.6.5.0``): the 5-byte MessageIDCode of
  the one shown; ``dmsActivateMsgError`` (``dms.6.17.0``); ``dmsMultiSyntaxError``
  (``dms.6.18.0``); ``dmsControlMode`` (``dms.6.1.0``, ``central`` = 4).

A central system changes the sign in the standard's sequence: ``dmsMessageStatus`` to
``modifyReq`` (the row goes ``modifying``), the MULTI string and its companions written,
``validateReq`` (the sign checks the MULTI and goes ``valid`` or ``error``), the row's CRC
read, and the activation code carrying that CRC set on ``dmsActivateMessage``. A sign
refuses an activation whose CRC is not its row's (``messageCRC``), so a message changed
under the activation is never shown by mistake.

The CRC (``dmsMessageCRC``) is the ISO/IEC 3309 CRC-16 over the MULTI string's octets, the
beacon octet and the pixel-service octet, computed as the IRIS ATMS computes it (reflected
polynomial 0x8408, initial value 0xFFFF, no final inversion; Minnesota DOT's
``us.mn.state.dot.tms.server.comm.ntcip.CRC16``).
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass
from enum import IntEnum

DMS = (1, 3, 6, 1, 4, 1, 1206, 4, 2, 3)
MESSAGE_ENTRY = (*DMS, 5, 8, 1)
SYS_DESCR = (1, 3, 6, 1, 2, 1, 1, 1, 0)
NUM_CHANGEABLE = (*DMS, 5, 3, 0)  # dmsNumChangeableMsg
MAX_CHANGEABLE = (*DMS, 5, 4, 0)  # dmsMaxChangeableMsg
CONTROL_MODE = (*DMS, 6, 1, 0)
ACTIVATE_MESSAGE = (*DMS, 6, 3, 0)
MSG_TABLE_SOURCE = (*DMS, 6, 5, 0)
ACTIVATE_MSG_ERROR = (*DMS, 6, 17, 0)
MULTI_SYNTAX_ERROR = (*DMS, 6, 18, 0)

#: ``dmsControlMode``: the sign takes commands from a central system.
CONTROL_CENTRAL = 4
#: A duration of 65535 minutes on an activation: shown until another replaces it.
INDEFINITE = 0xFFFF


class Column(IntEnum):
    """Columns of ``dmsMessageTable``."""

    MULTI = 3
    OWNER = 4
    CRC = 5
    BEACON = 6
    PIXEL_SERVICE = 7
    PRIORITY = 8
    STATUS = 9


class MemoryType(IntEnum):
    PERMANENT = 2
    CHANGEABLE = 3
    VOLATILE = 4
    CURRENT_BUFFER = 5
    SCHEDULE = 6
    BLANK = 7


class MessageStatus(IntEnum):
    """``dmsMessageStatus``: states of a row, and the requests written to it (6-8)."""

    NOT_USED = 1
    MODIFYING = 2
    VALIDATING = 3
    VALID = 4
    ERROR = 5
    MODIFY_REQ = 6
    VALIDATE_REQ = 7
    NOT_USED_REQ = 8


class ActivateError(IntEnum):
    """``dmsActivateMsgError``."""

    OTHER = 1
    NONE = 2
    PRIORITY = 3
    MESSAGE_STATUS = 4
    MESSAGE_MEMORY_TYPE = 5
    MESSAGE_NUMBER = 6
    MESSAGE_CRC = 7
    SYNTAX_MULTI = 8
    LOCAL_MODE = 9


class MultiError(IntEnum):
    """``dmsMultiSyntaxError`` (the values a work-zone message can meet)."""

    OTHER = 1
    NONE = 2
    UNSUPPORTED_TAG = 3
    UNSUPPORTED_TAG_VALUE = 4
    TEXT_TOO_BIG = 5
    TOO_MANY_PAGES = 12


def message_oid(column: Column, memory: MemoryType, number: int) -> tuple[int, ...]:
    """The instance of ``column`` for the row (``memory``, ``number``)."""
    return (*MESSAGE_ENTRY, int(column), int(memory), number)


def _crc_table() -> list[int]:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0x8408 if crc & 1 else crc >> 1
        table.append(crc)
    return table


_TABLE = _crc_table()


def crc16(data: bytes, crc: int = 0xFFFF) -> int:
    """ISO/IEC 3309 CRC-16, reflected, initial 0xFFFF, no final inversion (module doc)."""
    for byte in data:
        crc = (crc >> 8) ^ _TABLE[(byte ^ crc) & 0xFF]
    return crc


def message_crc(multi: str, beacon: int = 0, pixel_service: int = 0) -> int:
    """``dmsMessageCRC`` of a row: over its MULTI octets, beacon and pixel service."""
    return crc16(multi.encode("ascii") + bytes((beacon & 0xFF, pixel_service & 0xFF)))


@dataclass(frozen=True)
class ActivationCode:
    """``MessageActivationCode``: what ``dmsActivateMessage`` carries (12 octets)."""

    memory: MemoryType
    number: int
    crc: int
    duration_min: int = INDEFINITE
    priority: int = 255
    source_ip: tuple[int, int, int, int] = (127, 0, 0, 1)

    def encode(self) -> bytes:
        return struct.pack(
            ">HBBHH4B",
            self.duration_min,
            self.priority,
            int(self.memory),
            self.number,
            self.crc,
            *self.source_ip,
        )

    @classmethod
    def decode(cls, data: bytes) -> ActivationCode:
        """Raises ValueError unless ``data`` is 12 octets with a known memory type."""
        if len(data) != 12:
            raise ValueError(f"an activation code has 12 octets, not {len(data)}")
        duration, priority, memory, number, crc, *ip = struct.unpack(">HBBHH4B", data)
        a, b, c, d = ip
        return cls(MemoryType(memory), number, crc, duration, priority, (a, b, c, d))


def message_id_code(memory: MemoryType, number: int, crc: int) -> bytes:
    """``MessageIDCode`` (``dmsMsgTableSource``): memory type, number, CRC (5 octets)."""
    return struct.pack(">BHH", int(memory), number, crc)


def parse_message_id_code(data: bytes) -> tuple[MemoryType, int, int]:
    if len(data) != 5:
        raise ValueError(f"a message id code has 5 octets, not {len(data)}")
    memory, number, crc = struct.unpack(">BHH", data)
    return MemoryType(memory), number, crc


# --- MULTI ------------------------------------------------------------------------------------

_TAG = re.compile(r"\[([a-z]+)([^\]]*)\]", re.IGNORECASE)
#: Tags a text-only portable sign supports: new line, new page, line and page justification.
SUPPORTED_TAGS = frozenset({"nl", "np", "jl", "jp", "pt"})


def text_to_multi(text: str, chars_per_line: int, lines_per_page: int) -> str:
    """Sign text (upper case words, ``SLOW TRAFFIC 0.3 MI``) as MULTI for a character sign of
    ``lines_per_page`` lines of ``chars_per_line``: words filled into lines, lines into pages
    (``[np]``), each line centred (``[jl3]``, the default on most signs, left implicit).

    Raises ValueError for a word longer than a line or for a character the sign cannot show.
    """
    words = text.upper().split()
    for word in words:
        if len(word) > chars_per_line:
            raise ValueError(f"{word!r} is longer than a line of {chars_per_line} characters")
        if not word.isascii() or "[" in word or "]" in word:
            raise ValueError(f"{word!r}: a character the sign cannot show")
    lines: list[str] = []
    for word in words:
        if lines and len(lines[-1]) + 1 + len(word) <= chars_per_line:
            lines[-1] += " " + word
        else:
            lines.append(word)
    pages = [lines[k : k + lines_per_page] for k in range(0, len(lines), lines_per_page)]
    return "[np]".join("[nl]".join(page) for page in pages)


def multi_to_text(multi: str) -> str:
    """The words a MULTI string shows, one space apart (tags dropped)."""
    return " ".join(_TAG.sub(" ", multi).split())


def check_multi(multi: str, chars_per_line: int, lines_per_page: int, max_pages: int) -> MultiError:
    """What a sign of that size says of ``multi`` on validation (``NONE``: it can show it)."""
    if not multi.isascii():
        return MultiError.OTHER
    for tag in _TAG.finditer(multi):
        if tag.group(1).lower() not in SUPPORTED_TAGS:
            return MultiError.UNSUPPORTED_TAG
    bare = _TAG.sub("", multi.replace("[[", "").replace("]]", ""))
    if "[" in bare or "]" in bare:
        return MultiError.OTHER  # an unclosed or empty tag (a bracket shown is doubled)
    pages = re.split(r"\[np\]", multi, flags=re.IGNORECASE)
    if len(pages) > max_pages:
        return MultiError.TOO_MANY_PAGES
    for page in pages:
        lines = re.split(r"\[nl\d*\]", page, flags=re.IGNORECASE)
        if len(lines) > lines_per_page:
            return MultiError.TEXT_TOO_BIG
        if any(len(_TAG.sub("", line)) > chars_per_line for line in lines):
            return MultiError.TEXT_TOO_BIG
    return MultiError.NONE
