"""NTCIP 1203 pieces: the CRC against its catalogue check value, MULTI filling and checking,
the activation code; and the sign simulator's refusals, over real SNMP with the driver's own
client (a wrong CRC, a row not valid, a write outside ``modifying``, a reader's community)."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.drivers.device_sims import Sign, free_udp_port
from wz_drivers.dms import DmsClient, SignError, SignSettings
from wz_drivers.ntcip1203 import (
    ActivationCode,
    Column,
    MemoryType,
    MultiError,
    check_multi,
    crc16,
    message_crc,
    message_oid,
    multi_to_text,
    text_to_multi,
)

ROOT = Path(__file__).resolve().parents[2]


def test_crc_is_the_iso_3309_reflected_crc16_without_final_inversion() -> None:
    # CRC-16/MCRF4XX (poly 0x1021 reflected, init 0xFFFF, no xorout): check value 0x6F91.
    assert crc16(b"123456789") == 0x6F91
    assert message_crc("SLOW[nl]DOWN", 0, 0) == crc16(b"SLOW[nl]DOWN\x00\x00")
    assert message_crc("SLOW", 1, 0) != message_crc("SLOW", 0, 0)


@pytest.mark.parametrize(
    ("text", "chars", "lines", "multi"),
    [
        ("SLOW DOWN", 8, 3, "SLOW[nl]DOWN"),
        ("QUEUE AHEAD 0.3 MI", 8, 3, "QUEUE[nl]AHEAD[nl]0.3 MI"),
        ("MERGE RIGHT NOW", 8, 3, "MERGE[nl]RIGHT[nl]NOW"),
        ("MERGE RIGHT NOW", 16, 2, "MERGE RIGHT NOW"),
        ("QUEUE AHEAD 0.3 MI", 5, 2, "QUEUE[nl]AHEAD[np]0.3[nl]MI"),
        ("", 8, 3, ""),
    ],
)
def test_text_fills_the_face(text: str, chars: int, lines: int, multi: str) -> None:
    assert text_to_multi(text, chars, lines) == multi
    assert multi_to_text(multi) == " ".join(text.split())
    assert check_multi(multi, chars, lines, 2) is MultiError.NONE


def test_text_that_cannot_fit_is_refused() -> None:
    with pytest.raises(ValueError, match="longer than a line"):
        text_to_multi("CONSTRUCTION", 8, 3)
    with pytest.raises(ValueError, match="cannot show"):
        text_to_multi("SLOW [DOWN]", 8, 3)


@pytest.mark.parametrize(
    ("multi", "verdict"),
    [
        ("TOO LONG A LINE", MultiError.TEXT_TOO_BIG),
        ("A[nl]B[nl]C[nl]D", MultiError.TEXT_TOO_BIG),
        ("A[np]B[np]C", MultiError.TOO_MANY_PAGES),
        ("[g1,1,1]A", MultiError.UNSUPPORTED_TAG),
        ("A[nl", MultiError.OTHER),
        ("ÉTÉ", MultiError.OTHER),
    ],
)
def test_the_sign_finds_what_it_cannot_show(multi: str, verdict: MultiError) -> None:
    assert check_multi(multi, 8, 3, 2) is verdict


def test_activation_code_round_trips_and_refuses_a_wrong_length() -> None:
    code = ActivationCode(MemoryType.CHANGEABLE, 3, 0xBEEF, 60, 200, (10, 1, 2, 3))
    data = code.encode()
    assert len(data) == 12 and data[:2] == b"\x00\x3c" and data[3] == 3
    assert ActivationCode.decode(data) == code
    with pytest.raises(ValueError, match="12 octets"):
        ActivationCode.decode(data[:11])


@pytest.fixture(scope="module")
def sign() -> Iterator[tuple[Sign, int]]:
    port = free_udp_port()
    running = Sign(port)
    yield running, port
    running.kill()


def client(port: int, **overrides: object) -> DmsClient:
    return DmsClient(SignSettings("127.0.0.1", port, **overrides))  # type: ignore[arg-type]


def test_the_sign_refuses_an_activation_with_a_wrong_crc(sign: tuple[Sign, int]) -> None:
    running, port = sign
    dms = client(port)
    try:
        assert dms.show("SLOW[nl]DOWN") == "SLOW[nl]DOWN"
        assert running.next_face()[0] == "SLOW[nl]DOWN"
        wrong = ActivationCode(MemoryType.CHANGEABLE, 1, 0x1234)
        with pytest.raises(SignError, match="MESSAGE_CRC"):
            dms._run(dms._activate(wrong))
        missing = ActivationCode(MemoryType.CHANGEABLE, 99, 0)
        with pytest.raises(SignError, match="MESSAGE_NUMBER"):
            dms._run(dms._activate(missing))
        assert dms.showing() == "SLOW[nl]DOWN"  # a refused activation leaves the face alone
    finally:
        dms.close()


def test_the_sign_refuses_writes_outside_modifying_and_from_the_reader(
    sign: tuple[Sign, int],
) -> None:
    _, port = sign
    from pysnmp.proto import rfc1902

    dms = client(port)
    reader = client(port, write_community="public")
    try:
        dms.show("SLOW[nl]DOWN")  # the row is valid now, not modifying
        multi = message_oid(Column.MULTI, MemoryType.CHANGEABLE, 1)
        with pytest.raises(SignError, match="inconsistentValue"):
            dms._run(dms._set((multi, rfc1902.OctetString(b"X"))))
        with pytest.raises(SignError, match=r"noAccess"):
            reader._run(reader._set((multi, rfc1902.OctetString(b"X"))))
        crc = message_oid(Column.CRC, MemoryType.CHANGEABLE, 1)
        with pytest.raises(SignError, match="notWritable"):
            dms._run(dms._set((crc, rfc1902.Integer32(1))))
        with pytest.raises(SignError, match=r"invalid .*TEXT_TOO_BIG"):
            dms.show("FAR TOO LONG FOR THIS SIGN")
        assert dms.showing() == "SLOW[nl]DOWN"
    finally:
        dms.close()
        reader.close()


def test_the_simulator_refuses_bad_arguments() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "wz_drivers.sign_sim", "--lines", "0"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode == 2 and "--lines must be 1 to 255" in result.stderr
