"""What :meth:`Client.read` / :meth:`Client.write` / typed values work out once per call shape.

A polling loop asks for the same address and count forever. Parsing the address text,
checking the span, splitting the transfer to the route's limit, validating and encoding each
frame's parameters are pure functions of ``(address, count, limit)``, so they are computed
once and kept in bounded caches (least recently used shapes go first); a call then looks its
plan up with one dictionary access and only packs or unpacks the data.
"""

from __future__ import annotations

import struct
import sys
from array import array
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache
from itertools import accumulate

from .chunking import plan_memory
from .protocol.addresses import parse_span
from .protocol.areas import MemoryAddress
from .protocol.arrays import WordArray
from .protocol.commands.memory import MemoryAreaRead, MemoryAreaWrite
from .protocol.errors import CommandError
from .protocol.values import Value, ValueType, WordOrder, parse_value_type, words_to_values
from .protocol.wordcodec import numeric_codec, pack_elements, unpack_elements

#: Distinct call shapes kept per cache (a shape is a few hundred bytes).
PLAN_CACHE_SIZE = 1024

_SWAP = sys.byteorder == "little"
#: One zero word, repeated to size an array in one allocation.
_ZERO = (0,)
#: ``struct`` codes of unsigned elements by size in bytes.
_ELEMENT_CODES = {1: "B", 2: "H", 4: "I"}

AddressLike = str | MemoryAddress


def cacheable(address: object) -> bool:
    """Whether ``address`` can key a plan cache (else the uncached path says what is wrong)."""
    return type(address) is str or type(address) is MemoryAddress


def start_address(address: AddressLike, count: int) -> MemoryAddress:
    """The address of the first of ``count`` elements.

    Address text (CS/CJ notation) is also checked for room for all ``count`` elements, so a
    transfer running past the end of its area fails here (:class:`AddressError`, end code
    1104) before anything is sent, instead of at the PLC, possibly after part of a split
    write. A :class:`MemoryAddress` is sent as given (it may be meant for another series).
    """
    return address if isinstance(address, MemoryAddress) else parse_span(address, count)


@dataclass(frozen=True, slots=True)
class ReadFrames:
    """The 0101 frames of one ``read(address, count)`` on a route: their parameters, and how
    to turn the replies' data into element values."""

    #: The 0101 requests, one per frame (for their checks and error messages).
    requests: tuple[MemoryAreaRead, ...]
    #: ``(0x01, 0x01, parameters)`` per frame, ready for the session.
    commands: tuple[tuple[int, int, bytes], ...]
    #: Data bytes each reply must carry.
    sizes: tuple[int, ...]
    #: Elements each frame reads.
    counts: tuple[int, ...]
    element_size: int
    #: A one-frame read's unpacker of its whole reply frame (the data after the 14 bytes of
    #: header, command code and end code: ``unpack_from(frame, 14)``), else None.
    unpack_from: Callable[[bytes, int], tuple[int, ...]] | None
    #: The size of that reply frame (header, command code, end code and data).
    reply_size: int
    #: Where each frame's data goes in the whole read's bytes (the sum of the sizes before),
    #: and where it ends there.
    offsets: tuple[int, ...]
    ends: tuple[int, ...]

    def one(self, frame: bytes) -> list[int]:
        """The elements of a one-frame read's reply ``frame`` (its data checked for its
        size first; decoded in place, no copy of the data)."""
        unpack_from = self.unpack_from
        if unpack_from is None or len(frame) != self.reply_size:
            return self.values((frame[14:],))
        return list(unpack_from(frame, 14))

    def values(self, data: Sequence[bytes]) -> list[int]:
        """The elements of the replies' data (each checked for its size first)."""
        for request, size, part in zip(self.requests, self.sizes, data, strict=True):
            if len(part) != size:
                request.decode_response(part)  # raises DecodeError saying what is wrong
        if not data:
            return []
        raw = data[0] if len(data) == 1 else b"".join(data)
        if self.element_size == 2:
            words = array("H", raw)
            if _SWAP:
                words.byteswap()
            return words.tolist()
        return list(unpack_elements(raw, self.element_size))


@lru_cache(maxsize=PLAN_CACHE_SIZE)
def read_frames(address: AddressLike, count: int, limit: int) -> ReadFrames:
    """The frames of ``count`` elements from ``address`` at ``limit`` elements per frame."""
    if count < 0:
        raise CommandError(f"count must not be negative, got {count}")
    start = start_address(address, count)
    requests = tuple(MemoryAreaRead(c.address, c.count) for c in plan_memory(start, count, limit))
    size = requests[0].element_size if requests else 2
    code = _ELEMENT_CODES[size]
    return ReadFrames(
        requests,
        tuple((r.MRC, r.SRC, r.encode()) for r in requests),
        tuple(r.count * size for r in requests),
        tuple(r.count for r in requests),
        size,
        struct.Struct(f">{count}{code}").unpack_from if len(requests) == 1 else None,
        14 + count * size,
        tuple(accumulate((r.count * size for r in requests[:-1]), initial=0)) if requests else (),
        tuple(accumulate(r.count * size for r in requests)),
    )


