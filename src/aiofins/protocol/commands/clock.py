"""Time data access (manual 5-3-19, 5-3-20): 07 01 CLOCK READ, 07 02 CLOCK WRITE.

The BCD date/time layout (shared with the error and access logs) is in :mod:`._bcd_time`;
the clock covers 1998..2097.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime
from typing import Any, ClassVar

from ..codec import Reader, from_bcd
from ..errors import CommandError, DecodeError
from ._base import NoParameters, Request, expect_no_data
from ._bcd_time import (
    CLOCK_ORDER,
    check_day_of_week,
    check_decoded_day_of_week,
    day_of_week_of,
    encode_bcd_time,
    normalise_time,
    read_bcd_values,
    time_from_bcd,
)

#: Day of week codes (manual 5-3-19): 00 Sunday ... 06 Saturday.
DAY_NAMES = ("Sunday", "Monday", "Tuesday", "Wednesday", "Thursday", "Friday", "Saturday")


@dataclass(frozen=True, slots=True)
class ClockData:
    """Response of CLOCK READ: the PLC's wall-clock time and its day-of-week code.

    ``day_of_week`` is the PLC's own value (0 Sunday ... 6 Saturday); the PLC does not check
    it against the date, so it may disagree with ``time.weekday()``.
    """

    time: datetime
    day_of_week: int

    def __post_init__(self) -> None:
        object.__setattr__(self, "time", normalise_time(self.time, "clock time"))
        check_day_of_week(self.day_of_week)

    @property
    def day_name(self) -> str:
        return DAY_NAMES[self.day_of_week]

    def encode(self) -> bytes:
        return encode_bcd_time(self.time, CLOCK_ORDER, self.day_of_week)

    @classmethod
    def decode(cls, data: bytes) -> ClockData:
        r = Reader(data, "CLOCK READ response")
        values = read_bcd_values(r, 7)
        r.end()
        dow = check_decoded_day_of_week(values[6])
        return cls(time_from_bcd(values, CLOCK_ORDER), dow)


@dataclass(frozen=True)
class ClockRead(NoParameters[ClockData]):
    """07 01 CLOCK READ: year, month, day, hour, minute, second, day of week."""

    MRC: ClassVar[int] = 0x07
    SRC: ClassVar[int] = 0x01
    NAME: ClassVar[str] = "CLOCK READ"
    METHOD: ClassVar[str] = "clock_read"
    IDEMPOTENT: ClassVar[bool] = True

    def decode_response(self, data: bytes) -> ClockData:
        return ClockData.decode(data)


@dataclass(frozen=True)
class ClockWrite(Request[None]):
    """07 02 CLOCK WRITE.

    The manual's omission rules (5-3-20): the second and the day of week may be left out.
    Without the second (``with_second=False``) the PLC sets 00 seconds, so ``time.second``
    must be 0, and the day of week cannot be sent either. ``day_of_week=None`` keeps the
    PLC's previous day of week. :meth:`from_datetime` fills the day of week from the date.
    """

    MRC: ClassVar[int] = 0x07
    SRC: ClassVar[int] = 0x02
    NAME: ClassVar[str] = "CLOCK WRITE"
    METHOD: ClassVar[str] = "clock_write"

    time: datetime
    day_of_week: int | None = None
    with_second: bool = True

    def __post_init__(self) -> None:
        object.__setattr__(self, "time", normalise_time(self.time, "clock time"))
        if self.day_of_week is not None:
            check_day_of_week(self.day_of_week)
        if not self.with_second:
            if self.time.second != 0:
                raise CommandError(
                    "CLOCK WRITE without the second sets 00 seconds: time.second must be 0"
                )
            if self.day_of_week is not None:
                raise CommandError("CLOCK WRITE: the day of week cannot be sent without the second")

    @classmethod
    def from_datetime(cls, moment: datetime) -> ClockWrite:
        """Write all seven fields, the day of week computed from the date."""
        return cls(moment, day_of_week_of(moment))

    def encode(self) -> bytes:
        if self.with_second:
            return encode_bcd_time(self.time, CLOCK_ORDER, self.day_of_week)
        return encode_bcd_time(self.time, CLOCK_ORDER[:5])  # year .. minute

    @classmethod
    def decode(cls, params: bytes) -> ClockWrite:
        if len(params) < 5:
            raise DecodeError(f"{cls.NAME}: needs 5 to 7 bytes, got {len(params)}", end_code=0x1002)
        if len(params) > 7:
            raise DecodeError(f"{cls.NAME}: needs 5 to 7 bytes, got {len(params)}", end_code=0x1001)
        try:
            values = [from_bcd(b, 2) for b in params]
        except DecodeError as exc:
            raise DecodeError(f"{cls.NAME}: {exc}", end_code=0x110C) from None
        dow = None
        if len(values) > 6:
            dow = check_decoded_day_of_week(values[6], cls.NAME, end_code=0x110C)
        moment = time_from_bcd(values, CLOCK_ORDER)  # without the second: 00 seconds
        return cls(moment, dow, with_second=len(values) > 5)

    def decode_response(self, data: bytes) -> None:
        expect_no_data(self, data)


OPERATIONS: tuple[type[Request[Any]], ...] = (ClockRead, ClockWrite)
