"""09 20 (three operations), 0C 01-03, 21 01-03, 21 40/41, 23 01/02: golden bytes, round trips."""

from __future__ import annotations

import contextlib
from datetime import datetime
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aiofins.protocol.areas import MemoryAddress
from aiofins.protocol.commands import decode_request, operation_for
from aiofins.protocol.commands._base import Request
from aiofins.protocol.commands.access import (
    AccessRightAcquire,
    AccessRightForcedAcquire,
    AccessRightHolder,
    AccessRightRelease,
)
from aiofins.protocol.commands.debug import (
    ForcedSetReset,
    ForcedSetResetCancel,
    ForcedSetResetEntry,
    ForceSpec,
)
from aiofins.protocol.commands.errorlog import (
    ErrorClear,
    ErrorLog,
    ErrorLogClear,
    ErrorLogRead,
    ErrorLogRecord,
    FinsWriteAccessLog,
    FinsWriteAccessLogClear,
    FinsWriteAccessLogRead,
    FinsWriteAccessRecord,
)
from aiofins.protocol.commands.message import (
    FalFalsMessage,
    FalFalsRead,
    MessageClear,
    MessageRead,
    Messages,
)
from aiofins.protocol.errors import AddressError, CommandError, DecodeError

from .test_commands_status_clock import ascii_text, hexbytes, plc_times, u8, u16

# --- 09 20 MESSAGE READ / MESSAGE CLEAR / FAL/FALS READ ------------------------------------


def test_message_read_golden() -> None:
    assert MessageRead.of(0, 2).encode() == hexbytes("0005")
    assert MessageRead().encode() == hexbytes("00FF")
    data = hexbytes("0005") + b"PUMP 1 STOPPED".ljust(32) + b" " * 32
    result = MessageRead.of(0, 2).decode_response(data)
    assert result == Messages(0x05, ("PUMP 1 STOPPED", ""))
    assert result.numbers == (0, 2)
    assert result.by_number() == {0: "PUMP 1 STOPPED", 2: ""}
    assert result.encode() == data
    assert MessageRead(0).decode_response(hexbytes("0000")) == Messages(0, ())


def test_message_clear_and_fal_golden() -> None:
    assert MessageClear.of(1, 7).encode() == hexbytes("4082")
    assert MessageClear.decode(hexbytes("4082")) == MessageClear(0x82)
    MessageClear(1).decode_response(b"")  # no response data: returns None, raises nothing
    assert FalFalsRead(1).encode() == hexbytes("8001")
    assert FalFalsRead(511).encode() == hexbytes("81FF")
    data = hexbytes("8001") + b"LOW AIR\rPRESSURE"
    assert FalFalsRead(1).decode_response(data) == FalFalsMessage(1, "LOW AIR\rPRESSURE")
    assert FalFalsMessage(1, "LOW AIR\rPRESSURE").encode() == data
    assert FalFalsRead(5).decode_response(hexbytes("0005") + b" " * 16) == FalFalsMessage(5, "")


def test_0920_dispatch_by_bits_14_15() -> None:
    assert operation_for(0x09, 0x20, hexbytes("0001")) is MessageRead
    assert operation_for(0x09, 0x20, hexbytes("4001")) is MessageClear
    assert operation_for(0x09, 0x20, hexbytes("8001")) is FalFalsRead
    assert operation_for(0x09, 0x20, b"") is MessageRead  # then 1002 from decode
    with pytest.raises(DecodeError):
        operation_for(0x09, 0x20, hexbytes("C001"))
    variants: tuple[Request[Any], ...] = (MessageRead(1), MessageClear(1), FalFalsRead(1))
    for req in variants:
        others: set[type[Request[Any]]] = {MessageRead, MessageClear, FalFalsRead}
        others.discard(type(req))
        assert type(req).matches(req.encode())
        assert not any(op.matches(req.encode()) for op in others)


