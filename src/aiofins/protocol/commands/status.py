"""Status reading (manual 5-3-17, 5-3-18): 06 01 CPU UNIT STATUS READ, 06 20 CYCLE TIME READ."""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Any, ClassVar, cast

from ..codec import Reader, ascii_field, check_range, pad_ascii
from ..decoding import as_decode_error
from ..errors import CommandError, DecodeError
from ._base import NoParameters, Request, expect_no_data


class CpuMode(enum.IntEnum):
    """Operating mode byte of 06 01 (``DEBUG`` exists on CV-series CPUs only)."""

    #: The program does not run; the whole PLC may be written (programs, parameters).
    PROGRAM = 0x00
    #: CV-series only: the program runs for debugging.
    DEBUG = 0x01
    #: The program runs; memory, forced bits and present values may be changed online.
    MONITOR = 0x02
    #: The program runs; online changes are refused.
    RUN = 0x04


class FatalError(enum.IntFlag):
    """Fatal error data word of 06 01 (bit 15 = MSB of the first byte)."""

    FALS_ERROR = 1 << 6
    CYCLE_TIME_OVER = 1 << 8
    PROGRAM_ERROR = 1 << 9
    IO_SETTING_ERROR = 1 << 10
    TOO_MANY_IO_POINTS = 1 << 11
    INNER_BOARD_ERROR = 1 << 12
    DUPLICATION_ERROR = 1 << 13
    IO_BUS_ERROR = 1 << 14
    MEMORY_ERROR = 1 << 15


class NonFatalError(enum.IntFlag):
    """Non-fatal error data word of 06 01."""

    SPECIAL_IO_UNIT_SETTING_ERROR = 1 << 2
    CPU_BUS_UNIT_SETTING_ERROR = 1 << 3
    BATTERY_ERROR = 1 << 4
    SYSMAC_BUS_ERROR = 1 << 5
    SPECIAL_IO_UNIT_ERROR = 1 << 6
    CPU_BUS_UNIT_ERROR = 1 << 7
    INNER_BOARD_ERROR = 1 << 8
    IO_VERIFICATION_ERROR = 1 << 9
    PLC_SETUP_ERROR = 1 << 10
    BASIC_IO_UNIT_ERROR = 1 << 12
    INTERRUPT_TASK_ERROR = 1 << 13
    DUPLEX_ERROR = 1 << 14
    FAL_ERROR = 1 << 15


#: Status byte bits of 06 01 (bits 3-6 undefined: masked on decode).
STATUS_RUNNING = 0x01
STATUS_FLASH_WRITING = 0x02
STATUS_BATTERY_PRESENT = 0x04
STATUS_STANDBY = 0x80
_STATUS_DEFINED = STATUS_RUNNING | STATUS_FLASH_WRITING | STATUS_BATTERY_PRESENT | STATUS_STANDBY


@dataclass(frozen=True, slots=True)
class CpuUnitStatus:
    """Response of CPU UNIT STATUS READ (26 bytes)."""

    #: Status byte with the undefined bits 3-6 masked off.
    status: int
    mode: CpuMode
    fatal_errors: FatalError
    non_fatal_errors: NonFatalError
    #: Message yes/no word: bit n is ON when MSG message n (0-7) exists.
    message_flags: int
    #: Code of the most serious current error, 0000 if none.
    error_code: int
    #: FAL/FALS message, 16 ASCII characters (spaces when none).
    error_message: str

    def __post_init__(self) -> None:
        try:
            object.__setattr__(self, "mode", CpuMode(self.mode))
        except ValueError:
            raise CommandError(f"CPU mode {self.mode!r} must be 00, 01, 02 or 04") from None
        object.__setattr__(self, "fatal_errors", FatalError(int(self.fatal_errors)))
        object.__setattr__(self, "non_fatal_errors", NonFatalError(int(self.non_fatal_errors)))
        check_range("status", self.status, 0, 0xFF)
        check_range("message flags", self.message_flags, 0, 0xFFFF)
        check_range("error code", self.error_code, 0, 0xFFFF)
        check_range("fatal error data", int(self.fatal_errors), 0, 0xFFFF)
        check_range("non-fatal error data", int(self.non_fatal_errors), 0, 0xFFFF)

    @property
    def running(self) -> bool:
        """The user program is being executed."""
        return bool(self.status & STATUS_RUNNING)

    @property
    def flash_writing(self) -> bool:
        """Built-in flash memory is being written."""
        return bool(self.status & STATUS_FLASH_WRITING)

    @property
    def battery_present(self) -> bool:
        return bool(self.status & STATUS_BATTERY_PRESENT)

    @property
    def standby(self) -> bool:
        """The CPU is on standby (waiting for a device such as a remote I/O slave)."""
        return bool(self.status & STATUS_STANDBY)

    @property
    def has_fatal_error(self) -> bool:
        return bool(self.fatal_errors)

    @property
    def has_non_fatal_error(self) -> bool:
        return bool(self.non_fatal_errors)

    @property
    def messages(self) -> tuple[int, ...]:
        """Numbers (0-7) of the messages that exist."""
        return tuple(n for n in range(8) if self.message_flags >> n & 1)

    def encode(self) -> bytes:
        return (
            bytes((self.status, int(self.mode)))
            + int(self.fatal_errors).to_bytes(2, "big")
            + int(self.non_fatal_errors).to_bytes(2, "big")
            + self.message_flags.to_bytes(2, "big")
            + self.error_code.to_bytes(2, "big")
            + pad_ascii(self.error_message, 16, "error message")
        )

    @classmethod
    def decode(cls, data: bytes) -> CpuUnitStatus:
        r = Reader(data, "CPU UNIT STATUS READ response")
        status = r.u8() & _STATUS_DEFINED
        raw_mode = r.u8()
        try:
            mode = CpuMode(raw_mode)
        except ValueError:
            raise DecodeError(f"unknown CPU mode {raw_mode:02X}") from None
        fatal = FatalError(r.u16())
        non_fatal = NonFatalError(r.u16())
        flags = r.u16()
        code = r.u16()
        message = ascii_field(r.take(16))
        r.end()
        return cls(status, mode, fatal, non_fatal, flags, code, message)


