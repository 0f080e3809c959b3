"""The CS/CJ I/O memory of the virtual PLC (manual 5-2-2).

Every area is stored once as 16-bit words (or flag bytes); bit, word and forced-status area
codes are views of the same storage, so a bit written through ``30`` is seen through ``B0``.
Errors raise :class:`CommandFailed` with the end code a CPU Unit answers: ``1101`` area code
not usable, ``1103`` start address out of range, ``1104`` end beyond the area, ``2101``
write to the read-only part of the Auxiliary Area (A0-A447).
"""

from __future__ import annotations

import sys
import time
from array import array
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import Enum

from ..protocol.areas import AreaSpec, DataType, area_codes, area_specs
from .state import (
    ADDRESS_RANGE_ERROR,
    ADDRESS_RANGE_EXCEEDED,
    AREA_MISSING,
    PARAMETER_ERROR,
    READ_ONLY,
    CommandFailed,
)


class Kind(Enum):
    """How the simulator stores and encodes the elements of an area code."""

    BIT = "bit"  # 1 byte 00/01, view of a word store
    BIT_FORCED = "bit+forced"  # 1 byte: bit 0 value, bit 1 forced
    WORD = "word"  # 2 bytes
    WORD_FORCED = "word+forced"  # 4 bytes: forced mask word, value word
    FLAG = "flag"  # T/C completion flag, 1 byte
    FLAG_FORCED = "flag+forced"
    PV = "pv"  # T/C present value, 2 bytes
    TASK = "task"  # 06 task flag, 1 byte
    TASK_STATUS = "task status"  # 46, 1 byte
    SYSTEM = "system"  # 07 clock pulses and condition flags, 1 byte
    REGISTER = "register"  # BC: data registers and current EM bank number, 2 bytes
    INDEX = "index"  # DC: index registers, 4 bytes


# Segments of an area code: (first word, number of elements, index of the first element).
_Segments = tuple[tuple[int, int, int], ...]


@dataclass(frozen=True, slots=True)
class Area:
    """What an area code designates: its rows of manual 5-2-2 seen as one store.

    ``kind`` and ``store`` (``"CIO"``, ``"D"``, ``"E3"``, ``"E*"`` for the current bank,
    ``"TC"``...) are the simulator's; ``element_size``, ``segments`` (adjacent rows merged)
    and ``read_only`` (word ranges) come from :data:`aiofins.protocol.areas.AREAS`.
    """

    code: int
    kind: Kind
    store: str
    element_size: int
    segments: _Segments
    read_only: tuple[tuple[int, int], ...] = ()

    @property
    def is_bit(self) -> bool:
        return self.kind in (Kind.BIT, Kind.BIT_FORCED)

    @property
    def elements(self) -> int:
        """Number of elements (words, flags, registers) over all segments."""
        return sum(n for _, n, _ in self.segments)

    def index(self, word: int) -> int:
        """Element index of ``word``; :class:`KeyError` if no segment holds it."""
        for first, n, index in self.segments:
            if first <= word < first + n:
                return index + word - first
        raise KeyError(word)


_KIND_OF_TYPE = {
    DataType.BIT: Kind.BIT,
    DataType.BIT_FORCED: Kind.BIT_FORCED,
    DataType.WORD: Kind.WORD,
    DataType.WORD_FORCED: Kind.WORD_FORCED,
    DataType.COMPLETION_FLAG: Kind.FLAG,
    DataType.COMPLETION_FLAG_FORCED: Kind.FLAG_FORCED,
    DataType.PV: Kind.PV,
    DataType.TASK_FLAG: Kind.TASK,
    DataType.TASK_STATUS: Kind.TASK_STATUS,
    DataType.BANK_NUMBER: Kind.REGISTER,
    DataType.FLAG: Kind.SYSTEM,
}
#: Stores whose values are registers rather than T/C present values.
_KIND_OF_STORE = {"DR": Kind.REGISTER, "IR": Kind.INDEX}
#: Text prefixes of manual 5-2-2 that share one store (timers and counters; DR and bank No.).
_STORE_OF_AREA = {"E": "E*", "T": "TC", "C": "TC", "EMBANK": "DR"}


