"""The table behind read-only clients: one row per command code, decided by parameters where
the manual's command carries several operations."""

from __future__ import annotations

from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiofins.protocol.commands import ALL_OPERATIONS, Request
from aiofins.protocol.commands.message import FalFalsRead, MessageClear, MessageRead
from aiofins.protocol.commands.status import CycleTimeParameter, CycleTimeRead
from aiofins.protocol.errors import CommandError, ReadOnlyError
from aiofins.protocol.guard import CHANGES, changes, check_read_only

#: The manual's 5-1-1 note 1: refused by the PLC's own FINS write protection.
NOTE_1 = {
    0x0102, 0x0103, 0x0105, 0x0202, 0x0203, 0x0307, 0x0308, 0x0401, 0x0402, 0x0702, 0x0C01,
    0x2101, 0x2103, 0x2141, 0x2203, 0x2204, 0x2205, 0x2207, 0x2208, 0x220A, 0x220B, 0x220C,
    0x2215, 0x2301, 0x2302,
}  # fmt: skip


def test_every_command_of_note_1_changes_the_plc() -> None:
    assert {code for code in NOTE_1 if CHANGES[code] is None} == set()


def test_reads_are_reads() -> None:
    reads = {code for code, what in CHANGES.items() if what is None}
    assert reads == {
        0x0101, 0x0104, 0x0201, 0x0306, 0x0501, 0x0502, 0x0601, 0x0701, 0x2102, 0x2140,
        0x2201, 0x2202,
    }  # fmt: skip
    assert set(CHANGES) == {op.command_code() for op in ALL_OPERATIONS}


@pytest.mark.parametrize(
    ("request_", "what"),
    [
        (MessageRead(0xFF), None),
        (FalFalsRead(1), None),
        (MessageClear(0xFF), "the messages"),
        (CycleTimeRead(CycleTimeParameter.READ), None),
        (CycleTimeRead(CycleTimeParameter.INITIALIZE), "the cycle time statistics"),
    ],
)
def test_parameters_decide_for_0920_and_0620(request_: Request[Any], what: str | None) -> None:
    assert changes(request_.MRC, request_.SRC, request_.encode()) == what


@given(st.integers(0, 255), st.integers(0, 255), st.binary(max_size=40))
def test_any_command_is_judged_without_crashing(mrc: int, src: int, params: bytes) -> None:
    what = changes(mrc, src, params)
    if (mrc << 8) | src not in CHANGES:
        assert what is not None  # unknown: refused
    try:
        check_read_only(mrc, src, params)
    except ReadOnlyError as exc:
        assert isinstance(exc, CommandError) and exc.changes == what
    else:
        assert what is None
