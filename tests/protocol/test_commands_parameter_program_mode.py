"""Parameter area (02 xx), program area (03 xx) and mode (04 xx) commands."""

from __future__ import annotations

import contextlib
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiofins.protocol.commands import Request, mode, parameter, program
from aiofins.protocol.commands.mode import Run, RunMode, Stop
from aiofins.protocol.commands.parameter import (
    PARAMETER_AREA_WORDS,
    ParameterArea,
    ParameterAreaClear,
    ParameterAreaRead,
    ParameterAreaReadResult,
    ParameterAreaWrite,
)
from aiofins.protocol.commands.program import (
    ProgramAreaClear,
    ProgramAreaRead,
    ProgramAreaReadResult,
    ProgramAreaWrite,
    ProgramAreaWriteResult,
    ProgramClearCode,
)
from aiofins.protocol.errors import CommandError, DecodeError

H = bytes.fromhex
OPERATIONS = (*parameter.OPERATIONS, *program.OPERATIONS, *mode.OPERATIONS)


# --- golden bytes -------------------------------------------------------------------------


def test_parameter_area_read_golden() -> None:
    request = ParameterAreaRead(ParameterArea.PLC_SETUP, 0x01FE, 2)
    assert request.encode() == H("8010 01FE 0002")
    assert ParameterAreaRead.decode(H("801001FE0002")) == request
    # Bit 15 of the returned count: the data includes the area's last word (word 511).
    data = H("8010 01FE 8002 1234 5678")
    result = request.decode_response(data)
    assert result == ParameterAreaReadResult(0x8010, 0x01FE, (0x1234, 0x5678), last=True)
    assert result.encode() == data
    partial = ParameterAreaRead(0x8002, 0, 1).decode_response(H("8002 0000 0001 ABCD"))
    assert (partial.words, partial.last) == ((0xABCD,), False)


def test_parameter_area_read_max_498_words() -> None:
    assert ParameterAreaRead(0x8002, 0, 498).encode() == H("8002 0000 01F2")


def test_parameter_area_read_response_errors() -> None:
    request = ParameterAreaRead(0x8010, 0, 2)
    for bad in (H("8010 0000"), H("8010 0000 0002 0001"), H("8010 0000 0001 0001 00")):
        with pytest.raises(DecodeError):
            request.decode_response(bad)


def test_parameter_area_write_golden() -> None:
    # Includes the PLC Setup's last word (511): bit 15 set automatically.
    request = ParameterAreaWrite(0x8010, 0x01FE, (1, 2))
    assert request.last is True
    assert request.encode() == H("8010 01FE 8002 0001 0002")
    assert ParameterAreaWrite.decode(request.encode()) == request
    # Routing tables word 0 only: bit 15 clear; explicit last=True sets it.
    assert ParameterAreaWrite(0x8013, 0, (0xABCD,)).encode() == H("8013 0000 0001 ABCD")
    assert ParameterAreaWrite(0x8013, 0, (0xABCD,), last=True).encode() == H("8013 0000 8001 ABCD")
    assert ParameterAreaWrite(0x8013, 0, ()).encode() == H("8013 0000 0000")
    request.decode_response(b"")  # no response data: returns None


def test_parameter_area_clear_golden() -> None:
    request = ParameterAreaClear(ParameterArea.IO_TABLE)
    assert request.count == 1280
    assert request.encode() == H("8012 0000 0500 0000")
    assert ParameterAreaClear.decode(request.encode()) == request
    assert ParameterAreaClear(0x8010, 0).encode() == H("8010 0000 0000 0000")
    request.decode_response(b"")  # no response data: returns None


def test_parameter_area_sizes_from_manual() -> None:
    assert PARAMETER_AREA_WORDS == {
        0x8000: 8000,
        0x8002: 0x1440,
        0x8010: 0x200,
        0x8012: 0x500,
        0x8013: 0x200,
    }