def _store_of(spec: AreaSpec) -> str:
    if spec.bank is not None:
        return f"E{spec.bank}"
    if spec.data_type is DataType.FLAG:
        return "SYS"
    return _STORE_OF_AREA.get(spec.area, spec.area)


def _merged(specs: Sequence[AreaSpec]) -> _Segments:
    runs: list[tuple[int, int]] = []
    for spec in sorted(specs, key=lambda s: s.first_word):
        if runs and sum(runs[-1]) == spec.first_word:
            runs[-1] = (runs[-1][0], runs[-1][1] + spec.count)
        else:
            runs.append((spec.first_word, spec.count))
    segments: list[tuple[int, int, int]] = []
    index = 0
    for first, n in runs:
        segments.append((first, n, index))
        index += n
    return tuple(segments)


def _area(code: int) -> Area:
    specs = area_specs(code)
    stores = {_store_of(s) for s in specs}
    kinds = {_KIND_OF_STORE.get(_store_of(s), _KIND_OF_TYPE[s.data_type]) for s in specs}
    sizes = {s.element_size for s in specs}
    if len(stores) != 1 or len(kinds) != 1 or len(sizes) != 1:
        raise ValueError(f"area code {code:02X}: rows of manual 5-2-2 disagree: {specs}")
    read_only = tuple((s.first_word, s.last_word) for s in specs if s.read_only)
    return Area(code, kinds.pop(), stores.pop(), sizes.pop(), _merged(specs), read_only)


#: Every CS/CJ area code of :mod:`aiofins.protocol.areas`, as the simulator stores it.
AREAS: dict[int, Area] = {code: _area(code) for code in sorted(area_codes())}

_EM_WORD_CODES = frozenset(
    c for c, a in AREAS.items() if a.kind is Kind.WORD and a.store[0] == "E" and a.store != "E*"
)
_EM_BIT_CODES = frozenset(
    c for c, a in AREAS.items() if a.kind is Kind.BIT and a.store[0] == "E" and a.store != "E*"
)
#: Area codes accepted by each I/O memory command (manual's per-command area tables).
_BASIC_READ = (0x30, 0x31, 0x32, 0x33, 0xB0, 0xB1, 0xB2, 0xB3, 0x09, 0x89, 0x02, 0x82, 0x0A)
READ_AREAS = (
    frozenset((*_BASIC_READ, 0x98, 0xBC, 0x06, 0x46, 0xDC, 0x07)) | _EM_WORD_CODES | _EM_BIT_CODES
)
WRITE_AREAS = (
    frozenset((0x30, 0x31, 0x32, 0x33, 0xB0, 0xB1, 0xB2, 0xB3, 0x89, 0x02, 0x82, 0x0A, 0x98))
    | frozenset((0xDC, 0xBC))
    | _EM_WORD_CODES
    | _EM_BIT_CODES
)
FILL_AREAS = frozenset((0xB0, 0xB1, 0xB2, 0xB3, 0x89, 0x82, 0x98)) | _EM_WORD_CODES
TRANSFER_AREAS = FILL_AREAS
MULTIPLE_READ_AREAS = READ_AREAS | frozenset((0x70, 0x71, 0x72, 0xF0, 0xF1, 0xF2, 0x49))
#: 2301: relay areas (CIO, W, H bits) and timer/counter completion flags (manual 5-3-45).
FORCE_AREAS = frozenset((0x30, 0x31, 0x32, 0x09))