class FrameWords:
    """The words of a read of words, as its reply frames come: :meth:`put` (a batch's
    ``on_frame``) checks each frame's data for its size and copies it into its place in
    one ``array('H')``, sized once (no :class:`Response` and no Python object per word);
    :meth:`words` swaps the bytes once at the end. ``progress(done, total)`` is told the
    words read so far after each frame."""

    __slots__ = (
        "ends",
        "final",
        "into",
        "last",
        "out",
        "plan",
        "progress",
        "read",
        "starts",
        "total",
    )

    def __init__(self, plan: ReadFrames, progress: Callable[[int, int], object] | None) -> None:
        self.plan = plan
        self.progress = progress
        self.read = 0
        self.total = sum(plan.counts)
        #: Where each frame's data goes in the array's bytes, and where it ends.
        self.starts = plan.offsets
        self.ends = plan.ends
        self.out = array("H", _ZERO) * (sum(plan.sizes) >> 1)
        self.into = memoryview(self.out).cast("B")
        #: The last command's index, and its reply frame once it came (its end code is
        #: the call's ``last_end_code``).
        self.final = len(plan.sizes) - 1
        self.last: bytes | None = None

    def put(self, index: int, frame: bytes) -> None:
        """Frame ``index``'s reply: its data (``frame[14:]``) into its place."""
        at = self.starts[index]
        end = self.ends[index]
        if len(frame) != end - at + 14:
            self.plan.requests[index].decode_response(frame[14:])  # raises DecodeError
        self.into[at:end] = frame[14:]  # (a bytes slice: cheaper than a memoryview's)
        if index == self.final:
            self.last = frame
        if self.progress is not None:
            self.read += self.plan.counts[index]
            self.progress(self.read, self.total)

    def release(self) -> None:
        """No buffer of the array left exported (the caller may grow it)."""
        self.into.release()

    def words(self) -> WordArray:
        """The words read, in the host's byte order (after every frame came)."""
        self.into.release()
        words = self.out
        if _SWAP:
            words.byteswap()
        return words


@dataclass(frozen=True, slots=True)
class WriteFrames:
    """The 0102 frames of one ``write(address, n values)`` on a route."""

    start: MemoryAddress
    #: ``(offset into the values, count, parameter prefix: address and count)`` per frame.
    frames: tuple[tuple[int, int, bytes], ...]
    element_size: int
    #: Words of the last frame's limit (for the error of a split write not allowed).
    limit: int

    def params(self, index: int, values: Sequence[int]) -> bytes:
        """The parameters of frame ``index`` with its share of ``values``, checked as
        :class:`MemoryAreaWrite` checks them (an unfit value raises its error)."""
        offset, count, prefix = self.frames[index]
        part = values[offset : offset + count]
        size = self.element_size
        data = pack_elements(part, size)
        if data is None or (size == 1 and data and max(data) > 1):
            address = MemoryAddress.decode(prefix[:4])
            return MemoryAreaWrite.from_values(address, part).encode()  # raises the error
        return prefix + data

    def array_params(self, index: int, words: WordArray) -> bytes:
        """The parameters of frame ``index`` with its share of ``words`` (an ``array('H')``
        in the host's byte order: every element is a word already, nothing to check)."""
        offset, count, prefix = self.frames[index]
        part = words[offset : offset + count]
        if _SWAP:
            part.byteswap()
        return prefix + part.tobytes()


@lru_cache(maxsize=PLAN_CACHE_SIZE)
def write_frames(address: AddressLike, count: int, limit: int) -> WriteFrames:
    """The frames of a write of ``count`` elements from ``address``; the address is checked
    as :class:`MemoryAreaWrite` checks it (writable area, not the EM bank number word)."""
    start = start_address(address, count)
    chunks = plan_memory(start, count, limit)
    frames = []
    size = 0
    for c in chunks:
        size = MemoryAreaWrite(c.address, b"").element_size  # the address checks first
        request = MemoryAreaWrite(c.address, bytes(c.count * size))
        frames.append((c.offset, c.count, request.encode()[:6]))
    if not chunks:
        size = MemoryAreaWrite(start, b"").element_size
    return WriteFrames(start, tuple(frames), size, limit)


@dataclass(frozen=True, slots=True)
class TypedRead:
    """``count`` values of one type from an address: the words to read, and their decoder."""

    start: AddressLike
    words: int
    vtype: ValueType
    #: (memory words struct, values struct) of a numeric run, else None.
    codec: tuple[struct.Struct, struct.Struct] | None

    def decode(self, words: Sequence[int]) -> list[Value]:
        codec = self.codec
        if codec is not None and len(words) == self.words:
            try:
                return list(codec[1].unpack(codec[0].pack(*words)))
            except struct.error:
                pass  # a word out of range: the per-value path names it
        return words_to_values(self.vtype, words)


@lru_cache(maxsize=PLAN_CACHE_SIZE)
def typed_read(
    address: AddressLike, spec: str | ValueType, count: int, word_order: str
) -> TypedRead:
    """The plan of ``read_values(address, spec, count)`` for a client's word order (its
    :class:`WordOrder` value: a str hashes faster than the enum)."""
    vtype = value_type(spec, WordOrder(word_order))
    codec = numeric_codec(vtype, count) if vtype.kind not in ("bcd16", "bcd32") else None
    return TypedRead(typed_start(address, vtype, count), vtype.words * count, vtype, codec)


@lru_cache(maxsize=PLAN_CACHE_SIZE)
def value_type(spec: str | ValueType, word_order: WordOrder) -> ValueType:
    """:func:`parse_value_type` with ``default_word_order``, once per spec."""
    return parse_value_type(spec, default_word_order=word_order)


@lru_cache(maxsize=PLAN_CACHE_SIZE)
def typed_start(address: AddressLike, vtype: ValueType, count: int) -> AddressLike:
    """:func:`start_address` for ``count`` values of ``vtype``, which (but for ``bit``) need
    words: a typed value at a bit address would read its bits as the value's words."""
    if vtype.kind == "bit":
        return address
    start = start_address(address, vtype.words * count)
    size = start.element_size
    if size != 2:
        what = "a bit address" if size == 1 else f"an area of {size}-byte elements"
        raise CommandError(
            f"{address} is {what}: {vtype.kind} values need word addresses (drop the type, "
            "or use 'bit' for bits)"
        )
    return start
