"""Time data access (manual 5-3-19, 5-3-20): 07 01 CLOCK READ, 07 02 CLOCK WRITE.

Also the BCD date/time helpers the error log (21 02) and write access log (21 40) share.
The PLC stores the rightmost two digits of the year: 98 and 99 are 1998 and 1999, 00 to 97
are 2000 to 2097 (manual 5-3-19), so the clock covers 1998..2097.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime
from typing import Any, ClassVar, TypeVar

from ..codec import Reader, check_range, from_bcd, to_bcd
from ..errors import AddressError, CommandError, DecodeError
from ._base import Request, expect_no_data

T = TypeVar("T")

#: Earliest and latest year the two-digit BCD year can express.
FIRST_YEAR = 1998
LAST_YEAR = 2097

#: Day of week codes (manual 5-3-19): 00 Sunday ... 06 Saturday.
DAY_NAMES = ("Sunday", "Monday", "Tuesday", "Wednesday", "Thursday", "Friday", "Saturday")


def construct(end_code: int, build: Callable[..., T], *args: Any, **kwargs: Any) -> T:
    """Build a value from decoded fields; a validation failure becomes :class:`DecodeError`.

    Used by the server-side ``decode``: ``end_code`` is what a PLC answers for such a
    parameter (e.g. ``0x1103`` address range error, ``0x110C`` parameter error).
    """
    try:
        return build(*args, **kwargs)
    except (CommandError, AddressError) as exc:
        raise DecodeError(str(exc), end_code=end_code) from exc


def year_from_two_digits(yy: int) -> int:
    """``98`` → 1998, ``99`` → 1999, ``0``..``97`` → 2000..2097 (manual 5-3-19)."""
    return 1900 + yy if yy >= 98 else 2000 + yy


def check_year(year: int) -> None:
    check_range("year", year, FIRST_YEAR, LAST_YEAR)


def day_of_week_of(moment: datetime) -> int:
    """The FINS day-of-week code of a date: 0 Sunday ... 6 Saturday."""
    return (moment.weekday() + 1) % 7


def bcd_byte(value: int) -> int:
    return to_bcd(value, 2)


def read_bcd(reader: Reader) -> int:
    return from_bcd(reader.u8(), 2)


def make_datetime(year: int, month: int, day: int, hour: int, minute: int, second: int) -> datetime:
    """A naive ``datetime``; impossible dates raise :class:`DecodeError`."""
    try:
        return datetime(year, month, day, hour, minute, second)
    except ValueError as exc:
        raise DecodeError(
            f"invalid date/time {year:04d}-{month:02d}-{day:02d} "
            f"{hour:02d}:{minute:02d}:{second:02d}: {exc}",
            end_code=0x110C,
        ) from None


def normalise_time(moment: datetime, what: str) -> datetime:
    """Check a datetime fits the PLC clock; drop microseconds and time zone."""
    if not isinstance(moment, datetime):
        raise CommandError(f"{what} must be a datetime, got {type(moment).__name__}")
    check_year(moment.year)
    return moment.replace(microsecond=0, tzinfo=None)


def check_day_of_week(day_of_week: int) -> None:
    check_range("day of week", day_of_week, 0, 6)


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
        t = self.time
        return bytes(
            bcd_byte(v)
            for v in (t.year % 100, t.month, t.day, t.hour, t.minute, t.second, self.day_of_week)
        )

    @classmethod
    def decode(cls, data: bytes) -> ClockData:
        r = Reader(data, "CLOCK READ response")
        yy, month, day, hour, minute, second, dow = (read_bcd(r) for _ in range(7))
        r.end()
        if dow > 6:
            raise DecodeError(f"day of week {dow} out of range 0..6")
        return cls(make_datetime(year_from_two_digits(yy), month, day, hour, minute, second), dow)


@dataclass(frozen=True)
class ClockRead(Request[ClockData]):
    """07 01 CLOCK READ: year, month, day, hour, minute, second, day of week."""

    MRC: ClassVar[int] = 0x07
    SRC: ClassVar[int] = 0x01
    NAME: ClassVar[str] = "CLOCK READ"
    METHOD: ClassVar[str] = "clock_read"
    IDEMPOTENT: ClassVar[bool] = True

    def encode(self) -> bytes:
        return b""

    @classmethod
    def decode(cls, params: bytes) -> ClockRead:
        Reader(params, cls.NAME).end()
        return cls()

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
        t = self.time
        fields = [t.year % 100, t.month, t.day, t.hour, t.minute]
        if self.with_second:
            fields.append(t.second)
            if self.day_of_week is not None:
                fields.append(self.day_of_week)
        return bytes(bcd_byte(v) for v in fields)

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
        yy, month, day, hour, minute = values[:5]
        second = values[5] if len(values) > 5 else 0
        dow = values[6] if len(values) > 6 else None
        if dow is not None and dow > 6:
            raise DecodeError(f"{cls.NAME}: day of week {dow} out of range 0..6", end_code=0x110C)
        moment = make_datetime(year_from_two_digits(yy), month, day, hour, minute, second)
        return cls(moment, dow, with_second=len(values) > 5)

    def decode_response(self, data: bytes) -> None:
        expect_no_data(self, data)


OPERATIONS: tuple[type[Request[Any]], ...] = (ClockRead, ClockWrite)
