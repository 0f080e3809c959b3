"""05 01, 05 02, 06 01, 06 20, 07 01, 07 02: golden bytes, round trips, robustness."""

from __future__ import annotations

import contextlib
from datetime import datetime, timezone
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aiofins.protocol.commands import decode_request
from aiofins.protocol.commands._base import Request
from aiofins.protocol.commands.clock import ClockData, ClockRead, ClockWrite
from aiofins.protocol.commands.machine import (
    AreaData,
    ConnectionData,
    ConnectionDataRead,
    CpuUnitConfiguration,
    CpuUnitData,
    CpuUnitDataRead,
    CpuUnitModelData,
    UnitModel,
)
from aiofins.protocol.commands.status import (
    CpuMode,
    CpuUnitStatus,
    CpuUnitStatusRead,
    CycleTime,
    CycleTimeParameter,
    CycleTimeRead,
    FatalError,
    NonFatalError,
)
from aiofins.protocol.errors import CommandError, DecodeError

# --- shared strategies ---------------------------------------------------------------------

PRINTABLE = st.characters(min_codepoint=0x20, max_codepoint=0x7E)


def ascii_text(size: int) -> st.SearchStrategy[str]:
    """ASCII that survives the right-stripped fixed-width field (no trailing space)."""
    return st.text(PRINTABLE, max_size=size).map(str.rstrip)


u8 = st.integers(0, 0xFF)
u16 = st.integers(0, 0xFFFF)
u32 = st.integers(0, 0xFFFFFFFF)
plc_times = st.datetimes(
    min_value=datetime(1998, 1, 1), max_value=datetime(2097, 12, 31, 23, 59, 59)
).map(lambda d: d.replace(microsecond=0))


def hexbytes(text: str) -> bytes:
    return bytes.fromhex(text.replace(" ", ""))


# --- 05 01 CPU UNIT DATA READ --------------------------------------------------------------

PART_A = (
    b"CJ2M-CPU33"
    + b" " * 10  # model, space padded
    + b"02.01"
    + b"\x00" * 15  # internal system version, NUL padded
    + hexbytes("05 03")
    + bytes(38)  # DIP switches 0 and 2 ON, largest EM bank 3, reserved
    + hexbytes("0014 17 8000 08 03 0000 04 0800")  # area data
)
PART_B = (
    hexbytes("8005 0000 8012")
    + bytes(26)  # units 0 and 2 mounted, others not
    + bytes(32)  # reserved
    + hexbytes("01 02")  # one SYSMAC BUS master, two racks
)

MODEL_DATA = CpuUnitModelData(
    model="CJ2M-CPU33",
    internal_system_version="02.01",
    dip_switches=0x05,
    largest_em_bank=3,
    area_data=AreaData(
        program_area_size=20,
        iom_size=23,
        dm_words=32768,
        timer_counter_size=8,
        em_non_file_banks=3,
        memory_card_type=4,
        memory_card_size=2048,
    ),
)
CONFIGURATION = CpuUnitConfiguration(
    cpu_bus_units=(0x8005, 0, 0x8012) + (0,) * 13, remote_io_masters=1, cpu_unit_information=2
)


def test_cpu_unit_data_read_golden() -> None:
    assert CpuUnitDataRead().encode() == b""
    assert CpuUnitDataRead(0x00).encode() == b"\x00"
    assert CpuUnitDataRead(0x01).encode() == b"\x01"
    assert len(PART_A) == 92 and len(PART_B) == 66

    both = CpuUnitDataRead().decode_response(PART_A + PART_B)
    assert both == CpuUnitData(MODEL_DATA, CONFIGURATION)
    assert both.model == "CJ2M-CPU33"
    assert both.internal_system_version == "02.01"
    assert MODEL_DATA.dip_switch(0) and not MODEL_DATA.dip_switch(1) and MODEL_DATA.dip_switch(2)
    assert CONFIGURATION.racks == 2
    assert CONFIGURATION.unit_present(0) and not CONFIGURATION.unit_present(1)
    assert CpuUnitDataRead(0).decode_response(PART_A) == CpuUnitData(MODEL_DATA, None)
    assert CpuUnitDataRead(1).decode_response(PART_B) == CpuUnitData(None, CONFIGURATION)
    assert CpuUnitData(MODEL_DATA, CONFIGURATION).encode() == PART_A + PART_B


