"""One coroutine per FINS operation of manual section 5 (mixed into :class:`~aiofins.Client`).

Each method builds the operation's typed request, sends it and returns its typed result.
Every method accepts the call options ``dest`` (a :class:`FinsAddress`), ``timeout`` (seconds)
and ``retries``.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from datetime import datetime
from typing import TYPE_CHECKING, TypeVar

from .protocol import arguments as arg
from .protocol.arguments import AddressLike, DataLike, ForceLike
from .protocol.commands._file_manage import (
    CreateDeleteDirectory,
    FileCopy,
    FileDelete,
    FileDeleteResult,
    FileNameChange,
)
from .protocol.commands._file_transfer import (
    FileTransferResult,
    MemoryAreaFileTransfer,
    MemoryCassetteDataType,
    MemoryCassetteTransfer,
    ParameterAreaFileTransfer,
    ProgramAreaFileTransfer,
    ProgramAreaFileTransferResult,
)
from .protocol.commands.access import (
    AccessRightAcquire,
    AccessRightForcedAcquire,
    AccessRightHolder,
    AccessRightRelease,
)
from .protocol.commands.clock import ClockData, ClockRead, ClockWrite
from .protocol.commands.debug import ForcedSetReset, ForcedSetResetCancel
from .protocol.commands.errorlog import (
    ErrorClear,
    ErrorLog,
    ErrorLogClear,
    ErrorLogRead,
    FinsWriteAccessLog,
    FinsWriteAccessLogClear,
    FinsWriteAccessLogRead,
)
from .protocol.commands.file import (
    FILE_READ_OVERHEAD,
    MAX_FILE_READ,
    FileMemoryFormat,
    FileNameRead,
    SingleFileRead,
    SingleFileReadResult,
    SingleFileWrite,
)
from .protocol.commands.gateway import (
    CompowayFResponse,
    ConvertToCompowayFCommand,
    ConvertToModbusAsciiCommand,
    ConvertToModbusRtuCommand,
    ModbusAsciiResponse,
    ModbusRtuResponse,
)
from .protocol.commands.machine import (
    ConnectionData,
    ConnectionDataRead,
    CpuUnitData,
    CpuUnitDataRead,
)
from .protocol.commands.memory import (
    MemoryAreaFill,
    MemoryAreaRead,
    MemoryAreaReadResult,
    MemoryAreaTransfer,
    MemoryAreaWrite,
    MultipleMemoryAreaRead,
    MultipleMemoryAreaReadResult,
)
from .protocol.commands.message import (
    FalFalsMessage,
    FalFalsRead,
    MessageClear,
    MessageRead,
    Messages,
)
from .protocol.commands.mode import Run, RunMode, Stop
from .protocol.commands.parameter import (
    ParameterArea,
    ParameterAreaClear,
    ParameterAreaRead,
    ParameterAreaReadResult,
    ParameterAreaWrite,
)
from .protocol.commands.program import (
    ProgramAreaClear,
    ProgramAreaRead,
    ProgramAreaReadResult,
    ProgramAreaWrite,
    ProgramAreaWriteResult,
    ProgramClearCode,
)
from .protocol.commands.status import (
    CpuUnitStatus,
    CpuUnitStatusRead,
    CycleTime,
    CycleTimeParameter,
    CycleTimeRead,
)
from .protocol.files import (
    CassetteArea,
    CassetteOperation,
    DirectoryOperation,
    Disk,
    FileNameReadResult,
    FileTransferMode,
    FileWriteMode,
)
from .protocol.header import FinsAddress

if TYPE_CHECKING:
    from .protocol.commands import Request
    from .protocol.limits import RouteLimits

R = TypeVar("R")


class CommandMethods:
    """The 47 operations as methods; :meth:`call` is provided by the client."""

    async def call(
        self,
        request: Request[R],
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> R:  # pragma: no cover - provided by Client
        raise NotImplementedError

    def route_to(
        self, dest: FinsAddress | str | None = None
    ) -> RouteLimits:  # pragma: no cover - provided by Client
        raise NotImplementedError

    async def memory_area_read(
        self,
        address: AddressLike,
        count: int,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> MemoryAreaReadResult:
        """MEMORY AREA READ (01 01); see :class:`MemoryAreaRead`."""
        return await self.call(
            MemoryAreaRead(address=arg.address(address), count=count),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def memory_area_write(
        self,
        address: AddressLike,
        data: DataLike,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> None:
        """MEMORY AREA WRITE (01 02); see :class:`MemoryAreaWrite`. ``data``: bytes, or one
        int per element (``[5, 6]`` to words, ``[1, 0]`` to bits)."""
        start = arg.address(address)
        return await self.call(
            MemoryAreaWrite(address=start, data=arg.element_data(start, data)),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def memory_area_fill(
        self,
        address: AddressLike,
        count: int,
        value: int,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> None:
        """MEMORY AREA FILL (01 03); see :class:`MemoryAreaFill`."""
        return await self.call(
            MemoryAreaFill(address=arg.address(address), count=count, value=value),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def multiple_memory_area_read(
        self,
        addresses: AddressLike | Iterable[AddressLike],
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> MultipleMemoryAreaReadResult:
        """MULTIPLE MEMORY AREA READ (01 04); see :class:`MultipleMemoryAreaRead`."""
        return await self.call(
            MultipleMemoryAreaRead(addresses=arg.addresses(addresses)),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def memory_area_transfer(
        self,
        source: AddressLike,
        destination: AddressLike,
        count: int,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> None:
        """MEMORY AREA TRANSFER (01 05); see :class:`MemoryAreaTransfer`."""
        return await self.call(
            MemoryAreaTransfer(
                source=arg.address(source, "source"),
                destination=arg.address(destination, "destination"),
                count=count,
            ),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def parameter_area_read(
        self,
        area_code: ParameterArea | int | str,
        begin_word: int,
        count: int,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> ParameterAreaReadResult:
        """PARAMETER AREA READ (02 01); see :class:`ParameterAreaRead`."""
        return await self.call(
            ParameterAreaRead(area_code=_area(area_code), begin_word=begin_word, count=count),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def parameter_area_write(
        self,
        area_code: ParameterArea | int | str,
        begin_word: int,
        words: Iterable[int],
        last: bool | None = None,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> None:
        """PARAMETER AREA WRITE (02 02); see :class:`ParameterAreaWrite`."""
        return await self.call(
            ParameterAreaWrite(
                area_code=_area(area_code),
                begin_word=begin_word,
                words=arg.words(words),
                last=last,
            ),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def parameter_area_clear(
        self,
        area_code: ParameterArea | int | str,
        count: int | None = None,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> None:
        """PARAMETER AREA CLEAR (02 03); see :class:`ParameterAreaClear`."""
        return await self.call(
            ParameterAreaClear(area_code=_area(area_code), count=count),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def program_area_read(
        self,
        address: int,
        byte_count: int,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> ProgramAreaReadResult:
        """PROGRAM AREA READ (03 06); see :class:`ProgramAreaRead`."""
        return await self.call(
            ProgramAreaRead(address=address, byte_count=byte_count),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def program_area_write(
        self,
        address: int,
        data: bytes | bytearray | Sequence[int],
        last: bool = False,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> ProgramAreaWriteResult:
        """PROGRAM AREA WRITE (03 07); see :class:`ProgramAreaWrite`."""
        return await self.call(
            ProgramAreaWrite(address=address, data=arg.payload(data), last=last),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def program_area_clear(
        self,
        clear_code: ProgramClearCode | int | str = ProgramClearCode.WITHOUT_INTERRUPT_TASKS,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> None:
        """PROGRAM AREA CLEAR (03 08); see :class:`ProgramAreaClear`."""
        return await self.call(
            ProgramAreaClear(clear_code=arg.member(ProgramClearCode, clear_code, "clear_code")),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def run(
        self,
        mode: RunMode | int | str = RunMode.MONITOR,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> None:
        """RUN (04 01); see :class:`Run`."""
        return await self.call(
            Run(mode=arg.member(RunMode, mode, "mode")),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def stop(
        self,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> None:
        """STOP (04 02); see :class:`Stop`."""
        return await self.call(Stop(), dest=dest, timeout=timeout, retries=retries)

    async def cpu_unit_data_read(
        self,
        data_type: int | None = None,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> CpuUnitData:
        """CPU UNIT DATA READ (05 01); see :class:`CpuUnitDataRead`."""
        return await self.call(
            CpuUnitDataRead(data_type=data_type), dest=dest, timeout=timeout, retries=retries
        )

    async def connection_data_read(
        self,
        unit_address: int = 0,
        count: int | None = None,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> ConnectionData:
        """CONNECTION DATA READ (05 02); see :class:`ConnectionDataRead`."""
        return await self.call(
            ConnectionDataRead(unit_address=unit_address, count=count),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def cpu_unit_status_read(
        self,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> CpuUnitStatus:
        """CPU UNIT STATUS READ (06 01); see :class:`CpuUnitStatusRead`."""
        return await self.call(CpuUnitStatusRead(), dest=dest, timeout=timeout, retries=retries)

    async def cycle_time_read(
        self,
        parameter: CycleTimeParameter | int | str = CycleTimeParameter.READ,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> CycleTime | None:
        """CYCLE TIME READ (06 20); see :class:`CycleTimeRead`."""
        return await self.call(
            CycleTimeRead(parameter=arg.member(CycleTimeParameter, parameter, "parameter")),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def clock_read(
        self,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> ClockData:
        """CLOCK READ (07 01); see :class:`ClockRead`."""
        return await self.call(ClockRead(), dest=dest, timeout=timeout, retries=retries)

    async def clock_write(
        self,
        time: datetime | str,
        day_of_week: int | None = None,
        with_second: bool = True,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> None:
        """CLOCK WRITE (07 02); see :class:`ClockWrite`."""
        return await self.call(
            ClockWrite(time=arg.moment(time), day_of_week=day_of_week, with_second=with_second),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def message_read(
        self,
        mask: int = 255,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> Messages:
        """MESSAGE READ (09 20); see :class:`MessageRead`."""
        return await self.call(MessageRead(mask=mask), dest=dest, timeout=timeout, retries=retries)

    async def message_clear(
        self,
        mask: int,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> None:
        """MESSAGE CLEAR (09 20); see :class:`MessageClear`."""
        return await self.call(MessageClear(mask=mask), dest=dest, timeout=timeout, retries=retries)

    async def fal_fals_read(
        self,
        number: int,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> FalFalsMessage:
        """FAL/FALS READ (09 20); see :class:`FalFalsRead`."""
        return await self.call(
            FalFalsRead(number=number), dest=dest, timeout=timeout, retries=retries
        )

    async def access_right_acquire(
        self,
        program_number: int = 65535,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> AccessRightHolder | None:
        """ACCESS RIGHT ACQUIRE (0C 01); see :class:`AccessRightAcquire`."""
        return await self.call(
            AccessRightAcquire(program_number=program_number),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def access_right_forced_acquire(
        self,
        program_number: int = 65535,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> None:
        """ACCESS RIGHT FORCED ACQUIRE (0C 02); see :class:`AccessRightForcedAcquire`."""
        return await self.call(
            AccessRightForcedAcquire(program_number=program_number),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def access_right_release(
        self,
        program_number: int = 65535,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> None:
        """ACCESS RIGHT RELEASE (0C 03); see :class:`AccessRightRelease`."""
        return await self.call(
            AccessRightRelease(program_number=program_number),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def error_clear(
        self,
        error_code: int = 65534,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> None:
        """ERROR CLEAR (21 01); see :class:`ErrorClear`."""
        return await self.call(
            ErrorClear(error_code=error_code), dest=dest, timeout=timeout, retries=retries
        )

    async def error_log_read(
        self,
        beginning_record: int = 0,
        count: int = 20,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> ErrorLog:
        """ERROR LOG READ (21 02); see :class:`ErrorLogRead`."""
        return await self.call(
            ErrorLogRead(beginning_record=beginning_record, count=count),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def error_log_clear(
        self,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> None:
        """ERROR LOG CLEAR (21 03); see :class:`ErrorLogClear`."""
        return await self.call(ErrorLogClear(), dest=dest, timeout=timeout, retries=retries)

    async def fins_write_access_log_read(
        self,
        beginning_record: int = 0,
        count: int = 20,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> FinsWriteAccessLog:
        """FINS WRITE ACCESS LOG READ (21 40); see :class:`FinsWriteAccessLogRead`."""
        return await self.call(
            FinsWriteAccessLogRead(beginning_record=beginning_record, count=count),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def fins_write_access_log_clear(
        self,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> None:
        """FINS WRITE ACCESS LOG CLEAR (21 41); see :class:`FinsWriteAccessLogClear`."""
        return await self.call(
            FinsWriteAccessLogClear(), dest=dest, timeout=timeout, retries=retries
        )

    async def file_name_read(
        self,
        disk: Disk | str,
        first_file: int = 0,
        count: int = 20,
        directory: str = "",
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> FileNameReadResult:
        """FILE NAME READ (22 01); see :class:`FileNameRead`."""
        return await self.call(
            FileNameRead(disk=_disk(disk), first_file=first_file, count=count, directory=directory),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def single_file_read(
        self,
        disk: Disk | str,
        name: str,
        position: int = 0,
        length: int | None = None,
        directory: str = "",
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> SingleFileReadResult:
        """SINGLE FILE READ (22 02); see :class:`SingleFileRead`. ``length`` defaults to the
        most one response carries on the route to ``dest`` (1,988 bytes on Ethernet, 528 over
        Host Link), so the default never asks for more than the route can answer."""
        if length is None:
            carried = self.route_to(dest).max_response_data_bytes - FILE_READ_OVERHEAD
            length = max(0, min(MAX_FILE_READ, carried))
        return await self.call(
            SingleFileRead(
                disk=_disk(disk), name=name, position=position, length=length, directory=directory
            ),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def single_file_write(
        self,
        disk: Disk | str,
        name: str,
        data: bytes | bytearray | Sequence[int],
        mode: FileWriteMode | int | str = FileWriteMode.NEW,
        position: int = 0,
        directory: str = "",
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> None:
        """SINGLE FILE WRITE (22 03); see :class:`SingleFileWrite`."""
        return await self.call(
            SingleFileWrite(
                disk=_disk(disk),
                name=name,
                data=arg.payload(data),
                mode=arg.member(FileWriteMode, mode, "mode"),
                position=position,
                directory=directory,
            ),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def file_memory_format(
        self,
        disk: Disk | str,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> None:
        """FILE MEMORY FORMAT (22 04); see :class:`FileMemoryFormat`."""
        return await self.call(
            FileMemoryFormat(disk=_disk(disk)), dest=dest, timeout=timeout, retries=retries
        )

    async def file_delete(
        self,
        disk: Disk | str,
        names: str | Iterable[str],
        directory: str = "",
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> FileDeleteResult:
        """FILE DELETE (22 05); see :class:`FileDelete`."""
        return await self.call(
            FileDelete(disk=_disk(disk), names=arg.names(names), directory=directory),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def file_copy(
        self,
        source_disk: Disk | str,
        source_name: str,
        destination_disk: Disk | str,
        destination_name: str,
        source_directory: str = "",
        destination_directory: str = "",
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> None:
        """FILE COPY (22 07); see :class:`FileCopy`."""
        return await self.call(
            FileCopy(
                source_disk=_disk(source_disk),
                source_name=source_name,
                destination_disk=_disk(destination_disk),
                destination_name=destination_name,
                source_directory=source_directory,
                destination_directory=destination_directory,
            ),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def file_name_change(
        self,
        disk: Disk | str,
        old_name: str,
        new_name: str,
        directory: str = "",
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> None:
        """FILE NAME CHANGE (22 08); see :class:`FileNameChange`."""
        return await self.call(
            FileNameChange(
                disk=_disk(disk), old_name=old_name, new_name=new_name, directory=directory
            ),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def memory_area_file_transfer(
        self,
        mode: FileTransferMode | int | str,
        address: AddressLike,
        count: int,
        disk: Disk | str,
        name: str,
        directory: str = "",
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> FileTransferResult:
        """MEMORY AREA-FILE TRANSFER (22 0A); see :class:`MemoryAreaFileTransfer`."""
        return await self.call(
            MemoryAreaFileTransfer(
                mode=_transfer(mode),
                address=arg.address(address),
                count=count,
                disk=_disk(disk),
                name=name,
                directory=directory,
            ),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def parameter_area_file_transfer(
        self,
        mode: FileTransferMode | int | str,
        area_code: ParameterArea | int | str,
        disk: Disk | str,
        name: str,
        directory: str = "",
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> FileTransferResult:
        """PARAMETER AREA-FILE TRANSFER (22 0B); see :class:`ParameterAreaFileTransfer`.

        The whole area always: beginning word 0000 and number of items FFFF, as the manual
        fixes them (5-3-40)."""
        return await self.call(
            ParameterAreaFileTransfer(
                mode=_transfer(mode),
                area_code=_area(area_code),
                disk=_disk(disk),
                name=name,
                directory=directory,
            ),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def program_area_file_transfer(
        self,
        mode: FileTransferMode | int | str,
        disk: Disk | str,
        name: str,
        directory: str = "",
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> ProgramAreaFileTransferResult:
        """PROGRAM AREA-FILE TRANSFER (22 0C); see :class:`ProgramAreaFileTransfer`.

        The whole program always: program number FFFF, beginning word 00000000 and number
        of bytes FFFFFFFF, as the manual fixes them (5-3-41)."""
        return await self.call(
            ProgramAreaFileTransfer(
                mode=_transfer(mode),
                disk=_disk(disk),
                name=name,
                directory=directory,
            ),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def create_delete_directory(
        self,
        disk: Disk | str,
        operation: DirectoryOperation | int | str,
        name: str,
        directory: str = "",
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> None:
        """CREATE/DELETE DIRECTORY (22 15); see :class:`CreateDeleteDirectory`."""
        return await self.call(
            CreateDeleteDirectory(
                disk=_disk(disk),
                operation=arg.member(DirectoryOperation, operation, "operation"),
                name=name,
                directory=directory,
            ),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def memory_cassette_transfer(
        self,
        operation: CassetteOperation | int | str,
        areas: CassetteArea = CassetteArea(0),  # noqa: B008
        disk: Disk | str = Disk.MEMORY_CASSETTE,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> MemoryCassetteDataType | None:
        """MEMORY CASSETTE TRANSFER (22 20); see :class:`MemoryCassetteTransfer`."""
        return await self.call(
            MemoryCassetteTransfer(
                operation=arg.member(CassetteOperation, operation, "operation"),
                areas=areas,
                disk=_disk(disk),
            ),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def forced_set_reset(
        self,
        entries: ForceLike | Iterable[ForceLike],
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> None:
        """FORCED SET/RESET (23 01); see :class:`ForcedSetReset`."""
        return await self.call(
            ForcedSetReset(entries=arg.force_entries(entries)),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def forced_set_reset_cancel(
        self,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> None:
        """FORCED SET/RESET CANCEL (23 02); see :class:`ForcedSetResetCancel`."""
        return await self.call(ForcedSetResetCancel(), dest=dest, timeout=timeout, retries=retries)

    async def convert_to_compoway_f_command(
        self,
        payload: bytes | bytearray | Sequence[int],
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> CompowayFResponse:
        """CONVERT TO COMPOWAY/F COMMAND (28 03); see :class:`ConvertToCompowayFCommand`."""
        return await self.call(
            ConvertToCompowayFCommand(payload=arg.payload(payload, "payload")),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def convert_to_modbus_rtu_command(
        self,
        payload: bytes | bytearray | Sequence[int],
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> ModbusRtuResponse:
        """CONVERT TO MODBUS-RTU COMMAND (28 04); see :class:`ConvertToModbusRtuCommand`."""
        return await self.call(
            ConvertToModbusRtuCommand(payload=arg.payload(payload, "payload")),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )

    async def convert_to_modbus_ascii_command(
        self,
        payload: bytes | bytearray | Sequence[int],
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> ModbusAsciiResponse:
        """CONVERT TO MODBUS-ASCII COMMAND (28 05); see :class:`ConvertToModbusAsciiCommand`."""
        return await self.call(
            ConvertToModbusAsciiCommand(payload=arg.payload(payload, "payload")),
            dest=dest,
            timeout=timeout,
            retries=retries,
        )


def _disk(value: Disk | str) -> Disk:
    return arg.member(Disk, value, "disk")


def _transfer(value: FileTransferMode | int | str) -> FileTransferMode:
    return arg.member(FileTransferMode, value, "mode")


def _area(value: ParameterArea | int | str) -> int:
    return arg.member(ParameterArea, value, "area_code")