#: Words of each word store (CIO, W, H, A, D, EM banks), from its word area code.
_STORE_WORDS = {a.store: a.elements for a in AREAS.values() if a.kind is Kind.WORD}
_FORCEABLE = frozenset(a.store for a in AREAS.values() if a.kind is Kind.WORD_FORCED)
EM_BANK_WORDS = _STORE_WORDS["E0"]
_TC = AREAS[0x89]
TIMER_COUNTER_COUNT = _TC.segments[1][2]  # counters follow the timers in the T/C store
_BANK_NUMBER_WORD = next(
    s.first_word for s in area_specs(0xBC) if s.data_type is DataType.BANK_NUMBER
)
_CURRENT_BANK_INDEX = AREAS[0xBC].index(_BANK_NUMBER_WORD)
#: Area 07 elements in index order, by the short names of :data:`aiofins.protocol.areas.FLAGS`.
_SYSTEM_NAMES = tuple(s.area for s in sorted(area_specs(0x07), key=lambda s: s.first_word))
_SYSTEM_INDEX = {name: i for i, name in enumerate(_SYSTEM_NAMES)}
#: Clock pulses (simulated: ON for the first half of each period) and constant flags.
_CLOCK_PULSE_PERIODS = {"P_1min": 60.0, "P_1s": 1.0, "P_0_2s": 0.2, "P_0_1s": 0.1, "P_0_02s": 0.02}
_CONSTANT_FLAGS = {"P_Off": 0, "P_On": 1}
#: Area 07 flags that :meth:`IOMemory.set_condition_flag` may set (not pulses or constants).
SETTABLE_FLAGS = frozenset(_SYSTEM_NAMES) - set(_CLOCK_PULSE_PERIODS) - set(_CONSTANT_FLAGS)


def _words(n: int) -> array[int]:
    return array("H", bytes(2 * n))


