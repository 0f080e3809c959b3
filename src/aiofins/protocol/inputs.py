"""Checks of user input: numbers of seconds, whole numbers, on/off switches.

One wording for the API, URL query options (``?timeout=``) and the command line
(``--timeout``): a bad value raises :class:`CommandError` saying what was expected and what
was given, before anything is sent. Text (from a URL or a command line) is parsed here too
(``text=True``); values passed to the API must already have the right type (``"2"`` is no
number of seconds, ``True`` no count, ``1.5`` no whole number).
"""

from __future__ import annotations

import math
import operator

from .errors import CommandError


def shown(value: object, limit: int = 40) -> str:
    """``repr(value)`` for a message, cut to about ``limit`` characters; an integer too large
    to print (Python refuses over 4,300 digits) is described by its size instead."""
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 128:
        return f"an integer of {value.bit_length()} bits"
    try:
        text = repr(value)
    except ValueError:  # e.g. a list holding such an integer
        return f"a {type(value).__name__} too large to print"
    return text if len(text) <= limit else f"{text[: limit - 5]}...{text[-2:]}"


def seconds(
    name: str,
    value: object,
    *,
    allow_inf: bool = False,
    allow_zero: bool = False,
    text: bool = False,
) -> float:
    """``value`` as a positive, finite number of seconds (``math.inf`` too if ``allow_inf``,
    0 too if ``allow_zero``). ``text``: a string is parsed (a URL's or command line's value);
    otherwise it is refused, as the API takes numbers.

    NaN is refused: every comparison with it is false, so it would disable a deadline.
    """
    number: float | None = None
    if isinstance(value, str):
        if text:
            try:
                number = float(value.strip())
            except ValueError:
                number = None
    elif isinstance(value, (int, float)) and not isinstance(value, bool):
        number = float(value)
    if number is None or not (
        0 < number < math.inf or (allow_inf and number == math.inf) or (allow_zero and number == 0)
    ):
        what = "a number of seconds, 0 or more" if allow_zero else "a positive number of seconds"
        raise CommandError(
            f"{name} must be {what}{' (or inf)' if allow_inf else ''}; got {shown(value)}"
        )
    return number


def whole_number(
    name: str, value: object, low: int, high: int | None = None, *, text: bool = False
) -> int:
    """``value`` as a whole number in ``low..high`` (no upper bound if ``high`` is None).

    Integers (and integer-like objects such as numpy's) are taken as they are; text is parsed
    in base 10 if ``text`` (a URL's or command line's value), else refused; bools and floats
    are refused, even ``2.0``: a count is no truth value and a fraction of a word is no count.
    """
    number: int | None = None
    if isinstance(value, str):
        if text:
            try:
                number = int(value.strip(), 10)
            except ValueError:
                number = None
    elif not isinstance(value, (bool, float)):
        try:
            number = operator.index(value)  # type: ignore[arg-type]
        except TypeError:
            number = None
    if number is None or number < low or (high is not None and number > high):
        span = f"{low}..{high}" if high is not None else f"at least {low}"
        raise CommandError(f"{name} must be a whole number, {span}; got {shown(value)}")
    return number


_TRUE = frozenset({"1", "true", "yes", "on"})
_FALSE = frozenset({"0", "false", "no", "off"})


def switch(name: str, value: object) -> bool:
    """``value`` as on/off: a bool, or text ``1/0``, ``true/false``, ``yes/no``, ``on/off``."""
    if isinstance(value, bool):
        return value
    if isinstance(value, str):
        text = value.strip().lower()
        if text in _TRUE:
            return True
        if text in _FALSE:
            return False
    raise CommandError(f"{name} must be on or off (1/0, true/false, yes/no); got {shown(value)}")


def float_value(name: str, value: object, kind: str = "float64") -> float:
    """``value`` (a number, or text) as a float of ``kind``.

    Text or an integer too large for the type (``1e400``, ``10**400``) is refused as an
    overflow, not turned into an infinity. Infinities and NaN are IEEE values a REAL can
    hold: they are taken when given as such (``math.inf``, ``"inf"``, ``"nan"``), so what was
    read can be written back.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise CommandError(f"{name} {shown(value)} is not a number")
    try:
        number = float(value.strip()) if isinstance(value, str) else float(value)
    except ValueError:
        raise CommandError(f"{name} {shown(value)} is not a number") from None
    except OverflowError:  # an int beyond any float
        raise CommandError(f"{name} {shown(value)} overflows {kind}") from None
    if math.isinf(number) and isinstance(value, str) and "inf" not in value.lower():
        raise CommandError(f"{name} {shown(value)} overflows {kind}")
    return number


__all__ = ["float_value", "seconds", "shown", "switch", "whole_number"]