def test_program_area_read_golden() -> None:
    request = ProgramAreaRead(0, 992)
    assert request.encode() == H("FFFF 00000000 03E0")
    assert ProgramAreaRead.decode(request.encode()) == request
    small = ProgramAreaRead(0x100, 8)
    data = H("FFFF 00000100 8008 01020304 05060708")
    result = small.decode_response(data)
    assert result == ProgramAreaReadResult(0x100, H("0102030405060708"), last=True)
    assert result.encode() == data


def test_program_area_write_golden() -> None:
    request = ProgramAreaWrite(0x100, H("01020304 05060708"), last=True)
    assert request.byte_count == 8
    assert request.encode() == H("FFFF 00000100 8008 01020304 05060708")
    assert ProgramAreaWrite.decode(request.encode()) == request
    assert ProgramAreaWrite(0, H("00000000")).encode() == H("FFFF 00000000 0004 00000000")
    result = request.decode_response(H("FFFF 00000100 8008"))
    assert result == ProgramAreaWriteResult(0x100, 8, last=True)
    assert result.encode() == H("FFFF 00000100 8008")
    with pytest.raises(DecodeError):
        request.decode_response(b"")


def test_program_area_clear_golden() -> None:
    assert ProgramAreaClear().encode() == H("FFFF 00")
    with_tasks = ProgramAreaClear(ProgramClearCode.WITH_INTERRUPT_TASKS)
    assert with_tasks.encode() == H("FFFF 10")
    assert ProgramAreaClear.decode(H("FFFF10")) == with_tasks
    assert ProgramAreaClear(0x10) == with_tasks
    with_tasks.decode_response(b"")  # no response data: returns None


def test_run_golden() -> None:
    assert Run().encode() == H("FFFF 02")
    assert Run().mode is RunMode.MONITOR
    assert Run(RunMode.RUN).encode() == H("FFFF 04")
    # Manual 5-3-13: only the command code, or code + program number, means MONITOR.
    assert Run.decode(b"") == Run(RunMode.MONITOR)
    assert Run.decode(H("FFFF")) == Run(RunMode.MONITOR)
    assert Run.decode(H("FFFF04")) == Run(RunMode.RUN)
    assert Run(4) == Run(RunMode.RUN)
    Run().decode_response(b"")  # no response data: returns None


def test_stop_golden() -> None:
    assert Stop().encode() == H("FFFF")
    assert Stop.decode(b"") == Stop()
    assert Stop.decode(H("FFFF")) == Stop()
    Stop().decode_response(b"")  # no response data: returns None
    with pytest.raises(DecodeError):
        Stop().decode_response(b"\x00")


def test_operation_table() -> None:
    assert [op.command_code() for op in OPERATIONS] == [
        0x0201, 0x0202, 0x0203, 0x0306, 0x0307, 0x0308, 0x0401, 0x0402,
    ]  # fmt: skip
    idempotent = {op.METHOD for op in OPERATIONS if op.IDEMPOTENT}
    assert idempotent == {"parameter_area_read", "program_area_read"}


# --- server side: malformed commands carry the end code a PLC answers ---------------------


