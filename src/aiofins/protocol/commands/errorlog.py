"""Error log and FINS write access log (manual 5-3-27..5-3-31).

21 01 ERROR CLEAR, 21 02 ERROR LOG READ, 21 03 ERROR LOG CLEAR,
21 40 FINS WRITE ACCESS LOG READ, 21 41 FINS WRITE ACCESS LOG CLEAR.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime
from typing import Any, ClassVar, Generic, TypeVar

from ..codec import Reader, check_range
from ..errors import DecodeError
from ._base import Encodable, ParameterlessRequest, Request, _decode_fields, expect_no_data
from ._bcd_time import (
    CLOCK_ORDER,
    ERROR_LOG_ORDER,
    check_day_of_week,
    check_decoded_day_of_week,
    encode_bcd_time,
    normalise_time,
    read_bcd_values,
    time_from_bcd,
)

#: ERROR CLEAR codes valid in any mode / PROGRAM mode only (manual 5-3-27).
CLEAR_CURRENT_ERROR = 0xFFFE
CLEAR_ALL_ERRORS = 0xFFFF

ERROR_RECORD_SIZE = 10
ACCESS_RECORD_SIZE = 12
#: Both logs hold at most 20 records on CS/CJ; the wire field is 16 bits.
MAX_RECORD_COUNT = 0xFFFF


_RecordT = TypeVar("_RecordT", bound=Encodable)
_LogT = TypeVar("_LogT", bound="_RecordLog[Any]")
_ReadT = TypeVar("_ReadT", bound="_RecordLogRead[Any]")


@dataclass(frozen=True, slots=True)
class _RecordLog(Generic[_RecordT]):
    """Data of a log read: maximum and stored record counts, then fixed-size records."""

    #: Log name in messages, e.g. ``"error log"``.
    _LOG: ClassVar[str]
    #: Name of the read command, e.g. ``"ERROR LOG READ"``.
    _READ: ClassVar[str]
    #: The record type; its ``read(Reader)`` parses one record.
    _RECORD: ClassVar[type[Any]]
    _RECORD_SIZE: ClassVar[int]
    #: Whether response data of no bytes at all means "no records" (``(0, 0, ())``).
    _EMPTY_MEANS_NONE: ClassVar[bool] = False

    max_records: int
    stored_records: int
    records: tuple[_RecordT, ...] = ()

    def __post_init__(self) -> None:
        log = self._LOG
        check_range(f"{log} maximum number of stored records", self.max_records, 0, 0xFFFF)
        check_range(f"{log} number of stored records", self.stored_records, 0, 0xFFFF)
        object.__setattr__(self, "records", tuple(self.records))
        check_range(f"{log} records returned", len(self.records), 0, MAX_RECORD_COUNT)

    def encode(self) -> bytes:
        head = b"".join(
            v.to_bytes(2, "big") for v in (self.max_records, self.stored_records, len(self.records))
        )
        return head + b"".join(rec.encode() for rec in self.records)

    @classmethod
    def decode(cls: type[_LogT], data: bytes) -> _LogT:
        if not data and cls._EMPTY_MEANS_NONE:
            return cls(0, 0, ())
        r = Reader(data, f"{cls._READ} response")
        max_records, stored, count = r.u16(), r.u16(), r.u16()
        size = count * cls._RECORD_SIZE
        if r.remaining != size:
            raise DecodeError(
                f"{cls._READ} response: {count} record(s) need {size} bytes, got {r.remaining}"
            )
        records = tuple(cls._RECORD.read(r) for _ in range(count))
        return cls(max_records, stored, records)


@dataclass(frozen=True)
class _RecordLogRead(Request[_LogT]):
    """A log read: ``count`` records from ``beginning_record`` (0 = oldest)."""

    IDEMPOTENT: ClassVar[bool] = True

    beginning_record: int = 0
    count: int = 20

    def __post_init__(self) -> None:
        check_range("beginning record number", self.beginning_record, 0, 0xFFFF)
        check_range("number of records", self.count, 1, MAX_RECORD_COUNT)

    def encode(self) -> bytes:
        return self.beginning_record.to_bytes(2, "big") + self.count.to_bytes(2, "big")

    @classmethod
    def decode(cls: type[_ReadT], params: bytes) -> _ReadT:
        r = Reader(params, cls.NAME)
        begin, count = r.u16(), r.u16()
        r.end()
        if count == 0:
            raise DecodeError(f"{cls.NAME}: number of records is 0", end_code=0x110C)
        return cls(begin, count)


@dataclass(frozen=True)
class ErrorClear(Request[None]):
    """21 01 ERROR CLEAR: clear the error ``error_code`` (``FFFE`` current, ``FFFF`` all)."""

    MRC: ClassVar[int] = 0x21
    SRC: ClassVar[int] = 0x01
    NAME: ClassVar[str] = "ERROR CLEAR"
    METHOD: ClassVar[str] = "error_clear"

    error_code: int = CLEAR_CURRENT_ERROR

    def __post_init__(self) -> None:
        check_range("error code", self.error_code, 0, 0xFFFF)

    def encode(self) -> bytes:
        return self.error_code.to_bytes(2, "big")

    @classmethod
    def decode(cls, params: bytes) -> ErrorClear:
        return _decode_fields(cls, params, Reader.u16)

    def decode_response(self, data: bytes) -> None:
        expect_no_data(self, data)


@dataclass(frozen=True, slots=True)
class ErrorLogRecord:
    """One 10-byte error log record: two error codes and when the error occurred."""

    error_code: int
    error_code_2: int
    time: datetime

    def __post_init__(self) -> None:
        check_range("error code 1", self.error_code, 0, 0xFFFF)
        check_range("error code 2", self.error_code_2, 0, 0xFFFF)
        object.__setattr__(self, "time", normalise_time(self.time, "error time"))

    def encode(self) -> bytes:
        # Minute, second, day, hour, year, month: BCD (manual 5-3-28).
        stamp = encode_bcd_time(self.time, ERROR_LOG_ORDER)
        return self.error_code.to_bytes(2, "big") + self.error_code_2.to_bytes(2, "big") + stamp

    @classmethod
    def read(cls, r: Reader) -> ErrorLogRecord:
        code1 = r.u16()
        code2 = r.u16()
        moment = time_from_bcd(read_bcd_values(r, 6), ERROR_LOG_ORDER)
        return cls(code1, code2, moment)


@dataclass(frozen=True, slots=True)
class ErrorLog(_RecordLog[ErrorLogRecord]):
    """Response of ERROR LOG READ.

    When the beginning record is past the stored records, the PLC answers with no data at
    all (manual 5-3-28, which names no end code). With a normal end code that decodes as
    ``ErrorLog(0, 0, ())``; with 1103, which the virtual PLC answers (as 5-3-30 says for
    FINS WRITE ACCESS LOG READ), the client raises :class:`ParameterError` with that end code.
    """

    _LOG = "error log"
    _READ = "ERROR LOG READ"
    _RECORD = ErrorLogRecord
    _RECORD_SIZE = ERROR_RECORD_SIZE
    _EMPTY_MEANS_NONE = True


@dataclass(frozen=True)
class ErrorLogRead(_RecordLogRead[ErrorLog]):
    """21 02 ERROR LOG READ: ``count`` records from ``beginning_record`` (0 = oldest)."""

    MRC: ClassVar[int] = 0x21
    SRC: ClassVar[int] = 0x02
    NAME: ClassVar[str] = "ERROR LOG READ"
    METHOD: ClassVar[str] = "error_log_read"

    def decode_response(self, data: bytes) -> ErrorLog:
        return ErrorLog.decode(data)


@dataclass(frozen=True)
class ErrorLogClear(ParameterlessRequest):
    """21 03 ERROR LOG CLEAR: reset the error log pointer to 0."""

    MRC: ClassVar[int] = 0x21
    SRC: ClassVar[int] = 0x03
    NAME: ClassVar[str] = "ERROR LOG CLEAR"
    METHOD: ClassVar[str] = "error_log_clear"


# manual wins: 5-3-30 gives a 12-byte access record holding network, node and unit address,
# the command code, and year, month, day, hour, minute, second, day of week in BCD
# (3 + 2 + 7 = 12). fins-wire-format.md (from libfins only, no manual page) has a reserved
# byte after the unit address and six time bytes in error-log order (minute, second, day,
# hour, year, month). We follow the manual's field list.
@dataclass(frozen=True, slots=True)
class FinsWriteAccessRecord:
    """One 12-byte FINS write access log record: who wrote, with which command, when."""

    network: int
    node: int
    unit: int
    command_code: int
    time: datetime
    day_of_week: int

    def __post_init__(self) -> None:
        check_range("network address", self.network, 0, 0xFF)
        check_range("node address", self.node, 0, 0xFF)
        check_range("unit address", self.unit, 0, 0xFF)
        check_range("command code", self.command_code, 0, 0xFFFF)
        object.__setattr__(self, "time", normalise_time(self.time, "access time"))
        check_day_of_week(self.day_of_week)

    def encode(self) -> bytes:
        stamp = encode_bcd_time(self.time, CLOCK_ORDER, self.day_of_week)
        source = bytes((self.network, self.node, self.unit))
        return source + self.command_code.to_bytes(2, "big") + stamp

    @classmethod
    def read(cls, r: Reader) -> FinsWriteAccessRecord:
        network, node, unit = r.u8(), r.u8(), r.u8()
        code = r.u16()
        values = read_bcd_values(r, 7)
        dow = check_decoded_day_of_week(values[6], "access log record")
        moment = time_from_bcd(values, CLOCK_ORDER)
        return cls(network, node, unit, code, moment, dow)


@dataclass(frozen=True, slots=True)
class FinsWriteAccessLog(_RecordLog[FinsWriteAccessRecord]):
    """Response of FINS WRITE ACCESS LOG READ."""

    _LOG = "access log"
    _READ = "FINS WRITE ACCESS LOG READ"
    _RECORD = FinsWriteAccessRecord
    _RECORD_SIZE = ACCESS_RECORD_SIZE


@dataclass(frozen=True)
class FinsWriteAccessLogRead(_RecordLogRead[FinsWriteAccessLog]):
    """21 40 FINS WRITE ACCESS LOG READ: ``count`` records from ``beginning_record``."""

    MRC: ClassVar[int] = 0x21
    SRC: ClassVar[int] = 0x40
    NAME: ClassVar[str] = "FINS WRITE ACCESS LOG READ"
    METHOD: ClassVar[str] = "fins_write_access_log_read"

    def decode_response(self, data: bytes) -> FinsWriteAccessLog:
        return FinsWriteAccessLog.decode(data)


@dataclass(frozen=True)
class FinsWriteAccessLogClear(ParameterlessRequest):
    """21 41 FINS WRITE ACCESS LOG CLEAR."""

    MRC: ClassVar[int] = 0x21
    SRC: ClassVar[int] = 0x41
    NAME: ClassVar[str] = "FINS WRITE ACCESS LOG CLEAR"
    METHOD: ClassVar[str] = "fins_write_access_log_clear"


OPERATIONS: tuple[type[Request[Any]], ...] = (
    ErrorClear,
    ErrorLogRead,
    ErrorLogClear,
    FinsWriteAccessLogRead,
    FinsWriteAccessLogClear,
)
