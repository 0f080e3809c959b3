"""Bad input from the user is refused with a CommandError before anything is sent (#17 item 4):
the API, URLs and Pool arguments share one wording (tests/client/test_cli_inputs.py: the CLI)."""

from __future__ import annotations

import math
from typing import Any

import pytest

import aiofins
from aiofins.simulator.plc import VirtualPLC
from aiofins.simulator.runner import Simulator

pytestmark = pytest.mark.anyio

SECONDS = "timeout must be a positive number of seconds; got nan"
CALL_SECONDS = r"timeout must be a positive number of seconds \(or inf\); got nan"


def frames(sim: Simulator) -> int:
    plc = sim.plc
    assert isinstance(plc, VirtualPLC)
    return plc.frames_handled


async def test_nan_timeouts_are_refused_everywhere(url: str, sim: Simulator) -> None:
    """NaN compares false with everything: taken as a timeout it disabled every deadline."""
    with pytest.raises(aiofins.CommandError, match=SECONDS):
        async with aiofins.connect(url, timeout=math.nan):
            pass
    with pytest.raises(aiofins.CommandError, match=SECONDS.replace("nan", "'nan'")):
        async with aiofins.connect(url + "?timeout=nan"):
            pass
    async with aiofins.connect(url) as plc:
        before = frames(sim)
        for call in (
            lambda: plc.read("D0", 1, timeout=math.nan),
            lambda: plc.write("D0", [1], timeout=math.nan),
            lambda: plc.cpu_unit_status_read(timeout=math.nan),
            lambda: plc.execute(0x01, 0x01, b"\x82\x00\x00\x00\x00\x01", timeout=math.nan),
        ):
            with pytest.raises(aiofins.CommandError, match=CALL_SECONDS):
                await call()
        with pytest.raises(aiofins.CommandError, match="retries must be a whole number"):
            await plc.read("D0", 1, retries=1.5)  # type: ignore[arg-type]
        assert frames(sim) == before


async def test_wrong_types_are_command_errors_not_type_errors(url: str, sim: Simulator) -> None:
    async with aiofins.connect(url) as plc:
        await plc.write("D0", [7, 8])
        before = frames(sim)
        untyped: Any = plc  # what a caller without a type checker can pass
        cases: list[tuple[Any, str]] = [
            (untyped.read("D0", 1.5), r"^count must be a whole number, at least 0; got 1\.5$"),
            (untyped.read("D0", True), r"^count must be a whole number, at least 0; got True$"),
            (untyped.write("D0", 5), r"values must be a sequence of word \(or bit\) values"),
            (untyped.write("D0", b"\x01\x02"), r"got bytes: pass list\(data\)"),
            (untyped.write("D0", "12"), r"values must be a sequence .* got '12'"),
        ]
        for coro, said in cases:
            with pytest.raises(aiofins.CommandError, match=said):
                await coro
        assert frames(sim) == before
        assert await plc.read("D0", 2) == [7, 8]  # nothing was written


async def test_connect_needs_a_url_string() -> None:
    with pytest.raises(aiofins.CommandError, match="the connection URL must be text"):
        async with aiofins.connect(None):
            pass


@pytest.mark.parametrize(
    ("options", "said"),
    [
        ({"retries": -1}, "retries must be a whole number, at least 0; got -1"),
        ({"retries": 1.0}, "retries must be a whole number, at least 0; got 1.0"),
        ({"max_in_flight": 0}, r"max_in_flight must be a whole number, 1\.\.255; got 0"),
        ({"gct": 256}, r"gct must be a whole number, 0\.\.255; got 256"),
        ({"read_only": "yes"}, "read_only must be True or False"),
        ({"tcp_connect_timeout": math.nan}, "tcp_connect_timeout must be a positive number"),
    ],
)
async def test_connect_options_are_checked_before_connecting(
    url: str, options: dict[str, Any], said: str
) -> None:
    with pytest.raises(aiofins.CommandError, match=said):
        async with aiofins.connect(url, **options):
            pass


async def test_typed_values_that_overflow_are_refused(url: str, sim: Simulator) -> None:
    async with aiofins.connect(url) as plc:
        before = frames(sim)
        with pytest.raises(aiofins.CommandError, match=r"value 1e\+39 overflows float32"):
            await plc.write_value("D0", 1e39, "float32")
        with pytest.raises(aiofins.CommandError, match="an integer of 20000 bits does not fit"):
            await plc.write_value("D0", int("f" * 5000, 16), "uint64")
        assert frames(sim) == before


async def test_addresses_that_are_not_fins_addresses_are_refused(url: str, sim: Simulator) -> None:
    """dest=7 (a node number, not an address) raised AttributeError from inside connect()."""
    before = frames(sim)
    cases: list[tuple[dict[str, Any], str]] = [
        ({"dest": 7}, "a FINS address is a FinsAddress or 'NET.NODE.UNIT' text, got 7"),
        ({"src": "x"}, "FINS address 'x' is not NET.NODE"),
    ]
    for kwargs, message in cases:
        with pytest.raises(aiofins.CommandError, match=message):
            async with aiofins.connect(url, **kwargs):
                pass
    assert frames(sim) == before