@pytest.mark.parametrize(
    ("op", "params", "end_code"),
    [
        (ParameterAreaRead, H("8010 0000"), 0x1002),
        (ParameterAreaRead, H("8010 0000 0001 00"), 0x1001),
        (ParameterAreaRead, H("8010 0000 8001"), 0x110C),  # bit 15 must be 0
        (ParameterAreaRead, H("8099 0000 0001"), 0x1101),
        (ParameterAreaRead, H("8002 0000 01F3"), 0x1108),  # 499 words
        (ParameterAreaRead, H("8010 0200 0001"), 0x1103),  # past word 511
        (ParameterAreaRead, H("8010 01FF 0002"), 0x1104),
        (ParameterAreaWrite, H("8010 0000 0002 0001"), 0x1003),
        (ParameterAreaWrite, H("8010 0000 0000 0001"), 0x1003),
        (ParameterAreaWrite, H("8011 0000 0000"), 0x1101),
        (ParameterAreaClear, H("8010 0001 0200 0000"), 0x1103),
        (ParameterAreaClear, H("8010 0000 0200 0001"), 0x110C),
        (ParameterAreaClear, H("8010 0000 0201 0000"), 0x1104),
        (ParameterAreaClear, H("8010 0000 0200"), 0x1002),
        (ProgramAreaRead, H("0000 00000000 0004"), 0x1106),
        (ProgramAreaRead, H("FFFF 00000002 0004"), 0x1102),
        (ProgramAreaRead, H("FFFF 00000000 0006"), 0x1102),
        (ProgramAreaRead, H("FFFF 00000000 03E4"), 0x110B),  # 996 bytes
        (ProgramAreaRead, H("FFFF 00000000 8004"), 0x110C),
        (ProgramAreaRead, H("FFFF 00000000"), 0x1002),
        (ProgramAreaWrite, H("FFFF 00000000 0008 00000000"), 0x1003),
        (ProgramAreaWrite, H("FFFF 00000000 03E8") + bytes(1000), 0x1001),
        (ProgramAreaWrite, H("1234 00000000 0000"), 0x1106),
        (ProgramAreaClear, H("FFFF 01"), 0x110C),
        (ProgramAreaClear, H("FFFF"), 0x1002),
        (ProgramAreaClear, H("0000 00"), 0x1106),
        (Run, H("FF"), 0x1002),
        (Run, H("FFFF 03"), 0x110C),
        (Run, H("FFFF 02 00"), 0x1001),
        (Run, H("0000 02"), 0x1106),
        (Stop, H("FFFF 00"), 0x1001),
        (Stop, H("0000"), 0x1106),
    ],
)
def test_decode_rejects_with_end_code(op: type[Request[Any]], params: bytes, end_code: int) -> None:
    with pytest.raises(DecodeError) as info:
        op.decode(params)
    assert info.value.end_code == end_code


# --- builders reject bad arguments before anything is sent --------------------------------


@pytest.mark.parametrize(
    ("build", "match"),
    [
        (lambda: ParameterAreaRead(0x8099, 0, 1), "not one of 8000, 8002, 8010, 8012, 8013"),
        (lambda: ParameterAreaRead(0x8010, 0, 499), r"0\.\.498"),
        (lambda: ParameterAreaRead(0x8010, 512, 0), r"0\.\.511"),
        (lambda: ParameterAreaRead(0x8010, 500, 13), r"0\.\.12"),
        (lambda: ParameterAreaWrite(0x8010, 0, (0x10000,)), r"0\.\.65535"),
        (lambda: ParameterAreaWrite(0x8010, 0, (0,) * 499), r"0\.\.498"),
        (lambda: ParameterAreaClear(0x8010, 513), r"0\.\.512"),
        (lambda: ProgramAreaRead(2, 4), "multiple of 4"),
        (lambda: ProgramAreaRead(0, 6), "multiple of 4"),
        (lambda: ProgramAreaRead(0, 996), r"0\.\.992"),
        (lambda: ProgramAreaRead(-4, 4), r"0\.\.0xFFFFFFFF"),
        (lambda: ProgramAreaWrite(0, bytes(1000)), r"0\.\.996"),
        (lambda: ProgramAreaWrite(0, bytes(3)), "multiple of 4"),
        (lambda: ProgramAreaWrite(0, "abcd"), "bytes"),  # type: ignore[arg-type]
        (lambda: ProgramAreaClear(0x01), "not one of 00 .*, 10"),
        (lambda: Run(3), "not one of 02 .*, 04"),
        (lambda: ParameterAreaReadResult(0x8010, 0, (0x10000,), False), r"0\.\.65535"),
        (lambda: ProgramAreaWriteResult(0, 0x8000, False), r"0\.\.32767"),
    ],
)
def test_builders_reject(build: Any, match: str) -> None:
    with pytest.raises(CommandError, match=match):
        build()


