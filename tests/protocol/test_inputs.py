"""The user-input checks: one wording for the API, URLs and the command line."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiofins.protocol.errors import CommandError
from aiofins.protocol.inputs import float_value, seconds, shown, switch, whole_number
from aiofins.protocol.values import parse_value_type


@pytest.mark.parametrize("value", [math.nan, -1, 0, 0.0, math.inf, "nan", "inf", "", "2s", True])
def test_seconds_refuses_what_no_deadline_can_be(value: object) -> None:
    with pytest.raises(CommandError, match=r"^timeout must be a positive number of seconds; got"):
        seconds("timeout", value, text=True)


def test_seconds_takes_numbers_and_text() -> None:
    assert seconds("timeout", 2) == 2.0
    assert seconds("timeout", " 0.25 ", text=True) == 0.25
    assert seconds("backoff_min", 0, allow_zero=True) == 0.0
    with pytest.raises(
        CommandError, match=r"^timeout must be a positive number of seconds; got '2'$"
    ):
        seconds("timeout", "2")  # the API takes numbers; text is for URLs and command lines
    assert seconds("idle_timeout", math.inf, allow_inf=True) == math.inf
    with pytest.raises(CommandError, match=r"\(or inf\); got nan"):
        seconds("idle_timeout", math.nan, allow_inf=True)


@pytest.mark.parametrize("value", [True, False, 1.5, 2.0, "1.5", None, b"1", -1])
def test_whole_numbers_are_not_bools_floats_or_bytes(value: object) -> None:
    with pytest.raises(CommandError, match=r"^count must be a whole number, at least 0; got"):
        whole_number("count", value, 0)


def test_whole_number_ranges_and_text() -> None:
    assert whole_number("node", "12", 0, 254, text=True) == 12
    with pytest.raises(CommandError, match=r"^node must be a whole number, 0\.\.254; got 255$"):
        whole_number("node", 255, 0, 254)


def test_switch() -> None:
    assert switch("read_only", "yes") is True and switch("read_only", "0") is False
    with pytest.raises(CommandError, match="read_only must be on or off"):
        switch("read_only", "maybe")


def test_huge_integers_are_described_not_printed() -> None:
    huge = int("f" * 5000, 16)  # repr() of it would raise ValueError (4,300-digit limit)
    assert shown(huge) == "an integer of 20000 bits"
    assert shown([huge]) == "a list too large to print"
    assert shown("x" * 100).endswith("...x'") and len(shown("x" * 100)) == 40


def test_float_text_that_overflows_is_refused() -> None:
    with pytest.raises(CommandError, match=r"^value '1e400' overflows float64$"):
        float_value("value", "1e400", "float64")
    with pytest.raises(CommandError, match=r"overflows float64"):
        float_value("value", 10**400, "float64")
    assert float_value("value", "-inf") == -math.inf  # asked for by name: an IEEE value
    assert math.isnan(float_value("value", "nan"))


@pytest.mark.parametrize("kind", ["float32", "real"])
def test_float32_overflow_is_refused(kind: str) -> None:
    with pytest.raises(CommandError, match=r"^value 1e\+39 overflows float32$"):
        parse_value_type(kind).encode(1e39)


@given(st.integers(min_value=2**64))
def test_integers_too_large_for_any_type_say_so(value: int) -> None:
    for kind in ("uint64", "int64", "bcd32"):
        with pytest.raises(CommandError, match="does not fit"):
            parse_value_type(kind).encode(value)
