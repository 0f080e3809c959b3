"""Errors name the fix: a word write of a value no word holds names the typed write that
takes it; a mistyped address gets a "did you mean"."""

from __future__ import annotations

from typing import Any

import pytest

from aiofins import AddressError, CommandError, MemoryTransport, connect
from aiofins.cli import main
from aiofins.simulator import VirtualPLC


@pytest.mark.parametrize(
    ("values", "fix"),
    [
        # it said "1.5 out of range 0..65535" and nothing more
        ([1.5], "write_value('D100', 1.5, 'float32') (write_values for several; "),
        ([1, -1], "as an INT (1 word), use write_value('D100', -1, 'int16')"),
        ([70000], "as a UDINT (2 words), use write_value('D100', 70000, 'uint32')"),
        ([-70000], "write_value('D100', -70000, 'int32')"),
        ([1 << 40], "write_value('D100', 1099511627776, 'uint64')"),
        (
            ["abc"],
            "as text (one word per two characters), use write_value('D100', 'abc', 'string:4')",
        ),
    ],
)
@pytest.mark.anyio
async def test_a_word_write_of_another_type_names_the_typed_write(
    anyio_backend: object, values: list[object], fix: str
) -> None:
    plc = VirtualPLC()
    async with connect(transport=MemoryTransport(plc.handle_frame)) as client:
        with pytest.raises(CommandError) as info:
            await client.write("D100", values)  # type: ignore[arg-type]
        message = str(info.value)
        assert "is no word value (a word holds a whole number 0..65535)" in message
        assert fix in message and "--type" in message
        kind = fix.split("'")[-2]
        value: Any = values[-1]
        await client.write_value("D100", value, kind)
        assert await client.read_value("D100", kind) == value


@pytest.mark.anyio
async def test_a_bit_out_of_range_keeps_its_own_message(anyio_backend: object) -> None:
    plc = VirtualPLC()
    async with connect(transport=MemoryTransport(plc.handle_frame)) as client:
        with pytest.raises(CommandError, match=r"bit value 2 at element 0 of CIO0.00 out of"):
            await client.write("CIO 0.00", [2])


@pytest.mark.parametrize(
    ("value", "fix"),
    [
        ("1.5", "add --type float32"),
        ("-1", "add --type int16"),
        ("70000", "add --type uint32"),
        ("abc", "add --type string:4"),
    ],
)
def test_the_command_line_names_the_type_option(
    capsys: pytest.CaptureFixture[str], value: str, fix: str
) -> None:
    """Refused before anything opens (the URL is never reached)."""
    code = main(["write", "udp://127.0.0.1:1", "D100", "--yes", "--", value])
    err = capsys.readouterr().err
    assert code != 0
    assert f"value {value!r} is no word (a whole number 0..65535, 0x.. hex accepted)" in err
    assert err.rstrip().endswith(fix)


@pytest.mark.parametrize(
    ("typed", "meant"),
    [
        ("D1OO", "D100"),
        ("d1oo", "D100"),
        ("W1O.O1", "W10.01"),
        ("CIO 1O.13", "CIO 10.13"),
        ("CI0 10", "CIO 10"),
        ("E3_1OO", "E3_100"),
        ("DN100", "DM100"),
        ("Dl00", "D100"),
        ("P_0n", "P_On"),
    ],
)
@pytest.mark.anyio
async def test_a_mistyped_address_gets_a_did_you_mean(
    anyio_backend: object, typed: str, meant: str
) -> None:
    plc = VirtualPLC()
    async with connect(transport=MemoryTransport(plc.handle_frame)) as client:
        with pytest.raises(AddressError) as info:
            await client.read(typed)
        assert str(info.value).startswith(repr(typed))
        assert str(info.value).endswith(f"; did you mean {meant}?")
        await client.read(meant)  # what it suggests is an address


def test_no_suggestion_when_nothing_is_close(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(AddressError) as info:
        from aiofins.protocol.addresses import parse_address

        parse_address("XYZ")
    assert "did you mean" not in str(info.value)
    assert main(["read", "udp://127.0.0.1:1", "D1OO"]) != 0
    assert "'D1OO': not an address" in (err := capsys.readouterr().err)
    assert "did you mean D100?" in err