# --- hypothesis ---------------------------------------------------------------------------

words = st.integers(0, 0xFFFF)


@st.composite
def spans(draw: st.DrawFn) -> tuple[int, int, int]:
    area = draw(st.sampled_from(sorted(PARAMETER_AREA_WORDS)))
    size = PARAMETER_AREA_WORDS[area]
    begin = draw(st.integers(0, size - 1))
    return area, begin, draw(st.integers(0, min(498, size - begin)))


@st.composite
def parameter_writes(draw: st.DrawFn) -> ParameterAreaWrite:
    area, begin, count = draw(spans())
    values = draw(st.lists(words, min_size=count, max_size=count))
    return ParameterAreaWrite(area, begin, tuple(values), draw(st.none() | st.booleans()))


@st.composite
def parameter_clears(draw: st.DrawFn) -> ParameterAreaClear:
    area = draw(st.sampled_from(sorted(PARAMETER_AREA_WORDS)))
    return ParameterAreaClear(area, draw(st.none() | st.integers(0, PARAMETER_AREA_WORDS[area])))


program_addresses = st.integers(0, 0x3FFFFFFF).map(lambda n: n * 4)
requests = st.one_of(
    spans().map(lambda s: ParameterAreaRead(*s)),
    parameter_writes(),
    parameter_clears(),
    st.builds(ProgramAreaRead, program_addresses, st.integers(0, 248).map(lambda n: n * 4)),
    st.builds(
        ProgramAreaWrite,
        program_addresses,
        st.integers(0, 249).flatmap(lambda n: st.binary(min_size=4 * n, max_size=4 * n)),
        st.booleans(),
    ),
    st.builds(ProgramAreaClear, st.sampled_from(ProgramClearCode)),
    st.builds(Run, st.sampled_from(RunMode)),
    st.just(Stop()),
)


@given(requests)
def test_request_round_trip(request: Request[Any]) -> None:
    decoded = type(request).decode(request.encode())
    assert decoded == request
    assert decoded.encode() == request.encode()


@given(spans(), st.data())
def test_parameter_read_result_round_trip(span: tuple[int, int, int], data: st.DataObject) -> None:
    area, begin, count = span
    request = ParameterAreaRead(area, begin, count)
    values = tuple(data.draw(st.lists(words, max_size=count)))
    result = ParameterAreaReadResult(area, begin, values, data.draw(st.booleans()))
    assert request.decode_response(result.encode()) == result


@given(program_addresses, st.binary(max_size=992), st.booleans())
def test_program_results_round_trip(address: int, body: bytes, last: bool) -> None:
    read = ProgramAreaRead(0, 992)
    read_result = ProgramAreaReadResult(address, body, last)
    assert read.decode_response(read_result.encode()) == read_result
    write = ProgramAreaWrite(0, b"")
    write_result = ProgramAreaWriteResult(address, len(body), last)
    assert write.decode_response(write_result.encode()) == write_result


@given(st.sampled_from(OPERATIONS), st.binary(max_size=24))
def test_arbitrary_params_only_raise_decode_error(op: type[Request[Any]], params: bytes) -> None:
    try:
        request = op.decode(params)
    except DecodeError as exc:
        assert exc.end_code is not None
    else:
        assert type(request).decode(request.encode()) == request


RESPONSE_REQUESTS = [
    ParameterAreaRead(0x8010, 0, 4),
    ParameterAreaWrite(0x8010, 0, (1,)),
    ParameterAreaClear(0x8010),
    ProgramAreaRead(0, 8),
    ProgramAreaWrite(0, bytes(4)),
    ProgramAreaClear(),
    Run(),
    Stop(),
]


@given(st.sampled_from(RESPONSE_REQUESTS), st.binary(max_size=24))
def test_arbitrary_response_only_raises_decode_error(request: Request[Any], data: bytes) -> None:
    with contextlib.suppress(DecodeError):
        request.decode_response(data)
