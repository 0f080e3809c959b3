"""Machine configuration, status and clock: 0501, 0502, 0601, 0620, 0701, 0702."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ...protocol.commands.clock import ClockData, ClockRead, ClockWrite
from ...protocol.commands.machine import (
    AreaData,
    ConnectionData,
    ConnectionDataRead,
    CpuUnitConfiguration,
    CpuUnitData,
    CpuUnitDataRead,
    CpuUnitModelData,
    UnitModel,
)
from ...protocol.commands.status import (
    STATUS_BATTERY_PRESENT,
    STATUS_RUNNING,
    CpuMode,
    CpuUnitStatus,
    CpuUnitStatusRead,
    CycleTime,
    CycleTimeParameter,
    CycleTimeRead,
    FatalError,
    NonFatalError,
)
from ...protocol.files import Disk
from ..codes import by_command_code
from ..state import Mode
from ._call import Call, Handler, request_of

if TYPE_CHECKING:
    from ..plc import VirtualPLC

CPU_UNIT = 0x00
MEMORY_CARD_FLASH = 0x04


def _model_data(plc: VirtualPLC) -> CpuUnitModelData:
    card = plc.file_memory.get(Disk.MEMORY_CARD)
    area = AreaData(
        program_area_size=len(plc.program) // 2048,  # K words
        iom_size=23,
        dm_words=32768,
        timer_counter_size=8,
        em_non_file_banks=plc.memory.em_banks,
        memory_card_type=MEMORY_CARD_FLASH if card else 0x00,
        memory_card_size=min(card.capacity // 1024, 0xFFFF) if card else 0,
    )
    return CpuUnitModelData(
        model=plc.model,
        internal_system_version=plc.version,
        dip_switches=0x01 if plc.um_write_protected else 0x00,  # pin 1: UM write protection
        largest_em_bank=max(plc.memory.em_banks - 1, 0),
        area_data=area,
    )


def _configuration() -> CpuUnitConfiguration:
    # no CPU Bus Units, no SYSMAC BUS masters, one rack (the CPU Rack)
    return CpuUnitConfiguration(
        cpu_bus_units=(0,) * 16, remote_io_masters=0, cpu_unit_information=1
    )


def cpu_unit_data_read(plc: VirtualPLC, call: Call) -> bytes:
    req = request_of(call, CpuUnitDataRead)
    model = _model_data(plc) if req.data_type in (None, 0x00) else None
    configuration = _configuration() if req.data_type in (None, 0x01) else None
    return CpuUnitData(model, configuration).encode()


def connection_data_read(plc: VirtualPLC, call: Call) -> bytes:
    req = request_of(call, ConnectionDataRead)
    if req.unit_address > CPU_UNIT:  # the CPU Unit is the only unit
        return ConnectionData((), last=True).encode()
    return ConnectionData((UnitModel(CPU_UNIT, plc.model),), last=True).encode()


def cpu_unit_status_read(plc: VirtualPLC, call: Call) -> bytes:
    request_of(call, CpuUnitStatusRead)
    return CpuUnitStatus(
        status=STATUS_BATTERY_PRESENT | (STATUS_RUNNING if plc.mode is not Mode.PROGRAM else 0),
        mode=CpuMode(int(plc.mode)),
        fatal_errors=FatalError(plc.fatal_errors),
        non_fatal_errors=NonFatalError(plc.non_fatal_errors),
        message_flags=sum(1 << n for n in plc.messages if 0 <= n <= 7),
        error_code=plc.error_code,
        error_message=plc.error_message,
    ).encode()


def cycle_time_read(plc: VirtualPLC, call: Call) -> bytes:
    req = request_of(call, CycleTimeRead)
    if req.parameter == CycleTimeParameter.INITIALIZE:
        plc.cycle_min = plc.cycle_max = plc.cycle_times[-1]
        return b""
    average = sum(plc.cycle_times) // len(plc.cycle_times)
    return CycleTime(average, plc.cycle_max, plc.cycle_min).encode()


def clock_read(plc: VirtualPLC, call: Call) -> bytes:
    request_of(call, ClockRead)
    return ClockData(plc.now().replace(microsecond=0), plc.weekday()).encode()


def clock_write(plc: VirtualPLC, call: Call) -> bytes:
    # the codec refuses out-of-range data (manual 5-3-20: then the clock is not set); an
    # omitted second is 00 and an omitted day of week keeps its previous value
    req = request_of(call, ClockWrite)
    plc.set_clock(req.time, req.day_of_week)
    return b""


HANDLERS: dict[int, Handler] = by_command_code(
    {
        CpuUnitDataRead: cpu_unit_data_read,
        ConnectionDataRead: connection_data_read,
        CpuUnitStatusRead: cpu_unit_status_read,
        CycleTimeRead: cycle_time_read,
        ClockRead: clock_read,
        ClockWrite: clock_write,
    }
)
