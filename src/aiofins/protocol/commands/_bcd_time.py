"""Date and time as the PLC stores them: one BCD byte per field.

Shared by 07 01 CLOCK READ / 07 02 CLOCK WRITE (year, month, day, hour, minute, second, day
of week: manual 5-3-19, 5-3-20), the 21 02 error log records (minute, second, day, hour,
year, month: 5-3-28) and the 21 40 write access log records (clock order: 5-3-30).

The year is its rightmost two digits: 98 and 99 are 1998 and 1999, 00 to 97 are 2000 to
2097 (manual 5-3-19), so these dates cover 1998..2097. Day of week codes: 00 Sunday ... 06
Saturday.
"""

from __future__ import annotations

from collections.abc import Sequence
from datetime import datetime
from typing import Literal

from ..codec import Reader, check_range, from_bcd, to_bcd
from ..errors import CommandError, DecodeError

#: Earliest and latest year the two-digit BCD year can express.
FIRST_YEAR = 1998
LAST_YEAR = 2097

TimeField = Literal["year", "month", "day", "hour", "minute", "second"]

#: Field order of the clock and the access log records.
CLOCK_ORDER: tuple[TimeField, ...] = ("year", "month", "day", "hour", "minute", "second")
#: Field order of the error log records.
ERROR_LOG_ORDER: tuple[TimeField, ...] = ("minute", "second", "day", "hour", "year", "month")


def year_from_two_digits(yy: int) -> int:
    """``98`` → 1998, ``99`` → 1999, ``0``..``97`` → 2000..2097 (manual 5-3-19)."""
    return 1900 + yy if yy >= 98 else 2000 + yy


def day_of_week_of(moment: datetime) -> int:
    """The FINS day-of-week code of a date: 0 Sunday ... 6 Saturday."""
    return (moment.weekday() + 1) % 7


def check_day_of_week(day_of_week: int) -> None:
    """:class:`CommandError` unless ``day_of_week`` is 0..6."""
    check_range("day of week", day_of_week, 0, 6)


def normalise_time(moment: datetime, what: str) -> datetime:
    """Check a datetime fits the PLC clock; drop microseconds and time zone."""
    if not isinstance(moment, datetime):
        raise CommandError(f"{what} must be a datetime, got {type(moment).__name__}")
    check_range("year", moment.year, FIRST_YEAR, LAST_YEAR)
    return moment.replace(microsecond=0, tzinfo=None)


def encode_bcd_time(
    moment: datetime, order: Sequence[TimeField] = CLOCK_ORDER, day_of_week: int | None = None
) -> bytes:
    """The fields of ``moment`` named by ``order`` as BCD bytes, then ``day_of_week`` if given."""
    values = {
        "year": moment.year % 100,
        "month": moment.month,
        "day": moment.day,
        "hour": moment.hour,
        "minute": moment.minute,
        "second": moment.second,
    }
    fields = [values[name] for name in order]
    if day_of_week is not None:
        fields.append(day_of_week)
    return bytes(to_bcd(v, 2) for v in fields)


def read_bcd_values(reader: Reader, count: int) -> list[int]:
    """``count`` BCD bytes as numbers; a non-decimal nibble raises :class:`DecodeError`."""
    return [from_bcd(reader.u8(), 2) for _ in range(count)]


def time_from_bcd(values: Sequence[int], order: Sequence[TimeField] = CLOCK_ORDER) -> datetime:
    """A naive ``datetime`` from decoded BCD numbers laid out in ``order``.

    Numbers past the end of ``order`` (a day of week) are ignored; a missing second (CLOCK
    WRITE without it) is 0. Impossible dates raise :class:`DecodeError` (end code 110C).
    """
    fields = dict(zip(order, values, strict=False))
    year = year_from_two_digits(fields["year"])
    month, day, hour, minute = fields["month"], fields["day"], fields["hour"], fields["minute"]
    second = fields.get("second", 0)
    try:
        return datetime(year, month, day, hour, minute, second)
    except ValueError as exc:
        raise DecodeError(
            f"invalid date/time {year:04d}-{month:02d}-{day:02d} "
            f"{hour:02d}:{minute:02d}:{second:02d}: {exc}",
            end_code=0x110C,
        ) from None


def check_decoded_day_of_week(value: int, what: str = "", end_code: int | None = None) -> int:
    """``value`` if it is a day of week code (0..6); :class:`DecodeError` if not."""
    if value > 6:
        prefix = f"{what}: " if what else ""
        raise DecodeError(f"{prefix}day of week {value} out of range 0..6", end_code=end_code)
    return value
