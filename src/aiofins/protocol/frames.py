"""Pure helpers on whole command and reply frames that the session's request path uses.

Byte offsets of the 10-byte header (see :mod:`aiofins.protocol.header`) as named constants,
the packing of a command's head, the check that a command fits a frame, the 32-bit key a
reply is matched by, and the exception a non-normal end code maps to. No I/O, no clock.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

from .endcodes import CPU_ERROR_FLAGS, END_CODE_MASK, EndCode
from .errors import CommandError, FinsError, RelayError, error_for_end_code
from .header import MAX_PARAMETER_SIZE

#: Offsets in a frame: ICF, destination (DNA DA1 DA2), source (SNA SA1 SA2), SID, command
#: code (MRC SRC), then in a reply the end code (MRES SRES) and a relay error's trailer.
ICF = 0
DNA = 3
DA1 = 4
SNA = 6
SA1 = 7
SID = 9
MRC = 10
SRC = 11
END_CODE = 12
RELAY_TRAILER = 14
#: Shortest reply: header, command code and end code.
MIN_REPLY_SIZE = 14
#: Shortest reply carrying a relay error (end code bit 15): the 2-byte trailer follows.
MIN_RELAY_REPLY_SIZE = 16

#: The end codes that mean "busy, not executed" (2604 too many commands, 2605 service in
#: progress): the command may be sent again.
BUSY_CODES = (0x2604, 0x2605)
#: End code bits that make a reply an error: all but the CPU error flags (0040/0080 are normal).
ERROR_BITS = 0xFFFF & ~CPU_ERROR_FLAGS
#: The head of a command: the 9-byte ``ICF RSV GCT DNA DA1 DA2 SNA SA1 SA2`` prefix of its
#: destination, then SID, MRC, SRC.
pack_head = struct.Struct("9sBBB").pack

_unpack_key = struct.Struct(">I").unpack_from

#: ``(ICF, to, key, MRC, SRC, end code)`` of a reply in one call (``struct.error`` when the
#: frame is shorter than :data:`MIN_REPLY_SIZE`): what the session matches each reply by.
#: ``to & 0xFFFFFF`` is the reply's ``DNA DA1 DA2`` as :func:`address_bits` gives an address
#: (the byte above it is GCT); the key is as :func:`reply_key` gives it.
unpack_reply_head = struct.Struct(">BxIIBBH").unpack_from
#: The ``DNA DA1 DA2`` bits of :func:`unpack_reply_head`'s ``to``.
ADDRESS_MASK = 0xFFFFFF
#: The ICF values of a response (bit 6 set, bits 1-5 clear; bit 0 and bit 7 either way:
#: some servers set bit 0).
RESPONSE_ICFS = frozenset({0x40, 0x41, 0xC0, 0xC1})
#: End code bit 15: a relay error (the end code comes from a relay point).
RELAY_ERROR_BIT = 0x8000


def reply_key(frame: bytes) -> int:
    """``SNA SA1 SA2 SID`` of a reply as one integer: the ``DNA DA1 DA2 SID`` of its command."""
    key: int = _unpack_key(frame, SNA)[0]
    return key


def command_key(frame: bytes) -> int:
    """``DNA DA1 DA2 SID`` of a command as one integer (what its reply's :func:`reply_key` is)."""
    return (frame[DNA] << 24) | (frame[DNA + 1] << 16) | (frame[DNA + 2] << 8) | frame[SID]


def address_bits(network: int, node: int, unit: int) -> int:
    """``network node unit`` as one 24-bit integer, the ``DNA DA1 DA2`` of a reply to it."""
    return (network << 16) | (node << 8) | unit


def same_address(a: int, b: int) -> bool:
    """Whether two :func:`address_bits` name the same node and unit, network 0 (the local
    network) matching any network number (a node may fill in its real one)."""
    return a == b or ((a ^ b) & 0xFFFF == 0 and not (a >> 16 and b >> 16))


def key_address(key: int) -> tuple[int, int, int]:
    """The ``(network, node, unit)`` a request key (:func:`command_key`) is addressed to."""
    return key >> 24, (key >> 16) & 0xFF, (key >> 8) & 0xFF


def reply_end_code(frame: bytes) -> int:
    """A reply's 16-bit end code (MRES SRES), flags included."""
    return (frame[END_CODE] << 8) | frame[END_CODE + 1]


def header_prefix(gct: int, dest: tuple[int, int, int], source: tuple[int, int, int]) -> bytes:
    """``ICF RSV GCT DNA DA1 DA2 SNA SA1 SA2``: a command's header before its SID."""
    return bytes((0x80, 0, gct, *dest, *source))


def is_busy(end_code: int) -> bool:
    """Whether ``end_code`` says the command was not executed because the node was busy."""
    return (end_code & END_CODE_MASK) in BUSY_CODES


def check_command(mrc: object, src: object, params: object) -> None:
    """Refuse a command code or parameter block no FINS frame can carry, before sending
    (typed ``object``: it checks what a caller passed, whatever that is)."""
    if not isinstance(params, (bytes, bytearray, memoryview)):
        raise TypeError(f"command parameters must be bytes, got {type(params).__name__}")
    if not (isinstance(mrc, int) and isinstance(src, int)):
        kinds = f"{type(mrc).__name__}/{type(src).__name__}"
        raise TypeError(f"command codes must be ints, got {kinds}")
    if not (0 <= mrc <= 0xFF and 0 <= src <= 0xFF):
        raise CommandError(f"command code {mrc:#x}/{src:#x} out of range 0..255")
    if len(params) > MAX_PARAMETER_SIZE:
        raise CommandError(
            f"{len(params)} parameter bytes exceed the FINS limit of {MAX_PARAMETER_SIZE}"
        )


_PARAMETER_TYPES = frozenset({bytes, bytearray, memoryview})


def check_commands(commands: Sequence[tuple[object, object, object]]) -> None:
    """:func:`check_command` for each of ``commands`` (``(mrc, src, params)``). When every
    one fits, as nearly always, that is found in a few passes over the whole list in C;
    the loop that says which does not only runs when one may not."""
    try:
        mrcs, srcs, blocks = zip(*commands, strict=True)
        bytes(mrcs + srcs)  # every code an int in 0..255 (else ValueError or TypeError)
        if {*map(type, blocks)} <= _PARAMETER_TYPES and max(map(len, blocks)) <= MAX_PARAMETER_SIZE:
            return
    except (TypeError, ValueError):  # (and when there are none)
        pass
    for mrc, src, params in commands:
        check_command(mrc, src, params)


def end_code_error(frame: bytes, mrc: int, src: int) -> FinsError:
    """The exception for a reply with a non-normal end code (relay errors name the relay)."""
    end_code = EndCode((frame[END_CODE] << 8) | frame[END_CODE + 1])
    command_code = (mrc << 8) | src
    if end_code.relay_error:
        return RelayError(
            end_code,
            network=frame[RELAY_TRAILER],
            node=frame[RELAY_TRAILER + 1],
            command_code=command_code,
            data=frame[RELAY_TRAILER + 2 :],
        )
    return error_for_end_code(end_code, command_code=command_code, data=frame[RELAY_TRAILER:])