def test_cpu_unit_data_cv_part_b_has_two_remote_io_bytes() -> None:
    cv = PART_B[:64] + hexbytes("01 02 03")
    config = CpuUnitDataRead(1).decode_response(cv).configuration
    assert config is not None
    assert (config.sysmac_bus2_masters, config.remote_io_masters, config.racks) == (1, 2, 3)
    assert config.encode() == cv


def test_cpu_unit_data_wrong_lengths() -> None:
    with pytest.raises(DecodeError):
        CpuUnitDataRead(0).decode_response(PART_A + b"\x00")
    with pytest.raises(DecodeError):
        CpuUnitDataRead().decode_response(PART_A + PART_B[:-1])
    with pytest.raises(DecodeError):
        CpuUnitDataRead(1).decode_response(PART_B + b"\x00\x00")


def test_cpu_unit_data_read_invalid_args() -> None:
    with pytest.raises(CommandError, match="data type"):
        CpuUnitDataRead(2)
    with pytest.raises(DecodeError) as err:
        CpuUnitDataRead.decode(b"\x02")
    assert err.value.end_code == 0x110C
    assert CpuUnitDataRead.decode(b"") == CpuUnitDataRead()
    with pytest.raises(CommandError):
        CpuUnitData(None, None)
    with pytest.raises(CommandError, match="16 codes"):
        CpuUnitConfiguration((0,) * 15, 0, 1)


area_data = st.builds(AreaData, u16, u8, u16, u8, u8, u8, u16, u16)
model_data = st.builds(
    CpuUnitModelData,
    ascii_text(20),
    ascii_text(20),
    u8,
    u8,
    area_data,
    st.binary(min_size=38, max_size=38),
)
configuration = st.builds(
    CpuUnitConfiguration,
    st.tuples(*[u16] * 16),
    u8,
    u8,
    st.none() | u8,
    st.binary(min_size=32, max_size=32),
)


@given(model_data, configuration, st.sampled_from([None, 0, 1]))
def test_cpu_unit_data_round_trip(
    a: CpuUnitModelData, b: CpuUnitConfiguration, kind: int | None
) -> None:
    req = CpuUnitDataRead(kind)
    assert CpuUnitDataRead.decode(req.encode()) == req
    result = CpuUnitData(a if kind != 1 else None, b if kind != 0 else None)
    assert req.decode_response(result.encode()) == result


# --- 05 02 CONNECTION DATA READ ------------------------------------------------------------


def test_connection_data_read_golden() -> None:
    assert ConnectionDataRead().encode() == b"\x00"
    assert ConnectionDataRead(0x10, 2).encode() == hexbytes("10 02")
    data = (
        hexbytes("82")
        + b"\x10" + b"CJ1W-ETN21".ljust(20)
        + b"\x11" + b"CJ1W-SCU41-V1".ljust(20)
    )  # fmt: skip
    result = ConnectionDataRead(0x10, 2).decode_response(data)
    assert result == ConnectionData(
        (UnitModel(0x10, "CJ1W-ETN21"), UnitModel(0x11, "CJ1W-SCU41-V1")), last=True
    )
    assert result.encode() == data
    assert ConnectionDataRead.decode(b"\x20") == ConnectionDataRead(0x20, None)


def test_connection_data_read_invalid() -> None:
    with pytest.raises(CommandError, match=r"1\.\.25"):
        ConnectionDataRead(0, 26)
    with pytest.raises(CommandError, match="unit address 80"):
        ConnectionDataRead(0x80)
    with pytest.raises(DecodeError) as err:
        ConnectionDataRead.decode(hexbytes("00 00"))
    assert err.value.end_code == 0x110C
    with pytest.raises(DecodeError):
        ConnectionDataRead().decode_response(hexbytes("02") + b"\x00" + bytes(20))


