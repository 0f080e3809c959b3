"""The virtual PLC's tables are keyed by the protocol's command codes, one entry per operation."""

from __future__ import annotations

from aiofins.protocol.commands import ALL_OPERATIONS, COMMAND_CODES
from aiofins.protocol.commands.access import AccessRightAcquire
from aiofins.protocol.commands.file import MemoryCassetteTransfer, ProgramAreaFileTransfer
from aiofins.protocol.commands.memory import MemoryAreaRead
from aiofins.protocol.commands.message import FalFalsRead, MessageClear, MessageRead
from aiofins.simulator.codes import by_command_code
from aiofins.simulator.handlers import HANDLERS, UNANSWERED
from aiofins.simulator.plc import VirtualPLC
from aiofins.simulator.restrictions import RESTRICTIONS, restriction_for

OPERATION_CODES = {op.command_code() for op in ALL_OPERATIONS}
HEADER = bytes.fromhex("80 00 02 00 01 00 00 22 00 31")  # to node 1 from node 0x22, SID 31


def _code(key: int | tuple[int, str]) -> int:
    return key[0] if isinstance(key, tuple) else key


def test_every_handler_key_is_an_operation_code() -> None:
    assert set(HANDLERS) <= OPERATION_CODES
    assert OPERATION_CODES == COMMAND_CODES


def test_every_restriction_key_is_an_operation_code() -> None:
    assert {_code(key) for key in RESTRICTIONS} <= OPERATION_CODES


def test_every_operation_has_a_handler_unless_explicitly_unanswered() -> None:
    unanswered = {op.command_code() for op in UNANSWERED}
    assert unanswered == {MemoryCassetteTransfer.command_code()}
    assert not unanswered & set(HANDLERS)
    missing = [op.NAME for op in ALL_OPERATIONS if op.command_code() not in HANDLERS]
    assert missing == [op.NAME for op in UNANSWERED]


def test_every_operation_has_a_restriction_row() -> None:
    assert {_code(key) for key in RESTRICTIONS} == OPERATION_CODES
    for op in ALL_OPERATIONS:
        rows = [key for key in RESTRICTIONS if _code(key) == op.command_code()]
        assert rows, op.NAME


def test_restriction_rows_keep_the_manual_order() -> None:
    codes = [_code(key) for key in RESTRICTIONS]
    assert codes == sorted(codes)
    assert len(RESTRICTIONS) == 51  # 45 codes; 0920, 220B and 220C have three rows each


def test_message_operations_share_one_handler_and_have_their_own_rows() -> None:
    code = MessageRead.command_code()
    assert code == 0x0920
    assert {MessageClear.command_code(), FalFalsRead.command_code()} == {code}
    assert [key for key in RESTRICTIONS if _code(key) == code] == [
        (code, "read"),
        (code, "clear"),
        (code, "fal"),
    ]
    # each operation's own encoding selects its row
    read = restriction_for(code, MessageRead(0x0001).encode())
    clear = restriction_for(code, MessageClear(0x0001).encode())
    fal = restriction_for(code, FalFalsRead(1).encode())
    assert read is RESTRICTIONS[(code, "read")]
    assert clear is RESTRICTIONS[(code, "clear")] and not clear.access_right
    assert fal is RESTRICTIONS[(code, "fal")]


def test_area_file_transfers_keep_their_variant_rows() -> None:
    code = ProgramAreaFileTransfer.command_code()
    assert [key[1] for key in RESTRICTIONS if isinstance(key, tuple) and key[0] == code] == [
        "to_file",
        "from_file",
        "compare",
    ]


def test_by_command_code_refuses_two_values_for_one_code() -> None:
    assert by_command_code({MemoryAreaRead: 1}) == {0x0101: 1}
    shared = object()
    assert by_command_code({MessageRead: shared, MessageClear: shared}) == {0x0920: shared}
    try:
        by_command_code({MessageRead: object(), MessageClear: object()})
    except ValueError as exc:
        assert "0920" in str(exc)
    else:
        raise AssertionError("two values for 0920 accepted")


def test_access_right_acquire_refusal_still_names_the_holder() -> None:
    plc = VirtualPLC()
    plc.handle_frame(bytes.fromhex("80 00 02 00 01 00 00 33 00 01") + b"\x0c\x01\xff\xff")
    frame = HEADER + AccessRightAcquire.command_code().to_bytes(2, "big") + b"\xff\xff"
    reply = plc.handle_frame(frame)
    assert reply is not None
    assert reply[10:12] == b"\x0c\x01"
    assert reply[12:14] == b"\x30\x01" and reply[14:] == bytes((0, 0x33, 0))