def test_message_invalid() -> None:
    with pytest.raises(CommandError, match="message mask 256"):
        MessageRead(0x100)
    with pytest.raises(CommandError, match="message number 8"):
        MessageClear.of(8)
    with pytest.raises(CommandError, match="FAL/FALS number"):
        FalFalsRead(0x4000)
    with pytest.raises(CommandError, match="selects 2"):
        Messages(0x03, ("one",))
    with pytest.raises(CommandError, match="longer than 32"):
        Messages(0x01, ("x" * 33,)).encode()
    for op, bad, code in (
        (MessageRead, "0100", 0x110C),
        (MessageRead, "00", 0x1002),
        (MessageClear, "400100", 0x1001),
        (FalFalsRead, "4001", 0x110C),
    ):
        with pytest.raises(DecodeError) as err:
            op.decode(hexbytes(bad))
        assert err.value.end_code == code
    with pytest.raises(DecodeError):
        MessageRead(3).decode_response(hexbytes("0003") + bytes(32))


messages = st.integers(0, 0xFF).flatmap(
    lambda mask: st.tuples(st.just(mask), st.tuples(*[ascii_text(32)] * bin(mask).count("1")))
)


@given(u8, st.integers(0, 0x3FFF), messages, ascii_text(16))
def test_message_round_trips(
    mask: int, fal: int, msgs: tuple[int, tuple[str, ...]], fal_text: str
) -> None:
    for req in (MessageRead(mask), MessageClear(mask), FalFalsRead(fal)):
        params = req.encode()
        assert operation_for(0x09, 0x20, params) is type(req)
        assert type(req).decode(params) == req
    result = Messages(*msgs)
    assert MessageRead(msgs[0]).decode_response(result.encode()) == result
    fal_result = FalFalsMessage(fal, fal_text)
    assert FalFalsRead(fal).decode_response(fal_result.encode()) == fal_result


# --- 0C 01 / 0C 02 / 0C 03 access right ----------------------------------------------------


def test_access_right_golden() -> None:
    for op, src in (
        (AccessRightAcquire, 1),
        (AccessRightForcedAcquire, 2),
        (AccessRightRelease, 3),
    ):
        req = op()
        assert req.command_code() == 0x0C00 | src
        assert req.encode() == hexbytes("FFFF")
        assert op.decode(hexbytes("FFFF")) == req
        assert op(0x0000).encode() == hexbytes("0000")
        req.decode_response(b"")  # no response data: raises nothing
    assert AccessRightAcquire().decode_response(b"") is None
    holder = AccessRightAcquire().decode_response(hexbytes("00 05 00"))
    assert holder == AccessRightHolder(network=0, node=5, unit=0)
    assert AccessRightHolder(1, 2, 0x10).encode() == hexbytes("01 02 10")


def test_access_right_invalid() -> None:
    with pytest.raises(CommandError, match="program number 65536"):
        AccessRightAcquire(0x10000)
    with pytest.raises(CommandError, match="node address 256"):
        AccessRightHolder(0, 256, 0)
    with pytest.raises(DecodeError) as err:
        AccessRightRelease.decode(b"\xff")
    assert err.value.end_code == 0x1002
    with pytest.raises(DecodeError):
        AccessRightForcedAcquire().decode_response(b"\x00")
    with pytest.raises(DecodeError):
        AccessRightAcquire().decode_response(b"\x00\x05")


@given(u16, u8, u8, u8)
def test_access_right_round_trips(program: int, net: int, node: int, unit: int) -> None:
    for op in (AccessRightAcquire, AccessRightForcedAcquire, AccessRightRelease):
        assert op.decode(op(program).encode()) == op(program)
    holder = AccessRightHolder(net, node, unit)
    assert AccessRightAcquire().decode_response(holder.encode()) == holder


# --- 21 01 / 21 02 / 21 03 error clear and error log --------------------------------------