unit_addresses = st.sampled_from([0x00, 0x10, 0x1F, 0x20, 0x7F, 0xE1])


@given(
    unit_addresses,
    st.none() | st.integers(1, 25),
    st.lists(st.builds(UnitModel, u8, ascii_text(20)), max_size=25),
    st.booleans(),
)
def test_connection_data_round_trip(
    unit: int, count: int | None, units: list[UnitModel], last: bool
) -> None:
    req = ConnectionDataRead(unit, count)
    assert ConnectionDataRead.decode(req.encode()) == req
    result = ConnectionData(tuple(units), last)
    assert req.decode_response(result.encode()) == result


# --- 06 01 CPU UNIT STATUS READ ------------------------------------------------------------


def test_cpu_unit_status_read_golden() -> None:
    assert CpuUnitStatusRead().encode() == b""
    data = hexbytes("7D 04 4000 8010 0005 C123") + b"MOTOR OVERHEAT  "
    status = CpuUnitStatusRead().decode_response(data)
    assert status == CpuUnitStatus(
        status=0x05,  # undefined bits 3-6 masked
        mode=CpuMode.RUN,
        fatal_errors=FatalError.IO_BUS_ERROR,
        non_fatal_errors=NonFatalError.FAL_ERROR | NonFatalError.BATTERY_ERROR,
        message_flags=0x0005,
        error_code=0xC123,
        error_message="MOTOR OVERHEAT",
    )
    assert status.running and status.battery_present
    assert not status.standby and not status.flash_writing
    assert status.has_fatal_error and status.has_non_fatal_error
    assert FatalError.MEMORY_ERROR not in status.fatal_errors
    assert status.messages == (0, 2)
    assert status.encode() == hexbytes("05 04 4000 8010 0005 C123") + b"MOTOR OVERHEAT  "


def test_cpu_unit_status_bits_follow_manual_not_wireshark() -> None:
    data = hexbytes("80 00 8040 0004 0000 0000") + b" " * 16
    status = CpuUnitStatusRead().decode_response(data)
    assert status.fatal_errors == FatalError.MEMORY_ERROR | FatalError.FALS_ERROR
    assert status.non_fatal_errors == NonFatalError.SPECIAL_IO_UNIT_SETTING_ERROR
    assert status.standby and not status.running and status.mode is CpuMode.PROGRAM
    assert status.error_message == ""


def test_cpu_unit_status_rejects_unknown_mode_and_params() -> None:
    with pytest.raises(DecodeError, match="mode"):
        CpuUnitStatusRead().decode_response(hexbytes("01 03") + bytes(24))
    with pytest.raises(DecodeError) as err:
        CpuUnitStatusRead.decode(b"\x00")
    assert err.value.end_code == 0x1001


statuses = st.builds(
    CpuUnitStatus,
    st.sampled_from([0x00, 0x01, 0x02, 0x04, 0x80, 0x87]),
    st.sampled_from(list(CpuMode)),
    u16.map(FatalError),
    u16.map(NonFatalError),
    u16,
    u16,
    ascii_text(16),
)


@given(statuses)
def test_cpu_unit_status_round_trip(status: CpuUnitStatus) -> None:
    assert CpuUnitStatusRead.decode(CpuUnitStatusRead().encode()) == CpuUnitStatusRead()
    assert CpuUnitStatusRead().decode_response(status.encode()) == status


# --- 06 20 CYCLE TIME READ -----------------------------------------------------------------


