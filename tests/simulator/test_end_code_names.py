"""The simulator's named end codes are rows of the manual's end-code table (5-1-3)."""

from __future__ import annotations

from aiofins.protocol.endcodes import END_CODES
from aiofins.simulator import state

#: Named in state.py but given only in a command's own section, not in 5-1-3's table.
OUTSIDE_THE_TABLE = {"TOO_MANY_WORDS": 0x1108}  # 5-3-7 PARAMETER AREA READ

NAMED = {
    name: value
    for name, value in vars(state).items()
    if name.isupper() and isinstance(value, int) and name != "LOG_CAPACITY"
}


def test_every_named_end_code_is_in_the_manual_table() -> None:
    assert len(NAMED) >= 25
    for name, code in NAMED.items():
        if name in OUTSIDE_THE_TABLE:
            assert code == OUTSIDE_THE_TABLE[name] and code not in END_CODES
        else:
            assert code in END_CODES, f"{name} = {code:04X} is not in the end-code table"