class IOMemory:
    """CIO, W, H, A, T/C, DM, EM banks, task flags, IR/DR, system flags and forced status."""

    def __init__(self, *, em_banks: int = 25, clock: Callable[[], float] = time.time) -> None:
        if not 0 <= em_banks <= 25:
            raise ValueError(f"em_banks {em_banks} out of range 0..25")
        self.em_banks = em_banks
        self._clock = clock
        self._stores: dict[str, array[int]] = {
            k: _words(n) for k, n in _STORE_WORDS.items() if k[0] != "E"
        }
        for bank in range(em_banks):
            self._stores[f"E{bank}"] = _words(EM_BANK_WORDS)
        self._forced: dict[str, array[int]] = {k: _words(_STORE_WORDS[k]) for k in _FORCEABLE}
        self.pv = _words(_TC.elements)
        self.completion = bytearray(_TC.elements)
        self.completion_forced = bytearray(_TC.elements)
        self.task_flags = bytearray(AREAS[0x06].elements)
        self.task_status = bytearray(AREAS[0x46].elements)
        self.condition_flags = bytearray(len(_SYSTEM_NAMES))  # area 07, by element index
        self.data_registers = _words(AREAS[0xBC].elements)  # the bank number's entry unused
        self.index_registers = [0] * AREAS[0xDC].elements
        self.current_bank = 0

    # ---- location -------------------------------------------------------------------------

    def area(self, code: int, allowed: frozenset[int] | None = None) -> Area:
        """The area of ``code``; ``1101`` if unknown, not allowed or an absent EM bank."""
        area = AREAS.get(code)
        if area is None or (allowed is not None and code not in allowed):
            raise CommandFailed(AREA_MISSING, message=f"area code {code:02X} not usable here")
        if area.store[0] == "E":
            bank = self.current_bank if area.store == "E*" else int(area.store[1:])
            if bank >= self.em_banks:
                raise CommandFailed(AREA_MISSING, message=f"EM bank {bank} absent")
        return area

    def locate(self, area: Area, word: int, bit: int, count: int) -> int:
        """Index of the first element; ``1103`` bad start, ``1104`` end past the area."""
        for first, n, index in area.segments:
            if first <= word < first + n:
                if area.is_bit:
                    if bit > 15:
                        raise CommandFailed(ADDRESS_RANGE_ERROR, message=f"bit {bit} > 15")
                    start = (word - first) * 16 + bit
                    if start + count > n * 16:
                        raise CommandFailed(ADDRESS_RANGE_EXCEEDED)
                    return index * 16 + start
                if bit != 0:
                    raise CommandFailed(ADDRESS_RANGE_ERROR, message="bit must be 00")
                if word - first + count > n:
                    raise CommandFailed(ADDRESS_RANGE_EXCEEDED)
                return index + word - first
        raise CommandFailed(ADDRESS_RANGE_ERROR, message=f"word {word:04X} outside the area")

    def _store(self, area: Area) -> array[int]:
        if area.store == "E*":
            return self._stores[f"E{self.current_bank}"]
        return self._stores[area.store]

    # ---- element access (raw, after locate) -----------------------------------------------

    def _get(self, area: Area, i: int) -> int:
        k = area.kind
        if k in (Kind.BIT, Kind.BIT_FORCED):
            value = (self._store(area)[i >> 4] >> (i & 15)) & 1
            if k is Kind.BIT_FORCED:
                value |= ((self._forced[area.store][i >> 4] >> (i & 15)) & 1) << 1
            return value
        if k is Kind.WORD:
            return self._store(area)[i]
        if k is Kind.WORD_FORCED:
            return (self._forced[area.store][i] << 16) | self._store(area)[i]
        if k is Kind.FLAG:
            return self.completion[i]
        if k is Kind.FLAG_FORCED:
            return self.completion[i] | (self.completion_forced[i] << 1)
        if k is Kind.PV:
            return self.pv[i]
        if k is Kind.TASK:
            return self.task_flags[i]
        if k is Kind.TASK_STATUS:
            return self.task_status[i]
        if k is Kind.SYSTEM:
            return self._system_flag(i)
        if k is Kind.REGISTER:
            return self.current_bank if i == _CURRENT_BANK_INDEX else self.data_registers[i]
        return self.index_registers[i]

    def _system_flag(self, i: int) -> int:
        name = _SYSTEM_NAMES[i]
        period = _CLOCK_PULSE_PERIODS.get(name)
        if period is not None:
            return int((self._clock() % period) < period / 2)
        return _CONSTANT_FLAGS.get(name, self.condition_flags[i])

    def set_condition_flag(self, name: str, value: bool) -> None:
        """Set an area 07 flag by its short name (``P_CY``, ``P_AER``...), as the CPU would."""
        if name not in SETTABLE_FLAGS:
            raise ValueError(f"{name!r} is not a settable area 07 flag")
        self.condition_flags[_SYSTEM_INDEX[name]] = int(value)

    def _set(self, area: Area, i: int, value: int) -> None:
        k = area.kind
        if k is Kind.BIT:
            store = self._store(area)
            mask = 1 << (i & 15)
            if area.store in _FORCEABLE and self._forced[area.store][i >> 4] & mask:
                return  # a forced bit keeps its forced state
            store[i >> 4] = (store[i >> 4] | mask) if value else (store[i >> 4] & ~mask)
        elif k is Kind.WORD:
            store = self._store(area)
            if area.store in _FORCEABLE:
                fmask = self._forced[area.store][i]
                value = (store[i] & fmask) | (value & ~fmask & 0xFFFF)
            store[i] = value
        elif k is Kind.PV:
            self.pv[i] = value
        elif k is Kind.REGISTER:
            if i == _CURRENT_BANK_INDEX:
                if value >= max(self.em_banks, 1):
                    raise CommandFailed(PARAMETER_ERROR, message=f"EM bank {value} absent")
                self.current_bank = value
            else:
                self.data_registers[i] = value
        elif k is Kind.INDEX:
            self.index_registers[i] = value
        else:  # pragma: no cover - excluded by the command area tables
            raise CommandFailed(READ_ONLY)

    def _check_writable(self, area: Area, word: int, bit: int, count: int) -> None:
        """``2101`` if the run touches a read-only word (A0-A447)."""
        last = word + (bit + count - 1) // 16 if area.is_bit else word + count - 1
        for first, end in area.read_only:
            if word <= end and first <= last:
                raise CommandFailed(
                    READ_ONLY, message=f"words {first:04X}-{end:04X} hex are read-only"
                )

    # ---- wire-level operations ------------------------------------------------------------

    def read(self, code: int, word: int, bit: int, count: int, allowed: frozenset[int]) -> bytes:
        """Elements encoded as on the wire (0101/0104); count 0 reads nothing."""
        area = self.area(code, allowed)
        start = self.locate(area, word, bit, max(count, 1))
        if area.kind is Kind.WORD:  # fast path: a slice of the store, big-endian
            chunk = self._store(area)[start : start + count]
            if sys.byteorder == "little":
                chunk.byteswap()
            return chunk.tobytes()
        if area.kind is Kind.BIT and count:  # the bits of the words they sit in, at once
            return _bits_of(self._store(area), start, count)
        size = area.element_size
        out = bytearray()
        for i in range(start, start + count):
            out += self._get(area, i).to_bytes(size, "big")
        return bytes(out)

    def write(
        self, code: int, word: int, bit: int, data: bytes, count: int, allowed: frozenset[int]
    ) -> None:
        """Write ``count`` elements from wire bytes (0102); validates everything first."""
        area = self.area(code, allowed)
        start = self.locate(area, word, bit, max(count, 1))
        if count == 0:
            return
        self._check_writable(area, word, bit, count)
        if area.kind is Kind.WORD and not self._any_forced(area, start, count):
            chunk = array("H", data[: 2 * count])  # fast path: one slice assignment
            if sys.byteorder == "little":
                chunk.byteswap()
            self._store(area)[start : start + count] = chunk
            return
        size = area.element_size
        if area.is_bit and max(data[:count]) > 1:
            raise CommandFailed(PARAMETER_ERROR, message="bit data must be 00 or 01")
        if area.kind is Kind.BIT:  # one pass over the words the bits sit in
            forced = self._forced.get(area.store)
            _set_bits(self._store(area), forced, start, data[:count])
            return
        values = [int.from_bytes(data[j * size : (j + 1) * size], "big") for j in range(count)]
        if area.kind is Kind.REGISTER:
            bank_index = _CURRENT_BANK_INDEX - start
            if 0 <= bank_index < count and values[bank_index] >= max(self.em_banks, 1):
                raise CommandFailed(PARAMETER_ERROR, message="EM bank absent")
        for j, v in enumerate(values):
            self._set(area, start + j, v)

    def _any_forced(self, area: Area, start: int, count: int) -> bool:
        forced = self._forced.get(area.store)
        return forced is not None and any(forced[start : start + count])

    def fill(self, code: int, word: int, bit: int, count: int, value: int) -> None:
        """0103: write one word value to ``count`` words (T/C PV fill clears completion)."""
        area = self.area(code, FILL_AREAS)
        start = self.locate(area, word, bit, max(count, 1))
        if count == 0:
            return
        self._check_writable(area, word, bit, count)
        for i in range(start, start + count):
            self._set(area, i, value)
            if area.kind is Kind.PV:
                self.completion[i] = 0

    def transfer(self, src: tuple[int, int, int], dst: tuple[int, int, int], count: int) -> None:
        """0105: copy words; all addresses are checked before anything is written."""
        s_area = self.area(src[0], TRANSFER_AREAS)
        d_area = self.area(dst[0], TRANSFER_AREAS)
        s = self.locate(s_area, src[1], src[2], max(count, 1))
        d = self.locate(d_area, dst[1], dst[2], max(count, 1))
        if count == 0:
            return
        self._check_writable(d_area, dst[1], dst[2], count)
        values = [self._get(s_area, i) for i in range(s, s + count)]
        for j, v in enumerate(values):
            self._set(d_area, d + j, v)

    # ---- typed helpers (tests, servers, CLI) -----------------------------------------------

    def read_words(self, code: int, word: int, count: int) -> list[int]:
        area = self.area(code)
        start = self.locate(area, word, 0, max(count, 1))
        if area.kind is Kind.WORD:
            return self._store(area)[start : start + count].tolist()
        return [self._get(area, i) for i in range(start, start + count)]

    def write_words(self, code: int, word: int, values: Sequence[int]) -> None:
        """Write words without the FINS read-only check (the PLC's own program may)."""
        area = self.area(code)
        start = self.locate(area, word, 0, max(len(values), 1))
        for j, v in enumerate(values):
            self._set(area, start + j, v & 0xFFFF if area.element_size == 2 else v)

    def read_bits(self, code: int, word: int, bit: int, count: int) -> list[bool]:
        area = self.area(code)
        start = self.locate(area, word, bit, max(count, 1))
        if area.kind is Kind.BIT and count:
            return [b == 1 for b in _bits_of(self._store(area), start, count)]
        return [bool(self._get(area, i) & 1) for i in range(start, start + count)]

    def write_bits(self, code: int, word: int, bit: int, values: Sequence[bool]) -> None:
        area = self.area(code)
        start = self.locate(area, word, bit, max(len(values), 1))
        for j, v in enumerate(values):
            self._set(area, start + j, int(v))

    def set_completion(self, number: int, value: bool, *, counter: bool = False) -> None:
        """Set a timer (or counter) completion flag, as the PLC program would."""
        self.completion[number + (TIMER_COUNTER_COUNT if counter else 0)] = int(value)

    # ---- forced set/reset (2301/2302) -----------------------------------------------------

    def force(self, code: int, word: int, bit: int, spec: int) -> None:
        """Apply one 2301 entry: 0000 force OFF, 0001 force ON, 8000/8001 release to OFF/ON,
        FFFF release keeping the state."""
        area = self.area(code, FORCE_AREAS)
        i = self.locate(area, word, bit, 1)
        if spec not in (0x0000, 0x0001, 0x8000, 0x8001, 0xFFFF):
            raise CommandFailed(PARAMETER_ERROR, message=f"set/reset spec {spec:04X}")
        forced = spec in (0x0000, 0x0001)
        if area.kind is Kind.FLAG:
            self.completion_forced[i] = int(forced)
            if spec != 0xFFFF:
                self.completion[i] = spec & 1
            return
        fstore = self._forced[area.store]
        mask = 1 << (i & 15)
        fstore[i >> 4] &= ~mask & 0xFFFF
        if spec != 0xFFFF:
            self._set(area, i, spec & 1)
        if forced:
            fstore[i >> 4] |= mask

    def cancel_forces(self) -> None:
        """2302: release every forced bit, keeping its present state."""
        for fstore in self._forced.values():
            for i in range(len(fstore)):
                fstore[i] = 0
        for i in range(len(self.completion_forced)):
            self.completion_forced[i] = 0

    def forced_count(self) -> int:
        n = sum(bin(w).count("1") for f in self._forced.values() for w in f)
        return n + sum(self.completion_forced)