def test_cycle_time_read_golden() -> None:
    assert CycleTimeRead().encode() == b"\x01"
    assert CycleTimeRead(CycleTimeParameter.INITIALIZE).encode() == b"\x00"
    data = hexbytes("0000028A 000003E8 00000064")
    result = CycleTimeRead().decode_response(data)
    assert result == CycleTime(650, 1000, 100)
    assert (result.average_ms, result.maximum_ms, result.minimum_ms) == (65.0, 100.0, 10.0)
    assert result.encode() == data
    assert CycleTimeRead(CycleTimeParameter.INITIALIZE).decode_response(b"") is None
    with pytest.raises(DecodeError):
        CycleTimeRead(CycleTimeParameter.INITIALIZE).decode_response(data)


def test_cycle_time_read_invalid() -> None:
    with pytest.raises(CommandError, match="initialize"):
        CycleTimeRead(2)  # type: ignore[arg-type]
    with pytest.raises(DecodeError) as err:
        CycleTimeRead.decode(b"\x02")
    assert err.value.end_code == 0x110C
    assert CycleTimeRead(0) == CycleTimeRead(CycleTimeParameter.INITIALIZE)  # type: ignore[arg-type]


@given(st.sampled_from(list(CycleTimeParameter)), u32, u32, u32)
def test_cycle_time_round_trip(param: CycleTimeParameter, a: int, b: int, c: int) -> None:
    req = CycleTimeRead(param)
    assert CycleTimeRead.decode(req.encode()) == req
    assert CycleTimeRead().decode_response(CycleTime(a, b, c).encode()) == CycleTime(a, b, c)


# --- 07 01 CLOCK READ / 07 02 CLOCK WRITE --------------------------------------------------


def test_clock_read_golden() -> None:
    assert ClockRead().encode() == b""
    clock = ClockRead().decode_response(hexbytes("24 05 06 07 08 09 01"))
    assert clock == ClockData(datetime(2024, 5, 6, 7, 8, 9), 1)
    assert clock.day_name == "Monday"
    assert clock.encode() == hexbytes("24 05 06 07 08 09 01")


@pytest.mark.parametrize(("yy", "year"), [(0x98, 1998), (0x99, 1999), (0x00, 2000), (0x97, 2097)])
def test_clock_two_digit_year_rule(yy: int, year: int) -> None:
    clock = ClockRead().decode_response(bytes((yy, 0x01, 0x01, 0x00, 0x00, 0x00, 0x00)))
    assert clock.time.year == year


def test_clock_read_rejects_bad_bcd_and_dates() -> None:
    for bad in (
        "24 1A 06 07 08 09 01",
        "24 13 06 07 08 09 01",
        "23 02 29 00 00 00 00",
        "24 05 06 07 08 09 07",
    ):
        with pytest.raises(DecodeError):
            ClockRead().decode_response(hexbytes(bad))
    with pytest.raises(DecodeError):
        ClockRead().decode_response(hexbytes("24 05 06 07 08 09"))


def test_clock_write_golden_and_omission_rules() -> None:
    moment = datetime(2024, 5, 6, 7, 8, 9)
    assert ClockWrite.from_datetime(moment).encode() == hexbytes("24 05 06 07 08 09 01")
    assert ClockWrite(moment).encode() == hexbytes("24 05 06 07 08 09")
    assert ClockWrite(moment, 3).encode() == hexbytes("24 05 06 07 08 09 03")
    no_second = ClockWrite(datetime(2024, 5, 6, 7, 8), with_second=False)
    assert no_second.encode() == hexbytes("24 05 06 07 08")
    assert ClockWrite.decode(hexbytes("24 05 06 07 08")) == no_second
    assert ClockWrite.decode(hexbytes("98 12 31 23 59 58 04")) == ClockWrite(
        datetime(1998, 12, 31, 23, 59, 58), 4
    )
    ClockWrite(moment).decode_response(b"")  # no response data: returns None, raises nothing


def test_clock_write_normalises_microseconds_and_zone() -> None:
    aware = datetime(2024, 5, 6, 7, 8, 9, 123456, tzinfo=timezone.utc)
    assert ClockWrite(aware).time == datetime(2024, 5, 6, 7, 8, 9)


