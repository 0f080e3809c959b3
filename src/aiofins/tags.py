"""Tag lists compiled into the fewest frames: 0101 runs of nearby words plus 0104 for the rest.

A tag is ``"ADDRESS[:TYPE]"`` — ``"D100:float32"``, ``"CIO 0.01"`` (a bit), ``"D200:uint32"``,
``"T5"`` (a timer PV), ``"H10:string:8"``. :func:`compile_tags` groups the words every tag needs
by area, merges runs whose gap is at most ``max_gap`` words into MEMORY AREA READ (0101) frames
under the route's word limit, and reads what is left — short isolated runs and flags that have
no word view (timer/counter completion flags, task flags, clock pulses) — with MULTIPLE MEMORY
AREA READ (0104), up to its element limit per frame, whenever that needs fewer frames.

Bits of word areas (CIO, W, H, A, DM, EM) are read through their word, so ``CIO 0.01`` and
``CIO 0.02`` and ``CIO 0`` cost one word. The :class:`ReadPlan` is immutable and reusable:
compile once, execute every scan.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from itertools import chain
from operator import and_, itemgetter, truth
from typing import Any

from .chunking import plan_multiple
from .protocol.addresses import parse_address
from .protocol.areas import MemoryAddress, check_span
from .protocol.commands.memory import MemoryAreaRead, MultipleMemoryAreaRead
from .protocol.errors import AddressError, CommandError, DecodeError
from .protocol.frames import MIN_REPLY_SIZE
from .protocol.values import Value, ValueType, WordOrder, parse_value_type
from .protocol.wordcodec import NUMBER_CODES

__all__ = ["ReadPlan", "Tag", "TagNames", "WordRun", "compile_tags", "parse_tag"]

#: Bit area code → the word area code holding the same bits (CS/CJ codes).
BIT_TO_WORD_AREA: dict[int, int] = {
    0x30: 0xB0,  # CIO
    0x31: 0xB1,  # W
    0x32: 0xB2,  # H
    0x33: 0xB3,  # A
    0x02: 0x82,  # DM
    0x0A: 0x98,  # EM current bank
    **{0x20 + bank: 0xA0 + bank for bank in range(16)},  # EM banks 0-F
    **{0xE0 + bank: 0x60 + bank for bank in range(9)},  # EM banks 10-18
}
#: Word areas a 0101 read can span (2-byte elements).
WORD_AREAS: frozenset[int] = frozenset(
    {0xB0, 0xB1, 0xB2, 0xB3, 0x82, 0x98, 0x89, *range(0xA0, 0xB0), *range(0x60, 0x69)}
)


@dataclass(frozen=True)
class Tag:
    """One named value: where it lives and how to read its words."""

    name: str
    address: MemoryAddress
    vtype: ValueType
    text: str

    @property
    def word_area(self) -> int | None:
        """The word area the tag is read from, or None if it has no word view."""
        code = self.address.area_code
        if self.vtype.kind == "bit" and code in BIT_TO_WORD_AREA:
            return BIT_TO_WORD_AREA[code]
        if code in WORD_AREAS and (self.vtype.kind != "bit" or self.address.bit == 0):
            return code
        return None

    @property
    def width(self) -> int:
        """The words the tag needs from its word area (a bit: the one word holding it)."""
        return 1 if self.vtype.kind == "bit" else self.vtype.words


def parse_tag(name: str, spec: str) -> Tag:
    """``"D100:float32"`` → :class:`Tag`. Bits default to ``bit``, words to ``uint16``."""
    text, _, type_text = spec.partition(":")
    address = parse_address(text.strip())
    size = address.element_size
    if type_text:
        vtype = parse_value_type(type_text)
    elif size == 1:
        vtype = parse_value_type("bit")
    else:
        vtype = parse_value_type("uint16")
    if vtype.kind == "bit" and size != 1 and address.area_code not in WORD_AREAS:
        raise CommandError(f"tag {name!r}: {text} is not a bit address")
    if vtype.kind != "bit" and size == 1:
        raise CommandError(f"tag {name!r}: {text} is a bit; drop the type or use ':bit'")
    if vtype.kind != "bit" and address.area_code not in WORD_AREAS:
        raise CommandError(f"tag {name!r}: {text} cannot hold a {vtype} (not a word area)")
    if vtype.kind != "bit":
        try:
            check_span(address, vtype.words)
        except AddressError as exc:
            raise AddressError(f"tag {name!r}: {exc}", end_code=exc.end_code) from None
    return Tag(name, address, vtype, spec)


@dataclass(frozen=True)
class WordRun:
    """One MEMORY AREA READ (0101): ``count`` words of ``area_code`` from ``word``."""

    area_code: int
    word: int
    count: int

    def __str__(self) -> str:
        return f"0101 area {self.area_code:02X} words {self.word}..{self.word + self.count - 1}"


@dataclass(frozen=True)
class ReadPlan:
    """The frames of one scan. ``runs`` are 0101 frames; ``multiple`` holds 0104 frames."""

    tags: tuple[Tag, ...]
    runs: tuple[WordRun, ...]
    multiple: tuple[tuple[MemoryAddress, ...], ...]
    #: Work done once per plan (the decoder; the client's requests), built on first use.
    cache: dict[str, Any] = field(
        default_factory=dict, init=False, repr=False, compare=False, hash=False
    )

    @property
    def frame_count(self) -> int:
        return len(self.runs) + len(self.multiple)

    def scan_commands(
        self,
    ) -> tuple[list[tuple[int, int, bytes]], list[MultipleMemoryAreaRead]]:
        """The commands ``(mrc, src, parameters)`` of one pipelined scan (its 0101 runs,
        then its 0104 frames) and its 0104 requests, built once per plan."""
        built: tuple[list[tuple[int, int, bytes]], list[MultipleMemoryAreaRead]] | None
        built = self.cache.get("scan")
        if built is None:
            multiple = [MultipleMemoryAreaRead(addresses=addresses) for addresses in self.multiple]
            commands = [self.run_read(i)[:3] for i in range(len(self.runs))]
            commands += [(m.MRC, m.SRC, m.encode()) for m in multiple]
            built = self.cache["scan"] = (commands, multiple)
        return built

    def run_read(self, i: int) -> tuple[int, int, bytes, MemoryAreaRead, Any]:
        """The 0101 command of run ``i`` (MRC, SRC, parameters, request, unpacker of its
        words), built once per plan."""
        reads: list[Any] | None = self.cache.get("reads")
        if reads is None:
            reads = self.cache["reads"] = [None] * len(self.runs)
        read = reads[i]
        if read is None:
            r = self.runs[i]
            new = MemoryAreaRead(MemoryAddress(r.area_code, r.word, 0), r.count)
            unpack = struct.Struct(f">{r.count}H").unpack if new.element_size == 2 else None
            read = reads[i] = (new.MRC, new.SRC, new.encode(), new, unpack)
        return read  # type: ignore[no-any-return]

    def run_words(self, i: int, data: bytes) -> Sequence[int]:
        """The words of run ``i`` from its reply's data, unpacked in one step (data of the
        wrong size raises :class:`DecodeError` saying so)."""
        _, _, _, request, unpack = self.run_read(i)
        if unpack is None or len(data) != 2 * request.count:
            values: tuple[int, ...] = request.decode_response(data).values
            return values
        words: tuple[int, ...] = unpack(data)
        return words

    def describe(self) -> list[str]:
        lines = [str(run) for run in self.runs]
        for frame in self.multiple:
            lines.append("0104 " + ", ".join(f"{a.area_code:02X}:{a.word}.{a.bit}" for a in frame))
        return lines

    def decode(
        self,
        run_words: Sequence[Sequence[int]],
        multiple_values: Sequence[Sequence[int]],
        errors: dict[str, str] | None = None,
    ) -> dict[str, Value]:
        """Values by tag name from each frame's results, in plan order.

        A tag whose words are not a value of its type (invalid BCD, a string not in its
        encoding) raises :class:`DecodeError` naming it, or, given ``errors``, is left out and
        ``errors[name]`` says why (the other tags are decoded all the same).
        """
        decoder: _Decoder | None = self.cache.get("decoder")
        if decoder is None:
            decoder = self.cache["decoder"] = self._compile_decoder()
        steps, lengths, one_frame, bulk = decoder
        flat = self._flat(run_words, multiple_values, one_frame, lengths)
        if bulk is not None:
            template, pack, unpack, names, bits, rest = bulk
            try:
                numbers = unpack(pack(*flat))
            except struct.error:  # a word out of range (not from a reply): tag by tag below
                pass
            else:
                out = template.copy()  # every name, in the tag list's order
                out.update(zip(names, numbers, strict=True))
                for name, at, mask in bits:
                    out[name] = flat[at] & mask != 0
                return self._run_steps(out, rest, flat, errors, True) if rest else out
        return self._run_steps({}, steps, flat, errors, False)

    @property
    def tag_names(self) -> TagNames:
        """The tags' names in the tag list's order, with each one's position (made once per
        plan, shared by the values of every scan: see :meth:`decode_values`)."""
        names: TagNames | None = self.cache.get("names")
        if names is None:
            names = self.cache["names"] = TagNames(tuple(tag.name for tag in self.tags))
        return names

    def decode_values(
        self, run_words: Sequence[Sequence[int]], multiple_values: Sequence[Sequence[int]]
    ) -> tuple[Value, ...] | None:
        """The tags' values in :attr:`tag_names` order, without a dict, when every tag of the
        plan is decoded in bulk (numbers in Omron's word order, plain words, bits) and every
        word is in range; else ``None``: then :meth:`decode` says what each tag holds (or
        why it holds none). Results of the wrong length raise :class:`DecodeError`."""
        fast: _Values | None = self.cache.get("values")
        if fast is None:
            fast = self.cache["values"] = self._compile_values()
        if not fast:
            return None
        one_frame, lengths, pack, unpack, bit_words, masks, order = fast
        flat = self._flat(run_words, multiple_values, one_frame, lengths)
        try:
            numbers: tuple[Value, ...] = unpack(pack(*flat))
        except struct.error:  # a word out of range (not from a reply): decode() says which
            return None
        if masks:  # each bit: its word & its mask, as a bool (no Python loop)
            numbers += tuple(map(truth, map(and_, bit_words(flat), masks)))
        return numbers if order is None else order(numbers)

    def frame_decoder(self) -> Callable[[bytes], tuple[Value, ...] | None] | None:
        """For a plan of one 0101 frame whose tags all decode in bulk: a function from a
        normal reply frame (header, command and end code, then the words) straight to the
        values :meth:`decode_values` gives, or ``None`` where that would (and for a frame
        of the wrong size: then :meth:`decode` says why). ``None`` for other plans. Built
        once per plan: a scan of the Poller decodes its reply in one call."""
        built: Callable[[bytes], tuple[Value, ...] | None] | tuple[()] | None
        built = self.cache.get("frame")
        if built is None:
            built = self.cache["frame"] = self._compile_frame_decoder()
        return built or None

    def _compile_frame_decoder(self) -> Callable[[bytes], tuple[Value, ...] | None] | tuple[()]:
        fast: _Values | None = self.cache.get("values")
        if fast is None:
            fast = self.cache["values"] = self._compile_values()
        if not fast or not fast[0] or self.run_read(0)[4] is None:
            return ()
        count, _, pack, unpack, bit_words, masks, order = fast
        words = struct.Struct(f">{count}H").unpack_from
        size = MIN_REPLY_SIZE + 2 * count

        def decode(frame: bytes) -> tuple[Value, ...] | None:
            if len(frame) != size:
                return None
            flat = words(frame, MIN_REPLY_SIZE)
            try:
                numbers: tuple[Value, ...] = unpack(pack(*flat))
            except struct.error:
                return None
            if masks:
                numbers += tuple(map(truth, map(and_, bit_words(flat), masks)))
            return numbers if order is None else order(numbers)

        return decode

    def _compile_values(self) -> _Values:
        """What :meth:`decode_values` needs: the frames' lengths as :meth:`decode` checks
        them, the bulk decoder's pack and unpack, the bits' words (a getter of the flat
        words) and masks, and the reordering of (numbers + bits) into tag order (``None``:
        already in it); ``()`` if some tag is not decoded in bulk."""
        decoder: _Decoder | None = self.cache.get("decoder")
        if decoder is None:
            decoder = self.cache["decoder"] = self._compile_decoder()
        bulk = decoder[3]
        if bulk is None or bulk[5]:
            return ()
        _, pack, unpack, names, bits, _ = bulk
        position = {name: i for i, name in enumerate((*names, *(b[0] for b in bits)))}
        order = _getter([position[tag.name] for tag in self.tags], every=True)
        bit_words = _getter([at for _, at, _ in bits]) or _no_items
        return (
            decoder[2],
            decoder[1],
            pack,
            unpack,
            bit_words,
            tuple(mask for _, _, mask in bits),
            order,
        )

    def _compile_decoder(self) -> _Decoder:
        steps = _compile_steps(self)
        lengths = (
            tuple(run.count for run in self.runs),
            tuple(len(frame) for frame in self.multiple),
        )
        one_frame = self.runs[0].count if len(self.runs) == 1 and not self.multiple else 0
        bulk = _compile_bulk(steps, sum(lengths[0]) + sum(lengths[1]))
        return steps, lengths, one_frame, bulk

    def _run_steps(
        self,
        out: dict[str, Value],
        steps: list[_Step],
        flat: Sequence[int],
        errors: dict[str, str] | None,
        listed: bool,
    ) -> dict[str, Value]:
        """Decode the tags of ``steps`` into ``out`` (``listed``: ``out`` has a key for each
        already, which a tag that is no value of its type gives up)."""
        for name, op, at, arg in steps:
            if op is _BIT:
                out[name] = bool((flat[at] >> arg) & 1)
            elif op is _UINT16:
                word = flat[at]
                out[name] = word if 0 <= word <= 0xFFFF else arg.decode([word])
            elif op is _NUMBER:
                try:
                    if len(at) == 2:  # 32-bit values: no list
                        out[name] = arg[1](arg[0](flat[at[0]], flat[at[1]]))[0]
                    else:
                        out[name] = arg[1](arg[0](*[flat[i] for i in at]))[0]
                except struct.error:  # a word out of range: let the type say so
                    out[name] = arg[2].decode([flat[i] for i in arg[3]])
            elif op is _FLAG:
                out[name] = bool(flat[at] & 1)
            else:
                try:  # BCD and strings: words that are no value of the type
                    out[name] = arg.decode([flat[i] for i in at])
                except DecodeError as exc:
                    message = f"tag {name!r} ({self._text_of(name)}): {exc}"
                    if errors is None:
                        raise DecodeError(message) from None
                    errors[name] = message
                    if listed:
                        del out[name]
        return out

    def _flat(
        self,
        run_words: Sequence[Sequence[int]],
        multiple_values: Sequence[Sequence[int]],
        one_frame: int,
        lengths: tuple[tuple[int, ...], tuple[int, ...]],
    ) -> Sequence[int]:
        """The words of a scan's frames in plan order. Every scan decodes here: the frames'
        lengths are compared with the plan's in one step, each frame checked only to say
        which one is wrong (:class:`DecodeError`). ``one_frame``: the words of a plan of one
        0101 frame (indexed as they are), else 0."""
        if one_frame:
            if len(run_words) != 1 or multiple_values or len(run_words[0]) != one_frame:
                raise self._length_error(run_words, multiple_values)
            return run_words[0]
        if (tuple(map(len, run_words)), tuple(map(len, multiple_values))) != lengths:
            raise self._length_error(run_words, multiple_values)
        return list(chain(chain.from_iterable(run_words), chain.from_iterable(multiple_values)))

    def _length_error(
        self, run_words: Sequence[Sequence[int]], multiple_values: Sequence[Sequence[int]]
    ) -> DecodeError:
        """Which frame's result has the wrong length (:meth:`decode` found one)."""
        if len(run_words) != len(self.runs) or len(multiple_values) != len(self.multiple):
            return DecodeError("results do not match the plan's frames")
        for run, values in zip(self.runs, run_words, strict=True):
            if len(values) != run.count:
                return DecodeError(f"{run}: expected {run.count} words, got {len(values)}")
        return DecodeError("0104 result has the wrong number of elements")

    def _text_of(self, name: str) -> str:
        return next((tag.text for tag in self.tags if tag.name == name), "?")


class TagNames:
    """A plan's tag names in order and each one's position: shared by every snapshot of
    the plan, whose values are a tuple in that order."""

    __slots__ = ("index", "names")

    def __init__(self, names: tuple[str, ...]) -> None:
        self.names = names
        self.index = {name: i for i, name in enumerate(names)}


#: Picks items of a sequence by position, as a tuple.
_Getter = Callable[[Sequence[Any]], tuple[Any, ...]]

#: A plan's tuple decoder (see ReadPlan._compile_values), or () if it has none.
_Values = (
    tuple[
        int,
        tuple[tuple[int, ...], tuple[int, ...]],
        Callable[..., bytes],
        Callable[[bytes], tuple[Any, ...]],
        _Getter,
        tuple[int, ...],
        "_Getter | None",
    ]
    | tuple[()]
)


def _no_items(items: Sequence[Any]) -> tuple[Any, ...]:
    return ()


def _getter(positions: list[int], every: bool = False) -> _Getter | None:
    """The items at ``positions`` as a tuple, in one C call; ``None`` for no positions
    (and, given ``every``, for all the items in order, which need no getter)."""
    if not positions or (every and positions == list(range(len(positions)))):
        return None
    if len(positions) == 1:
        only = positions[0]

        def one(items: Sequence[Any]) -> tuple[Any, ...]:
            return (items[only],)

        return one
    return itemgetter(*positions)


# Decoding steps: (tag name, op, index or indices into the flat results, argument).
_BIT, _FLAG, _UINT16, _NUMBER, _OTHER = "bit", "flag", "uint16", "number", "other"
_Step = tuple[str, str, Any, Any]


def _compile_steps(plan: ReadPlan) -> list[_Step]:
    """Where each tag's words sit in the flat results, and how to decode them.

    A word comes from the last 0101 run holding it, else from the last 0104 element naming
    it. A plan with a tag whose word is in no frame (built by hand) raises DecodeError.
    """
    index: dict[tuple[int, int], int] = {}
    at = 0
    for run in plan.runs:
        for i in range(run.count):
            index[(run.area_code, run.word + i)] = at + i
        at += run.count
    elements: dict[MemoryAddress, int] = {}
    for frame in plan.multiple:
        for address in frame:
            elements[address] = at
            at += 1

    def word_at(area: int, word: int) -> int | None:
        got = index.get((area, word))
        return got if got is not None else elements.get(MemoryAddress(area, word, 0))

    steps: list[_Step] = []
    for tag in plan.tags:
        area, vtype = tag.word_area, tag.vtype
        if area is None:
            flag = elements.get(tag.address)
            if flag is None:
                raise _not_in_plan(tag, tag.address.word)
            steps.append((tag.name, _FLAG, flag, None))
            continue
        spots = [word_at(area, tag.address.word + i) for i in range(tag.width)]
        if None in spots:
            raise _not_in_plan(tag, tag.address.word + spots.index(None))
        where = [i for i in spots if i is not None]
        if vtype.kind == "bit":
            steps.append((tag.name, _BIT, where[0], tag.address.bit))
        elif vtype.kind == "uint16" and vtype.word_order in _UNSWAPPED:
            steps.append((tag.name, _UINT16, where[0], vtype))
        elif vtype.kind in NUMBER_CODES:
            codec = (*_codec(vtype), tuple(where))
            steps.append((tag.name, _NUMBER, tuple(_value_order(where, vtype)), codec))
        else:
            steps.append((tag.name, _OTHER, tuple(where), vtype))
    return steps


_UNSWAPPED = (WordOrder.LOW_FIRST, WordOrder.HIGH_FIRST)

#: The numbers of a plan decoded in two ``struct`` calls: (every tag name, in the tag list's
#: order; the flat words -> their bytes, each word little-endian; those bytes -> the
#: numbers; the numbers' tag names; the bits as (name, word's index, mask); the steps left
#: for the other tags).
_Bulk = tuple[
    dict[str, Value], Callable[..., bytes], Callable[[bytes], tuple[Any, ...]], tuple[str, ...],
    tuple[tuple[str, int, int], ...], list[_Step],
]  # fmt: skip


#: A plan's decoder: its steps, its frames' lengths (0101 runs, 0104 frames), the words of
#: its one 0101 frame (0 if it has other frames) and its bulk decoder.
_Decoder = tuple[list[_Step], tuple[tuple[int, ...], tuple[int, ...]], int, "_Bulk | None"]


def _compile_bulk(steps: list[_Step], words: int) -> _Bulk | None:
    """The bulk decoder of ``steps`` over ``words`` flat words, or None if it would decode
    no tag.

    Written little-endian word by word, the words of a value in Omron's order (least
    significant word first, each word big-endian) are that value's little-endian bytes: one
    ``struct`` format reads every such number (and every plain 16-bit word) of the plan,
    pad bytes between them; bits are masks of their words. Numbers in the other word
    orders, tags sharing words with an earlier one, BCD and strings keep their own step.
    """
    spans: list[tuple[int, int, str, str]] = []  # (first word, words, struct code, tag)
    bits: list[tuple[str, int, int]] = []
    rest: list[_Step] = []
    for step in steps:
        name, op, at, arg = step
        if op is _BIT:
            bits.append((name, at, 1 << arg))
            continue
        if op is _UINT16:
            spans.append((at, 1, "H", name))
            continue
        if op is _NUMBER:
            vtype: ValueType = arg[2]
            where: tuple[int, ...] = arg[3]
            plain = vtype.word_order is WordOrder.LOW_FIRST or (
                vtype.words == 1 and vtype.word_order in _UNSWAPPED
            )
            if plain and where == tuple(range(where[0], where[0] + len(where))):
                spans.append((where[0], len(where), NUMBER_CODES[vtype.kind], name))
                continue
        rest.append(step)
    fmt, names, cursor = ["<"], [], 0
    for first, count, code, name in sorted(spans):
        if first < cursor:  # overlaps the last one read in bulk: its own step
            rest.append(next(step for step in steps if step[0] == name))
            continue
        fmt.append("x" * (2 * (first - cursor)) + code)
        names.append(name)
        cursor = first + count
    if not names and not bits:
        return None
    template: dict[str, Value] = dict.fromkeys((step[0] for step in steps), 0)
    pack = struct.Struct(f"<{words}H").pack
    unpack = struct.Struct("".join(fmt)).unpack_from
    order = {step[0]: i for i, step in enumerate(steps)}
    rest.sort(key=lambda step: order[step[0]])
    return template, pack, unpack, tuple(names), tuple(bits), rest


def _not_in_plan(tag: Tag, word: int) -> DecodeError:
    return DecodeError(
        f"tag {tag.name!r} ({tag.address}): word {word} is in none of the plan's frames"
    )


def _value_order(spots: list[int], vtype: ValueType) -> list[int]:
    """The word positions in value order (most significant first)."""
    low_first = vtype.word_order in (WordOrder.LOW_FIRST, WordOrder.LOW_FIRST_SWAPPED)
    return spots[::-1] if low_first else spots


def _codec(
    vtype: ValueType,
) -> tuple[Callable[..., bytes], Callable[[bytes], tuple[Any, ...]], ValueType]:
    """Pack words (in value order) into the value's bytes, unpack those into the value.

    (Then the type itself, and the words in memory order, to report a word out of range.)
    """
    n = vtype.words
    swapped = vtype.word_order not in _UNSWAPPED  # bytes swapped inside each word
    pack = struct.Struct(f"{'<' if swapped else '>'}{n}H").pack
    unpack = struct.Struct(">" + NUMBER_CODES[vtype.kind]).unpack
    return pack, unpack, vtype


def compile_tags(
    tags: Mapping[str, str] | Sequence[Tag],
    *,
    max_read_words: int = 999,
    max_multiple_elements: int = 167,
    max_gap: int = 8,
) -> ReadPlan:
    """Compile tags into the fewest frames under the given limits.

    Runs of words closer than ``max_gap`` unused words are read together by 0101; then runs are
    moved to 0104 (shortest first) while that lowers the frame count.
    """
    if max_read_words < 1 or max_multiple_elements < 1 or max_gap < 0:
        raise CommandError("limits must be positive and max_gap not negative")
    parsed = (
        tuple(parse_tag(name, spec) for name, spec in tags.items())
        if isinstance(tags, Mapping)
        else tuple(tags)
    )
    names = [t.name for t in parsed]
    if len(set(names)) != len(names):
        raise CommandError("tag names must be unique")
    needed: dict[int, set[int]] = {}
    flags: list[MemoryAddress] = []
    for tag in parsed:
        area = tag.word_area
        if area is None:
            if tag.address not in flags:
                flags.append(tag.address)
            continue
        width = tag.width
        if width > max_read_words:
            raise CommandError(f"tag {tag.name!r} needs {width} words, over {max_read_words}")
        needed.setdefault(area, set()).update(range(tag.address.word, tag.address.word + width))

    runs: list[WordRun] = []
    for area in sorted(needed):
        runs.extend(_coalesce(area, sorted(needed[area]), max_read_words, max_gap))

    # Move the shortest runs into 0104 frames while that saves frames.
    runs.sort(key=lambda r: (r.count, r.area_code, r.word))
    best_k, best_frames = 0, len(runs) + math.ceil(len(flags) / max_multiple_elements)
    moved = len(flags)
    for k, run in enumerate(runs, start=1):
        moved += _used_words(run, needed)
        frames = len(runs) - k + math.ceil(moved / max_multiple_elements)
        if frames < best_frames:
            best_k, best_frames = k, frames
    elements = list(flags)
    for run in runs[:best_k]:
        elements.extend(
            MemoryAddress(run.area_code, w, 0)
            for w in range(run.word, run.word + run.count)
            if w in needed[run.area_code]
        )
    kept = sorted(runs[best_k:], key=lambda r: (r.area_code, r.word))
    multiple = tuple(tuple(frame) for frame in plan_multiple(elements, max_multiple_elements))
    return ReadPlan(parsed, tuple(kept), multiple)


def _used_words(run: WordRun, needed: dict[int, set[int]]) -> int:
    used = needed[run.area_code]
    return sum(1 for w in range(run.word, run.word + run.count) if w in used)


def _coalesce(area: int, words: list[int], max_words: int, max_gap: int) -> list[WordRun]:
    runs: list[WordRun] = []
    start = prev = words[0]
    for w in words[1:]:
        if w - prev - 1 <= max_gap and w - start + 1 <= max_words:
            prev = w
            continue
        runs.append(WordRun(area, start, prev - start + 1))
        start = prev = w
    runs.append(WordRun(area, start, prev - start + 1))
    return runs
