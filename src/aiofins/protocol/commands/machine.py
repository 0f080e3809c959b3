"""Machine configuration reading (manual 5-3-15, 5-3-16): 05 01 CPU UNIT DATA READ,
05 02 CONNECTION DATA READ.

05 01 answers in two parts. Data type ``00`` returns part A (92 bytes: model, internal
system version, system block, area data); ``01`` returns part B (CPU Bus Unit
configuration, remote I/O data, CPU Unit information); no data type returns A then B.
Part B is 66 bytes on CS/CJ (one remote I/O byte) and 67 on CV-series CPUs (two bytes:
SYSMAC BUS/2 masters, SYSMAC BUS masters); the decoder tells them apart by length.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from ..codec import Reader, ascii_field, check_range, pad_ascii
from ..decoding import as_decode_error
from ..errors import CommandError, DecodeError
from ._base import Request

MODEL_SIZE = 20
PART_A_SIZE = 92
PART_B_SIZE_CS = 66
PART_B_SIZE_CV = 67
SYSTEM_RESERVED_SIZE = 38
BUS_RESERVED_SIZE = 32
CPU_BUS_UNITS = 16

#: 05 01 data type: part A only / part B only (``None``: both).
DATA_TYPE_MODEL = 0x00
DATA_TYPE_CONFIGURATION = 0x01


@dataclass(frozen=True, slots=True)
class AreaData:
    """The 12-byte area data block of 05 01 part A."""

    #: Usable program area, K words.
    program_area_size: int
    #: Area usable by bit commands (CIO, WR, HR, AR, T/C flags, TN), K bytes (CS/CJ: 23).
    iom_size: int
    #: Words in the DM area (CS/CJ: 32768).
    dm_words: int
    #: Timers/counters available, x 1024 (CS/CJ: 8).
    timer_counter_size: int
    #: EM banks without file memory.
    em_non_file_banks: int
    #: Memory card type: 00 none, 04 flash memory.
    memory_card_type: int
    #: Memory card size in K bytes (0 without a card).
    memory_card_size: int
    #: Two bytes the manual leaves unused (CV: number of steps/transitions).
    reserved: int = 0

    def __post_init__(self) -> None:
        check_range("program area size", self.program_area_size, 0, 0xFFFF)
        check_range("IOM size", self.iom_size, 0, 0xFF)
        check_range("number of DM words", self.dm_words, 0, 0xFFFF)
        check_range("timer/counter size", self.timer_counter_size, 0, 0xFF)
        check_range("EM non-file memory size", self.em_non_file_banks, 0, 0xFF)
        check_range("memory card type", self.memory_card_type, 0, 0xFF)
        check_range("memory card size", self.memory_card_size, 0, 0xFFFF)
        check_range("area data reserved word", self.reserved, 0, 0xFFFF)

    def encode(self) -> bytes:
        return (
            self.program_area_size.to_bytes(2, "big")
            + bytes((self.iom_size,))
            + self.dm_words.to_bytes(2, "big")
            + bytes((self.timer_counter_size, self.em_non_file_banks))
            + self.reserved.to_bytes(2, "big")
            + bytes((self.memory_card_type,))
            + self.memory_card_size.to_bytes(2, "big")
        )

    @classmethod
    def read(cls, r: Reader) -> AreaData:
        program, iom, dm = r.u16(), r.u8(), r.u16()
        tc, em, reserved = r.u8(), r.u8(), r.u16()
        card_type, card_size = r.u8(), r.u16()
        return cls(program, iom, dm, tc, em, card_type, card_size, reserved)


@dataclass(frozen=True, slots=True)
class CpuUnitModelData:
    """Part A of 05 01: model, internal system version, system block, area data."""

    model: str
    internal_system_version: str
    #: DIP switch pins 0-7 on the CPU's front panel as bits 0-7.
    dip_switches: int
    #: Largest EM bank number (0-19).
    largest_em_bank: int
    area_data: AreaData
    #: The rest of the 40-byte system block, reserved.
    system_reserved: bytes = bytes(SYSTEM_RESERVED_SIZE)

    def __post_init__(self) -> None:
        check_range("DIP switch data", self.dip_switches, 0, 0xFF)
        check_range("largest EM bank number", self.largest_em_bank, 0, 0xFF)
        if len(self.system_reserved) != SYSTEM_RESERVED_SIZE:
            raise CommandError(f"system_reserved must be {SYSTEM_RESERVED_SIZE} bytes")

    def dip_switch(self, pin: int) -> bool:
        """Whether DIP switch ``pin`` (0-7) is ON."""
        check_range("DIP switch pin", pin, 0, 7)
        return bool(self.dip_switches >> pin & 1)

    def encode(self) -> bytes:
        # Model: space padded; internal system version: NUL padded (manual 5-3-15).
        return (
            pad_ascii(self.model, MODEL_SIZE, "CPU Unit model")
            + pad_ascii(self.internal_system_version, MODEL_SIZE, "system version", b"\x00")
            + bytes((self.dip_switches, self.largest_em_bank))
            + bytes(self.system_reserved)
            + self.area_data.encode()
        )

    @classmethod
    def read(cls, r: Reader) -> CpuUnitModelData:
        model = ascii_field(r.take(MODEL_SIZE))
        version = ascii_field(r.take(MODEL_SIZE))
        dip, em = r.u8(), r.u8()
        reserved = r.take(SYSTEM_RESERVED_SIZE)
        return cls(model, version, dip, em, AreaData.read(r), reserved)


@dataclass(frozen=True, slots=True)
class CpuUnitConfiguration:
    """Part B of 05 01: CPU Bus Unit configuration, remote I/O data, CPU Unit information."""

    #: Code of each CPU Bus Unit 0-15, two bytes each (CS/CJ: bit 15 = present,
    #: bits 0-14 = model ID; CV: two ASCII characters).
    cpu_bus_units: tuple[int, ...]
    #: SYSMAC BUS Master Units mounted (00-02).
    remote_io_masters: int
    #: CPU Unit information byte; bits 0-3 = racks connected (CPU + expansion).
    cpu_unit_information: int
    #: CV-series only: SYSMAC BUS/2 masters (its part B has two remote I/O bytes).
    sysmac_bus2_masters: int | None = None
    #: The 32 reserved bytes after the 16 unit codes.
    reserved: bytes = bytes(BUS_RESERVED_SIZE)

    def __post_init__(self) -> None:
        units = tuple(self.cpu_bus_units)
        object.__setattr__(self, "cpu_bus_units", units)
        if len(units) != CPU_BUS_UNITS:
            raise CommandError(f"cpu_bus_units needs {CPU_BUS_UNITS} codes, got {len(units)}")
        for n, code in enumerate(units):
            check_range(f"CPU Bus Unit {n} code", code, 0, 0xFFFF)
        check_range("remote I/O masters", self.remote_io_masters, 0, 0xFF)
        check_range("CPU Unit information", self.cpu_unit_information, 0, 0xFF)
        if self.sysmac_bus2_masters is not None:
            check_range("SYSMAC BUS/2 masters", self.sysmac_bus2_masters, 0, 0xFF)
        if len(self.reserved) != BUS_RESERVED_SIZE:
            raise CommandError(f"reserved must be {BUS_RESERVED_SIZE} bytes")

    @property
    def racks(self) -> int:
        """Racks connected to the CPU Unit (CPU Rack + Expansion Racks)."""
        return self.cpu_unit_information & 0x0F

    def unit_present(self, unit_number: int) -> bool:
        """CS/CJ: whether CPU Bus Unit ``unit_number`` is mounted (bit 15 of its code)."""
        check_range("unit number", unit_number, 0, CPU_BUS_UNITS - 1)
        return bool(self.cpu_bus_units[unit_number] & 0x8000)

    def encode(self) -> bytes:
        out = b"".join(code.to_bytes(2, "big") for code in self.cpu_bus_units) + bytes(
            self.reserved
        )
        if self.sysmac_bus2_masters is not None:
            out += bytes((self.sysmac_bus2_masters,))
        return out + bytes((self.remote_io_masters, self.cpu_unit_information))

    @classmethod
    def read(cls, r: Reader, size: int) -> CpuUnitConfiguration:
        units = tuple(r.u16() for _ in range(CPU_BUS_UNITS))
        reserved = r.take(BUS_RESERVED_SIZE)
        bus2 = r.u8() if size == PART_B_SIZE_CV else None
        return cls(units, r.u8(), r.u8(), bus2, reserved)


@dataclass(frozen=True, slots=True)
class CpuUnitData:
    """Response of CPU UNIT DATA READ: the parts the data type asked for."""

    model_data: CpuUnitModelData | None = None
    configuration: CpuUnitConfiguration | None = None

    def __post_init__(self) -> None:
        if self.model_data is None and self.configuration is None:
            raise CommandError("CpuUnitData needs model_data, configuration or both")

    @property
    def model(self) -> str | None:
        return None if self.model_data is None else self.model_data.model

    @property
    def internal_system_version(self) -> str | None:
        return None if self.model_data is None else self.model_data.internal_system_version

    def encode(self) -> bytes:
        a = b"" if self.model_data is None else self.model_data.encode()
        b = b"" if self.configuration is None else self.configuration.encode()
        return a + b


def _decode_part_b(data: bytes, what: str) -> CpuUnitConfiguration:
    if len(data) not in (PART_B_SIZE_CS, PART_B_SIZE_CV):
        raise DecodeError(
            f"{what}: CPU Bus Unit configuration part needs {PART_B_SIZE_CS} (CS/CJ) or "
            f"{PART_B_SIZE_CV} (CV) bytes, got {len(data)}"
        )
    r = Reader(data, what)
    out = CpuUnitConfiguration.read(r, len(data))
    r.end()
    return out


@dataclass(frozen=True)
class CpuUnitDataRead(Request[CpuUnitData]):
    """05 01 CPU UNIT DATA READ.

    ``data_type``: ``0x00`` model data (part A), ``0x01`` configuration (part B), ``None``
    (the byte omitted) both.
    """

    MRC: ClassVar[int] = 0x05
    SRC: ClassVar[int] = 0x01
    NAME: ClassVar[str] = "CPU UNIT DATA READ"
    METHOD: ClassVar[str] = "cpu_unit_data_read"
    IDEMPOTENT: ClassVar[bool] = True

    data_type: int | None = None

    def __post_init__(self) -> None:
        if self.data_type not in (None, DATA_TYPE_MODEL, DATA_TYPE_CONFIGURATION):
            raise CommandError(
                f"CPU UNIT DATA READ data type {self.data_type!r} must be 0x00, 0x01 or None"
            )

    def encode(self) -> bytes:
        return b"" if self.data_type is None else bytes((self.data_type,))

    @classmethod
    def decode(cls, params: bytes) -> CpuUnitDataRead:
        if not params:
            return cls()
        r = Reader(params, cls.NAME)
        data_type = r.u8()
        r.end()
        with as_decode_error(None):
            return cls(data_type)

    def decode_response(self, data: bytes) -> CpuUnitData:
        what = f"{self.NAME} response"
        if self.data_type == DATA_TYPE_CONFIGURATION:
            return CpuUnitData(None, _decode_part_b(data, what))
        r = Reader(data, what)
        model_data = CpuUnitModelData.read(r)
        if self.data_type == DATA_TYPE_MODEL:
            r.end()
            return CpuUnitData(model_data, None)
        return CpuUnitData(model_data, _decode_part_b(r.rest(), what))


@dataclass(frozen=True, slots=True)
class UnitModel:
    """One unit of a CONNECTION DATA READ response: its unit address and model number."""

    unit_address: int
    model: str

    def __post_init__(self) -> None:
        check_range("unit address", self.unit_address, 0, 0xFF)

    def encode(self) -> bytes:
        return bytes((self.unit_address,)) + pad_ascii(self.model, MODEL_SIZE, "model number")


@dataclass(frozen=True, slots=True)
class ConnectionData:
    """Response of CONNECTION DATA READ: units in unit address order.

    ``last`` is bit 7 of the count byte: the data includes the last unit.
    """

    units: tuple[UnitModel, ...]
    last: bool = False

    def __post_init__(self) -> None:
        units = tuple(self.units)
        object.__setattr__(self, "units", units)
        check_range("number of units", len(units), 0, 0x7F)

    def encode(self) -> bytes:
        head = len(self.units) | (0x80 if self.last else 0)
        return bytes((head,)) + b"".join(u.encode() for u in self.units)

    @classmethod
    def decode(cls, data: bytes) -> ConnectionData:
        r = Reader(data, "CONNECTION DATA READ response")
        head = r.u8()
        count = head & 0x7F
        if r.remaining != count * (1 + MODEL_SIZE):
            raise DecodeError(
                f"CONNECTION DATA READ response: {count} unit(s) need "
                f"{count * (1 + MODEL_SIZE)} bytes, got {r.remaining}"
            )
        units = tuple(UnitModel(r.u8(), ascii_field(r.take(MODEL_SIZE))) for _ in range(count))
        return cls(units, bool(head & 0x80))


def is_connection_unit_address(unit_address: int) -> bool:
    """05 02 unit addresses: CPU 00, CPU Bus Units 10-1F, Special I/O 20-7F, Inner Board E1."""
    return unit_address == 0x00 or 0x10 <= unit_address <= 0x7F or unit_address == 0xE1


#: Default and maximum number of units per 05 02 (19 hex).
MAX_CONNECTION_UNITS = 25


@dataclass(frozen=True)
class ConnectionDataRead(Request[ConnectionData]):
    """05 02 CONNECTION DATA READ: model numbers of units from ``unit_address`` on.

    ``count`` (1-25) of ``None`` omits the byte; the PLC then returns up to 25 units.
    """

    MRC: ClassVar[int] = 0x05
    SRC: ClassVar[int] = 0x02
    NAME: ClassVar[str] = "CONNECTION DATA READ"
    METHOD: ClassVar[str] = "connection_data_read"
    IDEMPOTENT: ClassVar[bool] = True

    unit_address: int = 0x00
    count: int | None = None

    def __post_init__(self) -> None:
        check_range("unit address", self.unit_address, 0, 0xFF)
        if not is_connection_unit_address(self.unit_address):
            raise CommandError(
                f"unit address {self.unit_address:02X} is not 00 (CPU), 10-1F (CPU Bus Unit), "
                "20-7F (Special I/O Unit) or E1 (Inner Board)"
            )
        if self.count is not None:
            check_range("number of items", self.count, 1, MAX_CONNECTION_UNITS)

    def encode(self) -> bytes:
        out = bytes((self.unit_address,))
        return out if self.count is None else out + bytes((self.count,))

    @classmethod
    def decode(cls, params: bytes) -> ConnectionDataRead:
        r = Reader(params, cls.NAME)
        unit = r.u8()
        count = r.u8() if r.remaining else None
        r.end()
        with as_decode_error(None):
            return cls(unit, count)

    def decode_response(self, data: bytes) -> ConnectionData:
        return ConnectionData.decode(data)


OPERATIONS: tuple[type[Request[Any]], ...] = (CpuUnitDataRead, ConnectionDataRead)
