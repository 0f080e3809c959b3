"""Plans that split any transfer into frames that fit the route's limits.

Pure functions (no I/O): the client sends the chunks, pipelined up to the session's in-flight
cap, and reassembles them in order. Limits come from :mod:`aiofins.protocol.limits`
(999/997 words on Ethernet and Controller Link, 269/267 on SYSMAC LINK, DeviceNet, SYSWAY and
Host Link, 167/89 elements for 0104, 498 parameter words, 992/996 program bytes).

Element addresses advance the way the PLC numbers them: bit areas (``CIO 0.15`` + 1 is
``CIO 1.00``) carry from bit 15 into the next word; every other area advances one word (or one
timer/counter/flag) per element.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from .protocol.areas import MemoryAddress
from .protocol.errors import CommandError

#: Bytes that must stay a multiple of this in program area reads and writes (manual 5-3-9/10).
PROGRAM_BLOCK_UNIT = 4


def offset_address(address: MemoryAddress, elements: int) -> MemoryAddress:
    """The address ``elements`` elements after ``address`` (see :meth:`MemoryAddress.offset`)."""
    if elements < 0:
        raise CommandError("element offset must not be negative")
    return address.offset(elements)


@dataclass(frozen=True)
class Chunk:
    """One frame's share: ``count`` elements from ``address``, ``offset`` into the whole."""

    offset: int
    address: MemoryAddress
    count: int


def split(total: int, limit: int) -> list[tuple[int, int]]:
    """``(offset, size)`` pieces of at most ``limit`` covering ``0..total`` in order."""
    if limit < 1:
        raise CommandError(f"limit must be at least 1, got {limit}")
    if total < 0:
        raise CommandError(f"size must not be negative, got {total}")
    return [(start, min(limit, total - start)) for start in range(0, total, limit)]


def plan_memory(address: MemoryAddress, count: int, limit: int) -> list[Chunk]:
    """Chunks of a MEMORY AREA READ/WRITE/FILL of ``count`` elements from ``address``."""
    return [Chunk(off, offset_address(address, off), n) for off, n in split(count, limit)]


def plan_multiple(addresses: Sequence[MemoryAddress], limit: int) -> list[list[MemoryAddress]]:
    """MULTIPLE MEMORY AREA READ frames of at most ``limit`` elements, order kept."""
    return [list(addresses[off : off + n]) for off, n in split(len(addresses), limit)]


@dataclass(frozen=True)
class Block:
    """A parameter-area or program-area piece: start (word or byte), size, last piece or not."""

    start: int
    size: int
    last: bool


def plan_parameter(begin_word: int, words: int, limit: int = 498) -> list[Block]:
    """PARAMETER AREA READ/WRITE pieces (498 words each by the manual)."""
    pieces = split(words, limit)
    return [Block(begin_word + off, n, i == len(pieces) - 1) for i, (off, n) in enumerate(pieces)]


def plan_program(begin: int, size: int, limit: int) -> list[Block]:
    """PROGRAM AREA READ (992) / WRITE (996) pieces; sizes stay multiples of 4 bytes."""
    if size % PROGRAM_BLOCK_UNIT:
        raise CommandError(f"program data must be a multiple of 4 bytes, got {size}")
    unit_limit = limit - limit % PROGRAM_BLOCK_UNIT
    pieces = split(size, unit_limit)
    return [Block(begin + off, n, i == len(pieces) - 1) for i, (off, n) in enumerate(pieces)]


def plan_file(position: int, size: int, limit: int) -> list[Block]:
    """SINGLE FILE READ/WRITE pieces of at most ``limit`` bytes from ``position``."""
    pieces = split(size, limit)
    return [Block(position + off, n, i == len(pieces) - 1) for i, (off, n) in enumerate(pieces)]
