"""The sign simulator's rules (``SignModel``) without SNMP: a changeable row written only while
modifying, validated against the face and given its CRC; an activation refused for a wrong CRC,
a row not valid, an unknown memory type or number; the current buffer and the message source
following an accepted one; a blank activation."""

from __future__ import annotations

import pytest
from pysnmp.smi import error as smi_error

from wz_drivers.ntcip1203 import (
    ACTIVATE_MESSAGE,
    ACTIVATE_MSG_ERROR,
    MSG_TABLE_SOURCE,
    MULTI_SYNTAX_ERROR,
    NUM_CHANGEABLE,
    ActivateError,
    ActivationCode,
    Column,
    MemoryType,
    MessageStatus,
    MultiError,
    message_crc,
    message_id_code,
    message_oid,
)
from wz_drivers.sign_sim import SignModel


def write(model: SignModel, oid: tuple[int, ...], value: int | bytes) -> None:
    model.check_write(oid, value)
    model.write(oid, value)


def row(column: Column, number: int = 1) -> tuple[int, ...]:
    return message_oid(column, MemoryType.CHANGEABLE, number)


def test_a_message_goes_on_the_face_by_the_standards_sequence() -> None:
    model = SignModel(lines=3, chars=8, pages=2, changeable=4)
    assert model.showing() == ""
    with pytest.raises(smi_error.InconsistentValueError):  # not modifying
        model.check_write(row(Column.MULTI), b"SLOW")
    write(model, row(Column.STATUS), int(MessageStatus.MODIFY_REQ))
    assert model.values[row(Column.STATUS)] == MessageStatus.MODIFYING
    write(model, row(Column.MULTI), b"SLOW[nl]DOWN")
    write(model, row(Column.STATUS), int(MessageStatus.VALIDATE_REQ))
    assert model.values[row(Column.STATUS)] == MessageStatus.VALID
    assert model.values[NUM_CHANGEABLE] == 1
    crc = model.values[row(Column.CRC)]
    assert crc == message_crc("SLOW[nl]DOWN")
    with pytest.raises(smi_error.GenError):
        write(model, ACTIVATE_MESSAGE, ActivationCode(MemoryType.CHANGEABLE, 1, 0xDEAD).encode())
    assert model.values[ACTIVATE_MSG_ERROR] == ActivateError.MESSAGE_CRC and model.showing() == ""
    assert isinstance(crc, int)
    write(model, ACTIVATE_MESSAGE, ActivationCode(MemoryType.CHANGEABLE, 1, crc).encode())
    assert model.showing() == "SLOW[nl]DOWN" and model.changes == 1
    assert model.values[MSG_TABLE_SOURCE] == message_id_code(MemoryType.CHANGEABLE, 1, crc)
    assert model.values[ACTIVATE_MSG_ERROR] == ActivateError.NONE
    write(model, ACTIVATE_MESSAGE, ActivationCode(MemoryType.BLANK, 1, 0).encode())
    assert model.showing() == "" and model.changes == 2
    write(model, row(Column.STATUS), int(MessageStatus.NOT_USED_REQ))
    assert model.values[row(Column.STATUS)] == MessageStatus.NOT_USED
    assert model.values[NUM_CHANGEABLE] == 0


@pytest.mark.parametrize(
    ("code", "why"),
    [
        (ActivationCode(MemoryType.CHANGEABLE, 2, 0), ActivateError.MESSAGE_STATUS),
        (ActivationCode(MemoryType.CHANGEABLE, 9, 0), ActivateError.MESSAGE_NUMBER),
        (ActivationCode(MemoryType.PERMANENT, 1, 0), ActivateError.MESSAGE_MEMORY_TYPE),
    ],
)
def test_activations_the_sign_refuses(code: ActivationCode, why: ActivateError) -> None:
    model = SignModel(lines=3, chars=8, pages=2, changeable=4)
    with pytest.raises(smi_error.GenError):
        write(model, ACTIVATE_MESSAGE, code.encode())
    assert model.values[ACTIVATE_MSG_ERROR] == why
    with pytest.raises(smi_error.GenError):
        write(model, ACTIVATE_MESSAGE, b"\x00" * 5)  # not an activation code
    assert model.values[ACTIVATE_MSG_ERROR] == ActivateError.OTHER


def test_validation_reports_what_the_face_cannot_show_and_writes_are_checked() -> None:
    model = SignModel(lines=3, chars=8, pages=1, changeable=1)
    write(model, row(Column.STATUS), int(MessageStatus.MODIFY_REQ))
    write(model, row(Column.MULTI), b"A[np]B")
    write(model, row(Column.STATUS), int(MessageStatus.VALIDATE_REQ))
    assert model.values[row(Column.STATUS)] == MessageStatus.ERROR
    assert model.values[MULTI_SYNTAX_ERROR] == MultiError.TOO_MANY_PAGES
    with pytest.raises(smi_error.WrongValueError):
        model.check_write(row(Column.STATUS), int(MessageStatus.VALID))  # not a request
    with pytest.raises(smi_error.WrongTypeError):
        model.check_write(row(Column.MULTI), 5)
    with pytest.raises(smi_error.NotWritableError):
        model.check_write(row(Column.CRC), 1)
    with pytest.raises(smi_error.NotWritableError):
        model.check_write(message_oid(Column.MULTI, MemoryType.CURRENT_BUFFER, 1), b"X")
    with pytest.raises(smi_error.NotWritableError):
        model.check_write((1, 3, 6, 1, 2, 1, 1, 5, 0), b"sysName")
    with pytest.raises(smi_error.WrongTypeError):
        model.check_write(ACTIVATE_MESSAGE, 1)