@dataclass(frozen=True)
class CpuUnitStatusRead(NoParameters[CpuUnitStatus]):
    """06 01 CPU UNIT STATUS READ: run/stop, mode, error flags, messages, error code."""

    MRC: ClassVar[int] = 0x06
    SRC: ClassVar[int] = 0x01
    NAME: ClassVar[str] = "CPU UNIT STATUS READ"
    METHOD: ClassVar[str] = "cpu_unit_status_read"
    IDEMPOTENT: ClassVar[bool] = True

    def decode_response(self, data: bytes) -> CpuUnitStatus:
        return CpuUnitStatus.decode(data)


class CycleTimeParameter(enum.IntEnum):
    """Parameter code of 06 20."""

    INITIALIZE = 0x00
    READ = 0x01


@dataclass(frozen=True, slots=True)
class CycleTime:
    """Response of CYCLE TIME READ (read): average, maximum, minimum in 0.1 ms units."""

    average: int
    maximum: int
    minimum: int

    def __post_init__(self) -> None:
        for name in ("average", "maximum", "minimum"):
            check_range(f"{name} cycle time", getattr(self, name), 0, 0xFFFFFFFF)

    @property
    def average_ms(self) -> float:
        return self.average / 10

    @property
    def maximum_ms(self) -> float:
        return self.maximum / 10

    @property
    def minimum_ms(self) -> float:
        return self.minimum / 10

    def encode(self) -> bytes:
        return b"".join(v.to_bytes(4, "big") for v in (self.average, self.maximum, self.minimum))

    @classmethod
    def decode(cls, data: bytes) -> CycleTime:
        # CS/CJ: binary (manual 5-3-18: 0000028A = 65.0 ms); CV-series used BCD.
        r = Reader(data, "CYCLE TIME READ response")
        out = cls(r.u32(), r.u32(), r.u32())
        r.end()
        return out


@dataclass(frozen=True)
class CycleTimeRead(Request["CycleTime | None"]):
    """06 20 CYCLE TIME READ: initialise (no data back) or read the cycle times.

    Initialising twice has the same effect as once, so the operation counts as idempotent.
    """

    MRC: ClassVar[int] = 0x06
    SRC: ClassVar[int] = 0x20
    NAME: ClassVar[str] = "CYCLE TIME READ"
    METHOD: ClassVar[str] = "cycle_time_read"
    IDEMPOTENT: ClassVar[bool] = True

    parameter: CycleTimeParameter = CycleTimeParameter.READ

    def __post_init__(self) -> None:
        try:
            object.__setattr__(self, "parameter", CycleTimeParameter(self.parameter))
        except ValueError:
            raise CommandError(
                f"cycle time parameter code {self.parameter!r} must be 00 (initialize) or 01 (read)"
            ) from None

    def encode(self) -> bytes:
        return bytes((int(self.parameter),))

    @classmethod
    def decode(cls, params: bytes) -> CycleTimeRead:
        r = Reader(params, cls.NAME)
        code = r.u8()
        r.end()
        with as_decode_error(None):
            # __post_init__ checks the raw code and turns it into a CycleTimeParameter.
            return cls(cast(CycleTimeParameter, code))

    def decode_response(self, data: bytes) -> CycleTime | None:
        if self.parameter == CycleTimeParameter.INITIALIZE:
            expect_no_data(self, data)
            return None
        return CycleTime.decode(data)


OPERATIONS: tuple[type[Request[Any]], ...] = (CpuUnitStatusRead, CycleTimeRead)