def test_error_clear_golden() -> None:
    assert ErrorClear().encode() == hexbytes("FFFE")
    assert ErrorClear(0xFFFF).encode() == hexbytes("FFFF")
    assert ErrorClear.decode(hexbytes("4101")) == ErrorClear(0x4101)
    ErrorClear().decode_response(b"")  # no response data: returns None, raises nothing
    assert ErrorLogClear().encode() == b""
    assert ErrorLogClear.decode(b"") == ErrorLogClear()
    with pytest.raises(CommandError, match="error code 65536"):
        ErrorClear(0x10000)
    with pytest.raises(DecodeError) as err:
        ErrorLogClear.decode(b"\x00")
    assert err.value.end_code == 0x1001


def test_error_log_read_golden() -> None:
    assert ErrorLogRead(0, 2).encode() == hexbytes("0000 0002")
    data = hexbytes(
        "0014 0005 0002"
        " 00F7 0000 30 15 06 07 24 05"  # battery error, 2024-05-06 07:30:15
        " 4101 0000 00 00 31 23 99 12"  # FAL 001, 1999-12-31 23:00:00
    )
    log = ErrorLogRead(0, 2).decode_response(data)
    assert log == ErrorLog(
        max_records=20,
        stored_records=5,
        records=(
            ErrorLogRecord(0x00F7, 0x0000, datetime(2024, 5, 6, 7, 30, 15)),
            ErrorLogRecord(0x4101, 0x0000, datetime(1999, 12, 31, 23, 0, 0)),
        ),
    )
    assert log.encode() == data
    # Beginning record past the stored ones: the PLC returns no data at all.
    assert ErrorLogRead(30, 1).decode_response(b"") == ErrorLog(0, 0, ())


def test_error_log_invalid() -> None:
    with pytest.raises(CommandError, match="number of records 0"):
        ErrorLogRead(0, 0)
    with pytest.raises(DecodeError) as err:
        ErrorLogRead.decode(hexbytes("0000 0000"))
    assert err.value.end_code == 0x110C
    with pytest.raises(DecodeError):  # count says 2, one record present
        ErrorLogRead().decode_response(hexbytes("0014 0005 0002 00F7 0000 30 15 06 07 24 05"))
    with pytest.raises(DecodeError):  # month 13
        ErrorLogRead().decode_response(hexbytes("0014 0005 0001 00F7 0000 30 15 06 07 24 13"))


error_records = st.builds(ErrorLogRecord, u16, u16, plc_times)


@given(u16, st.integers(1, 0xFFFF), u16, u16, st.lists(error_records, max_size=20))
def test_error_log_round_trips(
    begin: int, count: int, max_records: int, stored: int, records: list[ErrorLogRecord]
) -> None:
    req = ErrorLogRead(begin, count)
    assert ErrorLogRead.decode(req.encode()) == req
    assert ErrorClear.decode(ErrorClear(begin).encode()) == ErrorClear(begin)
    log = ErrorLog(max_records, stored, tuple(records))
    assert req.decode_response(log.encode()) == log


# --- 21 40 / 21 41 FINS write access log ---------------------------------------------------


def test_fins_write_access_log_golden() -> None:
    assert FinsWriteAccessLogRead(0, 20).encode() == hexbytes("0000 0014")
    assert FinsWriteAccessLogClear().encode() == b""
    FinsWriteAccessLogClear().decode_response(b"")  # no response data: returns None, raises nothing
    # manual 5-3-30 layout: network, node, unit, command code, then year..day of week (BCD).
    data = hexbytes("0014 0001 0001 01 22 00 0102 24 05 06 07 08 09 01")
    log = FinsWriteAccessLogRead().decode_response(data)
    assert log == FinsWriteAccessLog(
        20,
        1,
        (FinsWriteAccessRecord(1, 0x22, 0, 0x0102, datetime(2024, 5, 6, 7, 8, 9), 1),),
    )
    assert log.encode() == data
    with pytest.raises(DecodeError):
        FinsWriteAccessLogRead().decode_response(b"")
    with pytest.raises(DecodeError):  # day of week 7
        FinsWriteAccessLogRead().decode_response(
            hexbytes("0014 0001 0001 01 22 00 0102 24 05 06 07 08 09 07")
        )
    with pytest.raises(CommandError, match="command code 65536"):
        FinsWriteAccessRecord(0, 0, 0, 0x10000, datetime(2024, 1, 1), 1)


