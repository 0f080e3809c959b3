"""Typed values (#15): ``read_value``'s static type follows the type name (checked by mypy
--strict, which CI runs over tests/), and string byte orders are honoured both ways."""

from __future__ import annotations

import pytest

import aiofins
from aiofins.protocol.values import Value, parse_value_type
from aiofins.simulator.plc import VirtualPLC
from aiofins.simulator.runner import Simulator

pytestmark = pytest.mark.anyio


async def test_read_value_is_typed_by_its_type_name(url: str) -> None:
    async with aiofins.connect(url) as plc:
        await plc.write_value("D100", 21.5, "float32")
        await plc.write_value("D110", -7, "int32")
        await plc.write("CIO 0.01", [1])
        await plc.write_value("D120", 1234, "bcd16")
        # Annotated assignments: mypy --strict fails here if the overloads give the union.
        x: float = await plc.read_value("D100", "float32")
        r: float = await plc.read_value("D100", "real")
        n: int = await plc.read_value("D110", "int32")
        w: int = await plc.read_value("D110")
        d: int = await plc.read_value("D120", "bcd16")
        b: bool = await plc.read_value("CIO 0.01", "bit")
        xs: list[float] = await plc.read_values("D100", "float32", 1)
        ns: list[int] = await plc.read_values("D110", "DINT", 1)
        s: Value = await plc.read_value("D100", "string:4")
        assert (r, n, w, d, b, xs, ns) == (21.5, -7, 0xFFF9, 1234, True, [21.5], [-7])
        assert isinstance(s, str)
        assert x == 21.5 and type(x) is float
        assert await plc.read_value("D110", "int32") == -7
        assert await plc.read_value("CIO 0.01", "bit") is True
        assert await plc.read_values("D100", "REAL", 1) == [21.5]


async def test_string_byte_orders_are_honoured_both_ways(url: str, sim: Simulator) -> None:
    plc_state = sim.plc
    assert isinstance(plc_state, VirtualPLC)
    async with aiofins.connect(url) as plc:
        await plc.write_value("D0", "ABCD", "string:4:BADC")
        assert plc_state.read("D0", 2) == [0x4241, 0x4443]  # first character in the low byte
        assert await plc.read_value("D0", "string:4:BADC") == "ABCD"
        assert await plc.read_value("D0", "string:4") == "BADC"
        await plc.write_value("D10", "ABCD", "string:4:ABCD")
        assert plc_state.read("D10", 2) == [0x4142, 0x4344]  # Omron's: high byte first
        for order in ("CDAB", "DCBA"):
            with pytest.raises(aiofins.CommandError, match="a string's byte order is ABCD"):
                await plc.read_value("D0", f"string:4:{order}")
    async with aiofins.connect(url, word_order="ABCD") as plc:  # numbers only
        assert await plc.read_value("D10", "string:4") == "ABCD"


def test_string_types_print_their_byte_order() -> None:
    assert str(parse_value_type("string:8:badc")) == "string:8:BADC"
    assert str(parse_value_type("string:8", default_word_order="DCBA")) == "string:8"
    assert parse_value_type("string:8", word_order="BADC").swap_bytes