_BIT_CHARS = bytes.maketrans(b"01", b"\x00\x01")


def _words_int(store: array[int], first: int, last: int) -> int:
    """Words ``first..last`` of ``store`` as one integer, word ``first`` least significant."""
    return int.from_bytes(store[first : last + 1].tobytes(), sys.byteorder)


def _bits_of(store: array[int], start: int, count: int) -> bytes:
    """Bits ``start..start+count-1`` (16 per word, bit 0 first) as bytes 00/01."""
    first, last = start >> 4, (start + count - 1) >> 4
    value = _words_int(store, first, last) >> (start & 15)
    return format(value, f"0{count}b")[-count:][::-1].encode().translate(_BIT_CHARS)


def _set_bits(store: array[int], forced: array[int] | None, start: int, bits: bytes) -> None:
    """Set bits ``start..`` from bytes 00/01; a forced bit keeps its state."""
    count = len(bits)
    first, last = start >> 4, (start + count - 1) >> 4
    shift = start & 15
    span = ((1 << count) - 1) << shift
    new = int(bits[::-1].translate(_DIGIT_CHARS) or b"0", 2) << shift
    if forced is not None:
        span &= ~_words_int(forced, first, last)
    old = _words_int(store, first, last)
    value = (old & ~span) | (new & span)
    words = array("H")
    words.frombytes(value.to_bytes(2 * (last - first + 1), sys.byteorder))
    store[first : last + 1] = words


_DIGIT_CHARS = bytes.maketrans(b"\x00\x01", b"01")
