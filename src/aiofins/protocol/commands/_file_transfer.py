"""File memory commands 220A, 220B, 220C and 2220 (manual 5-3-39..5-3-41, 5-3-43): area ↔
file transfers and the CP-series Memory Cassette. Exported through :mod:`.file`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, TypeVar

from ..areas import MemoryAddress
from ..codec import Reader
from ..decoding import as_decode_error
from ..errors import AddressError, CommandError, DecodeError
from ..files import (
    ALL_CASSETTE_AREAS,
    CASSETTE_AREA_BITS,
    CassetteArea,
    CassetteContents,
    CassetteOperation,
    Disk,
    FileTransferMode,
    check_directory,
    check_disk,
    check_file_name,
    check_u,
    coerce_enum,
    encode_directory,
    encode_file_name,
    read_directory,
    read_disk,
    read_file_name,
)
from ._base import expect_no_data, finish
from ._file_common import FileCommand, read_number, set_field, u16, u32
from .program import PROGRAM_NUMBER

#: Memory area codes 220A accepts (word data only): CIO/W/H/A, T/C PV, DM, EM banks 0..18
#: (A0..AF; 50..5F on CJ2; 60..68), current EM bank.
FILE_TRANSFER_AREA_CODES: frozenset[int] = frozenset(
    {0xB0, 0xB1, 0xB2, 0xB3, 0x89, 0x82, 0x98}
    | set(range(0xA0, 0xB0))
    | set(range(0x50, 0x60))
    | set(range(0x60, 0x69))
)
#: Parameter area codes 220B accepts: whole area, CPU Bus Unit setup, PLC Setup,
#: I/O table registration, routing tables.
FILE_TRANSFER_PARAMETER_AREAS: frozenset[int] = frozenset({0x8000, 0x8002, 0x8010, 0x8012, 0x8013})

R = TypeVar("R")
T = TypeVar("T", bound="_AreaFileTransfer[Any]")


@dataclass(frozen=True, slots=True)
class FileTransferResult:
    """220A/220B response: items (words) transferred, or compared without a mismatch."""

    count: int

    def __post_init__(self) -> None:
        check_u("number of items", self.count, 16)

    def encode(self) -> bytes:
        return u16(self.count)

    @classmethod
    def decode(cls, data: bytes, what: str = "transfer response") -> FileTransferResult:
        return cls(read_number(data, what))


@dataclass(frozen=True, slots=True)
class ProgramAreaFileTransferResult:
    """220C response: bytes transferred, or compared without a mismatch."""

    length: int

    def __post_init__(self) -> None:
        check_u("data length", self.length, 32)

    def encode(self) -> bytes:
        return u32(self.length)

    @classmethod
    def decode(cls, data: bytes) -> ProgramAreaFileTransferResult:
        return cls(read_number(data, "PROGRAM AREA-FILE TRANSFER response", 4))


class _AreaFileTransfer(FileCommand[R]):
    """The layout 220A/220B/220C share: parameter code (``mode``), what to transfer (each
    command's own fields: ``_check_area``, ``_encode_area``, ``_read_area``), disk, file name,
    directory."""

    mode: FileTransferMode
    disk: Disk
    name: str
    directory: str

    def __post_init__(self) -> None:
        mode = coerce_enum(FileTransferMode, self.mode, "transfer parameter code")
        set_field(self, "mode", mode)
        self._check_area()
        set_field(self, "disk", check_disk(self.disk))
        check_file_name(self.name)
        set_field(self, "directory", check_directory(self.directory))

    def _check_area(self) -> None:
        raise NotImplementedError

    def _encode_area(self) -> bytes:
        raise NotImplementedError

    @classmethod
    def _read_area(cls, r: Reader) -> dict[str, Any]:
        """The command's own fields, by name; :class:`DecodeError` for values a PLC rejects."""
        raise NotImplementedError

    def encode(self) -> bytes:
        return (
            u16(self.mode)
            + self._encode_area()
            + u16(self.disk)
            + encode_file_name(self.name)
            + encode_directory(self.directory)
        )

    @classmethod
    def decode(cls: type[T], params: bytes) -> T:
        r = Reader(params, cls.NAME)
        value = r.u16()
        with as_decode_error("parameter code"):
            mode = coerce_enum(FileTransferMode, value, "transfer parameter code")
        area = cls._read_area(r)
        disk, name, directory = read_disk(r), read_file_name(r), read_directory(r)
        return finish(cls, r, mode=mode, disk=disk, name=name, directory=directory, **area)


#: The fixed parameters of 220B (manual 5-3-40): the whole parameter area, from word 0.
PARAMETER_FILE_BEGIN = 0x0000
PARAMETER_FILE_COUNT = 0xFFFF
#: The fixed parameters of 220C (manual 5-3-41): the whole program, from byte 0.
PROGRAM_FILE_BEGIN = 0x00000000
PROGRAM_FILE_BYTES = 0xFFFFFFFF

# --------------------------------------------------------------------------- 220A


@dataclass(frozen=True)
class MemoryAreaFileTransfer(_AreaFileTransfer[FileTransferResult]):
    """220A: transfer ``count`` words from ``address`` to a file, back, or compare them."""

    SRC: ClassVar[int] = 0x0A
    NAME: ClassVar[str] = "MEMORY AREA-FILE TRANSFER"
    METHOD: ClassVar[str] = "memory_area_file_transfer"

    mode: FileTransferMode
    address: MemoryAddress
    count: int
    disk: Disk
    name: str
    directory: str = ""

    def _check_area(self) -> None:
        if self.address.area_code not in FILE_TRANSFER_AREA_CODES:
            raise AddressError(
                f"memory area code {self.address.area_code:02X} cannot be transferred to a file "
                "(word areas CIO/W/H/A, T/C PV, DM and EM only)"
            )
        if self.address.bit:
            raise AddressError(f"bit number {self.address.bit} must be 0 (word transfer)")
        check_u("number of items", self.count, 16, low=1)

    def _encode_area(self) -> bytes:
        return self.address.encode() + u16(self.count)

    @classmethod
    def _read_area(cls, r: Reader) -> dict[str, Any]:
        address = MemoryAddress.decode(r.take(4))
        if address.area_code not in FILE_TRANSFER_AREA_CODES:
            raise DecodeError(f"memory area code {address.area_code:02X}", end_code=0x1101)
        if address.bit:
            raise DecodeError(f"bit number {address.bit} in a word transfer", end_code=0x1103)
        return {"address": address, "count": r.u16()}

    def decode_response(self, data: bytes) -> FileTransferResult:
        return FileTransferResult.decode(data, f"{self.NAME} response")


# --------------------------------------------------------------------------- 220B


@dataclass(frozen=True)
class ParameterAreaFileTransfer(_AreaFileTransfer[FileTransferResult]):
    """220B: transfer a parameter area to a file, back, or compare them.

    The manual fixes ``begin`` 0000 and ``count`` FFFF (the whole area, 5-3-40): other
    values are refused before anything is sent, and a command carrying them is answered
    with 1103 (beginning word) or 1104 (number of items) by the simulator.
    """

    SRC: ClassVar[int] = 0x0B
    NAME: ClassVar[str] = "PARAMETER AREA-FILE TRANSFER"
    METHOD: ClassVar[str] = "parameter_area_file_transfer"

    mode: FileTransferMode
    area_code: int
    disk: Disk
    name: str
    begin: int = 0
    count: int = 0xFFFF
    directory: str = ""

    def _check_area(self) -> None:
        if self.area_code not in FILE_TRANSFER_PARAMETER_AREAS:
            codes = ", ".join(f"{c:04X}" for c in sorted(FILE_TRANSFER_PARAMETER_AREAS))
            raise CommandError(f"parameter area code {self.area_code!r} is not one of {codes}")
        if self.begin != PARAMETER_FILE_BEGIN:
            raise CommandError(f"beginning word {self.begin!r} must be 0 (manual 5-3-40)")
        if self.count != PARAMETER_FILE_COUNT:
            raise CommandError(f"number of items {self.count!r} must be FFFF hex (5-3-40)")

    def _encode_area(self) -> bytes:
        return u16(self.area_code) + u16(self.begin) + u16(self.count)

    @classmethod
    def _read_area(cls, r: Reader) -> dict[str, Any]:
        area_code = r.u16()
        if area_code not in FILE_TRANSFER_PARAMETER_AREAS:
            raise DecodeError(f"parameter area code {area_code:04X}", end_code=0x1101)
        begin, count = r.u16(), r.u16()
        if begin != PARAMETER_FILE_BEGIN:
            raise DecodeError(f"beginning word {begin:04X} (always 0000)", end_code=0x1103)
        if count != PARAMETER_FILE_COUNT:
            raise DecodeError(f"number of items {count:04X} (always FFFF)", end_code=0x1104)
        return {"area_code": area_code, "begin": begin, "count": count}

    def decode_response(self, data: bytes) -> FileTransferResult:
        return FileTransferResult.decode(data, f"{self.NAME} response")


# --------------------------------------------------------------------------- 220C


@dataclass(frozen=True)
class ProgramAreaFileTransfer(_AreaFileTransfer[ProgramAreaFileTransferResult]):
    """220C: transfer the user program to a file, back (PROGRAM mode), or compare them.

    The manual fixes program number FFFF, beginning word 00000000, bytes FFFFFFFF
    (5-3-41): other values are refused before anything is sent, and a command carrying
    them is answered with 1106, 1103 or 1104 by the simulator.
    """

    SRC: ClassVar[int] = 0x0C
    NAME: ClassVar[str] = "PROGRAM AREA-FILE TRANSFER"
    METHOD: ClassVar[str] = "program_area_file_transfer"

    mode: FileTransferMode
    disk: Disk
    name: str
    program_number: int = PROGRAM_NUMBER
    begin_word: int = 0
    byte_count: int = 0xFFFFFFFF
    # The manual's text labels the directory "(response)" for 220C; it names the file's
    # location, so it travels in the command like in every other 22xx command.
    directory: str = ""

    def _check_area(self) -> None:
        if self.program_number != PROGRAM_NUMBER:
            raise CommandError(f"program number {self.program_number!r} must be FFFF hex")
        if self.begin_word != PROGRAM_FILE_BEGIN:
            raise CommandError(f"beginning word {self.begin_word!r} must be 0 (manual 5-3-41)")
        if self.byte_count != PROGRAM_FILE_BYTES:
            raise CommandError(
                f"number of bytes {self.byte_count!r} must be FFFFFFFF hex (manual 5-3-41)"
            )

    def _encode_area(self) -> bytes:
        return u16(self.program_number) + u32(self.begin_word) + u32(self.byte_count)

    @classmethod
    def _read_area(cls, r: Reader) -> dict[str, Any]:
        program_number = r.u16()
        if program_number != PROGRAM_NUMBER:
            raise DecodeError(f"program number {program_number:04X}", end_code=0x1106)
        begin, size = r.u32(), r.u32()
        if begin != PROGRAM_FILE_BEGIN:
            raise DecodeError(f"beginning word {begin:08X} (always 00000000)", end_code=0x1103)
        if size != PROGRAM_FILE_BYTES:
            raise DecodeError(f"number of bytes {size:08X} (always FFFFFFFF)", end_code=0x1104)
        return {"program_number": program_number, "begin_word": begin, "byte_count": size}

    def decode_response(self, data: bytes) -> ProgramAreaFileTransferResult:
        return ProgramAreaFileTransferResult.decode(data)


# --------------------------------------------------------------------------- 2220


@dataclass(frozen=True, slots=True)
class MemoryCassetteDataType:
    """2220 READ_DATA_TYPE response: which data the Memory Cassette holds."""

    contents: CassetteContents

    def __post_init__(self) -> None:
        check_u("stored data type", int(self.contents), 16)
        object.__setattr__(self, "contents", CassetteContents(self.contents))

    def encode(self) -> bytes:
        return u16(int(self.contents))

    @classmethod
    def decode(cls, data: bytes) -> MemoryCassetteDataType:
        return cls(CassetteContents(read_number(data, "MEMORY CASSETTE TRANSFER response")))


@dataclass(frozen=True)
class MemoryCassetteTransfer(FileCommand[MemoryCassetteDataType | None]):
    """2220 (CP1H/CP1L): transfer, verify or initialise the Memory Cassette, or read which
    data it holds (:attr:`CassetteOperation.READ_DATA_TYPE`, the only one with a result).

    ``areas`` 0 means all areas; ``INDIVIDUAL | DATA_MEMORY | ...`` selects some. Layout
    (from the manual's parameter list; its diagrams are not in our copy): disk 8003,
    parameter, then the data type designation except for READ_DATA_TYPE.
    """

    SRC: ClassVar[int] = 0x20
    NAME: ClassVar[str] = "MEMORY CASSETTE TRANSFER"
    METHOD: ClassVar[str] = "memory_cassette_transfer"

    operation: CassetteOperation
    areas: CassetteArea = ALL_CASSETTE_AREAS
    disk: Disk = Disk.MEMORY_CASSETTE

    def __post_init__(self) -> None:
        op = coerce_enum(CassetteOperation, self.operation, "memory cassette parameter")
        set_field(self, "operation", op)
        set_field(self, "disk", check_disk(self.disk, frozenset({Disk.MEMORY_CASSETTE})))
        value = int(self.areas)
        check_u("data type designation", value, 16)
        if value & ~(CASSETTE_AREA_BITS | CassetteArea.INDIVIDUAL):
            raise CommandError(f"data type designation {value:04X} sets reserved bits")
        individual = bool(value & CassetteArea.INDIVIDUAL)
        if individual != bool(value & CASSETTE_AREA_BITS):
            raise CommandError(
                f"data type designation {value:04X}: set INDIVIDUAL together with the "
                "areas to transfer, or nothing for all areas"
            )
        if op is CassetteOperation.READ_DATA_TYPE and value:
            raise CommandError("READ_DATA_TYPE takes no data type designation")
        set_field(self, "areas", CassetteArea(value))

    def encode(self) -> bytes:
        out = u16(self.disk) + u16(self.operation)
        if self.operation is not CassetteOperation.READ_DATA_TYPE:
            out += u16(int(self.areas))
        return out

    @classmethod
    def decode(cls, params: bytes) -> MemoryCassetteTransfer:
        r = Reader(params, cls.NAME)
        disk_value, op_value = r.u16(), r.u16()
        with as_decode_error(cls.NAME):
            disk = check_disk(disk_value, frozenset({Disk.MEMORY_CASSETTE}))
            operation = coerce_enum(CassetteOperation, op_value, "memory cassette parameter")
        areas = 0 if operation is CassetteOperation.READ_DATA_TYPE else r.u16()
        return finish(cls, r, operation, CassetteArea(areas), disk)

    def decode_response(self, data: bytes) -> MemoryCassetteDataType | None:
        if self.operation is CassetteOperation.READ_DATA_TYPE:
            return MemoryCassetteDataType.decode(data)
        expect_no_data(self, data)
        return None