access_records = st.builds(FinsWriteAccessRecord, u8, u8, u8, u16, plc_times, st.integers(0, 6))


@given(u16, st.integers(1, 0xFFFF), u16, u16, st.lists(access_records, max_size=20))
def test_fins_write_access_log_round_trips(
    begin: int, count: int, max_records: int, stored: int, records: list[FinsWriteAccessRecord]
) -> None:
    req = FinsWriteAccessLogRead(begin, count)
    assert FinsWriteAccessLogRead.decode(req.encode()) == req
    log = FinsWriteAccessLog(max_records, stored, tuple(records))
    assert req.decode_response(log.encode()) == log


# --- 23 01 / 23 02 forced set/reset --------------------------------------------------------


def test_forced_set_reset_golden() -> None:
    req = ForcedSetReset.of(
        (ForceSpec.FORCED_SET, MemoryAddress(0x30, 100, 3)),
        (ForceSpec.RELEASE, MemoryAddress(0x09, 5, 0)),
    )
    params = hexbytes("0002 0001 30 0064 03 FFFF 09 0005 00")
    assert req.encode() == params
    assert ForcedSetReset.decode(params) == req
    assert req.entries[0] == ForcedSetResetEntry(ForceSpec.FORCED_SET, MemoryAddress(0x30, 100, 3))
    req.decode_response(b"")  # no response data: returns None, raises nothing
    assert ForcedSetResetCancel().encode() == b""
    assert ForcedSetResetCancel.decode(b"") == ForcedSetResetCancel()
    ForcedSetResetCancel().decode_response(b"")  # no response data: returns None, raises nothing


def test_forced_set_reset_invalid() -> None:
    with pytest.raises(CommandError, match="number of bits/flags 0"):
        ForcedSetReset(())
    with pytest.raises(AddressError, match="area code 82"):
        ForcedSetResetEntry(ForceSpec.FORCED_SET, MemoryAddress(0x82, 0, 0))
    with pytest.raises(AddressError, match="bit number 16"):
        ForcedSetResetEntry(ForceSpec.FORCED_SET, MemoryAddress(0x30, 0, 16))
    for flags in (0x09, 0x01):  # completion flags: bit byte always 00 (manual 5-2-1)
        with pytest.raises(AddressError, match="completion flag"):
            ForcedSetResetEntry(ForceSpec.FORCED_SET, MemoryAddress(flags, 5, 5))
    with pytest.raises(CommandError, match="designation"):
        ForcedSetResetEntry(0x0002, MemoryAddress(0x30, 0, 0))  # type: ignore[arg-type]
    for bad, code in (
        ("0000", 0x110C),
        ("0002 0001 30 0064 03", 0x1002),
        ("0001 0001 30 0064 03 00", 0x1001),
        ("0001 0002 30 0064 03", 0x110C),
        ("0001 0001 82 0064 00", 0x1101),
        ("0001 0001 30 0064 10", 0x1103),
    ):
        with pytest.raises(DecodeError) as err:
            ForcedSetReset.decode(hexbytes(bad))
        assert err.value.end_code == code, bad
    with pytest.raises(DecodeError):
        ForcedSetResetCancel().decode_response(b"\x00")


entries = st.builds(
    ForcedSetResetEntry,
    st.sampled_from(list(ForceSpec)),
    st.one_of(
        st.builds(
            MemoryAddress, st.sampled_from([0x30, 0x31, 0x32, 0x00]), u16, st.integers(0, 15)
        ),
        st.builds(MemoryAddress, st.sampled_from([0x09, 0x01]), u16),  # completion flags: bit 00
    ),
)