def test_clock_write_invalid() -> None:
    with pytest.raises(CommandError, match="year 2098"):
        ClockWrite(datetime(2098, 1, 1))
    with pytest.raises(CommandError, match="year 1997"):
        ClockWrite(datetime(1997, 12, 31))
    with pytest.raises(CommandError, match="day of week 7"):
        ClockWrite(datetime(2024, 1, 1), 7)
    with pytest.raises(CommandError, match="second"):
        ClockWrite(datetime(2024, 1, 1, 0, 0, 5), with_second=False)
    with pytest.raises(CommandError, match="day of week cannot"):
        ClockWrite(datetime(2024, 1, 1), 1, with_second=False)
    with pytest.raises(CommandError, match="datetime"):
        ClockWrite("2024-01-01")  # type: ignore[arg-type]
    for bad, code in (("24 05 06 07", 0x1002), ("24 05 06 07 08 09 01 00", 0x1001),
                      ("24 13 06 07 08", 0x110C), ("24 05 06 07 08 09 09", 0x110C),
                      ("24 05 06 07 0A", 0x110C)):  # fmt: skip
        with pytest.raises(DecodeError) as err:
            ClockWrite.decode(hexbytes(bad))
        assert err.value.end_code == code, bad


@given(plc_times, st.integers(0, 6), st.sampled_from(["full", "no_dow", "no_second"]))
def test_clock_round_trips(moment: datetime, dow: int, form: str) -> None:
    assert ClockRead().decode_response(ClockData(moment, dow).encode()) == ClockData(moment, dow)
    if form == "full":
        req = ClockWrite(moment, dow)
    elif form == "no_dow":
        req = ClockWrite(moment)
    else:
        req = ClockWrite(moment.replace(second=0), with_second=False)
    assert ClockWrite.decode(req.encode()) == req


# --- robustness: arbitrary bytes only ever raise DecodeError --------------------------------

REQUESTS: list[Request[Any]] = [
    CpuUnitDataRead(),
    CpuUnitDataRead(0),
    CpuUnitDataRead(1),
    ConnectionDataRead(),
    CpuUnitStatusRead(),
    CycleTimeRead(),
    CycleTimeRead(CycleTimeParameter.INITIALIZE),
    ClockRead(),
    ClockWrite(datetime(2024, 1, 1)),
]


@pytest.mark.parametrize("req", REQUESTS, ids=lambda r: f"{type(r).__name__}")
@settings(max_examples=60)
@given(data=st.binary(max_size=200))
def test_arbitrary_bytes_raise_only_decode_error(req: Request[Any], data: bytes) -> None:
    for call in (lambda: type(req).decode(data), lambda: req.decode_response(data)):
        with contextlib.suppress(DecodeError):
            call()


@given(st.binary(min_size=150, max_size=170))
def test_cpu_unit_data_near_valid_lengths(data: bytes) -> None:
    try:
        result = CpuUnitDataRead().decode_response(data)
    except DecodeError:
        return
    assert len(data) in (158, 159) and result.configuration is not None


@pytest.mark.parametrize("req", REQUESTS, ids=lambda r: f"{type(r).__name__}")
def test_decode_request_dispatches_to_the_operation(req: Request[Any]) -> None:
    assert decode_request(req.MRC, req.SRC, req.encode()) == req


VALID_RESPONSES: list[tuple[Request[Any], bytes]] = [
    (CpuUnitDataRead(), PART_A + PART_B),
    (ConnectionDataRead(), ConnectionData((UnitModel(0x10, "CJ1W-ETN21"),), True).encode()),
    (CpuUnitStatusRead(), hexbytes("01 04 4000 8010 0005 C123") + b"MOTOR OVERHEAT  "),
    (CycleTimeRead(), CycleTime(1, 2, 3).encode()),
    (ClockRead(), hexbytes("24 05 06 07 08 09 01")),
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