@given(st.lists(entries, min_size=1, max_size=40))
def test_forced_set_reset_round_trip(items: list[ForcedSetResetEntry]) -> None:
    req = ForcedSetReset(tuple(items))
    assert len(req.encode()) == 2 + 6 * len(items)
    assert ForcedSetReset.decode(req.encode()) == req


# --- robustness: arbitrary bytes only ever raise DecodeError --------------------------------

REQUESTS: list[Request[Any]] = [
    MessageRead(),
    MessageClear(0x81),
    FalFalsRead(1),
    AccessRightAcquire(),
    AccessRightForcedAcquire(),
    AccessRightRelease(),
    ErrorClear(),
    ErrorLogRead(),
    ErrorLogClear(),
    FinsWriteAccessLogRead(),
    FinsWriteAccessLogClear(),
    ForcedSetReset.of((ForceSpec.FORCED_SET, MemoryAddress(0x30, 0, 0))),
    ForcedSetResetCancel(),
]


@pytest.mark.parametrize("req", REQUESTS, ids=lambda r: f"{type(r).__name__}")
@settings(max_examples=60)
@given(data=st.binary(max_size=300))
def test_arbitrary_bytes_raise_only_decode_error(req: Request[Any], data: bytes) -> None:
    for call in (lambda: type(req).decode(data), lambda: req.decode_response(data)):
        with contextlib.suppress(DecodeError):
            call()


@given(st.binary(max_size=60))
def test_0920_dispatch_then_decode_never_crashes(data: bytes) -> None:
    with contextlib.suppress(DecodeError):
        operation_for(0x09, 0x20, data).decode(data)


@pytest.mark.parametrize("req", REQUESTS, ids=lambda r: f"{type(r).__name__}")
def test_decode_request_dispatches_to_the_operation(req: Request[Any]) -> None:
    assert decode_request(req.MRC, req.SRC, req.encode()) == req


VALID_RESPONSES: list[tuple[Request[Any], bytes]] = [
    (MessageRead(0x05), Messages(0x05, ("A", "B")).encode()),
    (FalFalsRead(3), FalFalsMessage(3, "FAL 3").encode()),
    (AccessRightAcquire(), AccessRightHolder(0, 5, 0).encode()),
    (
        ErrorLogRead(),
        ErrorLog(20, 2, (ErrorLogRecord(0xF7, 0, datetime(2024, 5, 6, 7, 8, 9)),) * 2).encode(),
    ),
    (
        FinsWriteAccessLogRead(),
        FinsWriteAccessLog(
            20, 1, (FinsWriteAccessRecord(1, 2, 3, 0x0102, datetime(2024, 5, 6), 1),)
        ).encode(),
    ),
]


@pytest.mark.parametrize(("req", "data"), VALID_RESPONSES, ids=lambda v: type(v).__name__)
@settings(max_examples=60)
@given(st.data())
def test_mutated_responses_raise_only_decode_error(
    req: Request[Any], data: bytes, draw: st.DataObject
) -> None:
    raw = bytearray(data)
    for _ in range(draw.draw(st.integers(1, 3))):
        raw[draw.draw(st.integers(0, len(raw) - 1))] = draw.draw(u8)
    cut = draw.draw(st.integers(0, len(raw)))
    for candidate in (bytes(raw), bytes(raw[:cut])):
        with contextlib.suppress(DecodeError):
            req.decode_response(candidate)


@given(st.binary(min_size=8, max_size=8 + 6 * 3))
def test_forced_set_reset_structured_fuzz(tail: bytes) -> None:
    params = (len(tail) // 6).to_bytes(2, "big") + tail
    with contextlib.suppress(DecodeError):
        assert ForcedSetReset.decode(params).encode() == params
