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

from .state import (
    ADDRESS_RANGE_ERROR,
    ADDRESS_RANGE_EXCEEDED,
    AREA_MISSING,
    PARAMETER_ERROR,
    READ_ONLY,
    CommandFailed,
)

EM_BANK_WORDS = 32768
TIMER_COUNTER_COUNT = 4096
COUNTER_BASE = 0x8000
A_READ_ONLY_WORDS = 448  # A0-A447 are read-only for FINS writes


class Kind(Enum):
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


_SIZE = {
    Kind.BIT: 1,
    Kind.BIT_FORCED: 1,
    Kind.WORD: 2,
    Kind.WORD_FORCED: 4,
    Kind.FLAG: 1,
    Kind.FLAG_FORCED: 1,
    Kind.PV: 2,
    Kind.TASK: 1,
    Kind.TASK_STATUS: 1,
    Kind.SYSTEM: 1,
    Kind.REGISTER: 2,
    Kind.INDEX: 4,
}


@dataclass(frozen=True, slots=True)
class Area:
    """What an area code designates: a kind and a store (``"CIO"``, ``"D"``, ``"E3"``...)."""

    code: int
    kind: Kind
    store: str  # "CIO", "W", "H", "A", "D", "E<n>", "E*" (current bank), "TC", ...

    @property
    def element_size(self) -> int:
        return _SIZE[self.kind]

    @property
    def is_bit(self) -> bool:
        return self.kind in (Kind.BIT, Kind.BIT_FORCED)


def _area_table() -> dict[int, Area]:
    t: dict[int, Area] = {}
    for code, store in ((0x30, "CIO"), (0x31, "W"), (0x32, "H"), (0x33, "A"), (0x02, "D")):
        t[code] = Area(code, Kind.BIT, store)
    for code, store in ((0xB0, "CIO"), (0xB1, "W"), (0xB2, "H"), (0xB3, "A"), (0x82, "D")):
        t[code] = Area(code, Kind.WORD, store)
    for code, store in ((0x70, "CIO"), (0x71, "W"), (0x72, "H")):
        t[code] = Area(code, Kind.BIT_FORCED, store)
    for code, store in ((0xF0, "CIO"), (0xF1, "W"), (0xF2, "H")):
        t[code] = Area(code, Kind.WORD_FORCED, store)
    t[0x09] = Area(0x09, Kind.FLAG, "TC")
    t[0x49] = Area(0x49, Kind.FLAG_FORCED, "TC")
    t[0x89] = Area(0x89, Kind.PV, "TC")
    for bank in range(16):
        t[0x20 + bank] = Area(0x20 + bank, Kind.BIT, f"E{bank}")
        t[0xA0 + bank] = Area(0xA0 + bank, Kind.WORD, f"E{bank}")
        t[0x50 + bank] = Area(0x50 + bank, Kind.WORD, f"E{bank}")  # CJ2 only
    for bank in range(16, 25):
        t[0xE0 + bank - 16] = Area(0xE0 + bank - 16, Kind.BIT, f"E{bank}")
        t[0x60 + bank - 16] = Area(0x60 + bank - 16, Kind.WORD, f"E{bank}")
    t[0x0A] = Area(0x0A, Kind.BIT, "E*")
    t[0x98] = Area(0x98, Kind.WORD, "E*")
    t[0x06] = Area(0x06, Kind.TASK, "TK")
    t[0x46] = Area(0x46, Kind.TASK_STATUS, "TK")
    t[0x07] = Area(0x07, Kind.SYSTEM, "SYS")
    t[0xBC] = Area(0xBC, Kind.REGISTER, "DR")
    t[0xDC] = Area(0xDC, Kind.INDEX, "IR")
    return t


AREAS: dict[int, Area] = _area_table()

_EM_WORD_CODES = frozenset((*range(0xA0, 0xB0), *range(0x50, 0x60), *range(0x60, 0x69)))
_EM_BIT_CODES = frozenset((*range(0x20, 0x30), *range(0xE0, 0xE9)))
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

# Segments of each store: (first address, number of elements, index of the first element).
_Segments = tuple[tuple[int, int, int], ...]
_TC_SEGMENTS: _Segments = ((0, TIMER_COUNTER_COUNT, 0), (COUNTER_BASE, TIMER_COUNTER_COUNT, 4096))
_SYSTEM_SEGMENTS: _Segments = ((0x0000, 5, 0), (0x1000, 16, 5), (0x2001, 1, 21))
_DR_SEGMENTS: _Segments = ((0x0200, 16, 0), (0x0F00, 1, 16))
_IR_SEGMENTS: _Segments = ((0x0100, 16, 0),)
_TASK_SEGMENTS: _Segments = ((0, 32, 0),)
_WORD_COUNTS = {"CIO": 6144, "W": 512, "H": 512, "A": 960, "D": 32768}
_FORCEABLE = ("CIO", "W", "H")
#: Condition flag numbers (07 area, word 0x1000 + n) that are constant.
_ALWAYS_OFF = 0x0E
_ALWAYS_ON = 0x0F
_CURRENT_BANK_INDEX = 16


def _words(n: int) -> array[int]:
    return array("H", bytes(2 * n))


class IOMemory:
    """CIO, W, H, A, T/C, DM, EM banks, task flags, IR/DR, system flags and forced status."""

    def __init__(self, *, em_banks: int = 25, clock: Callable[[], float] = time.time) -> None:
        if not 0 <= em_banks <= 25:
            raise ValueError(f"em_banks {em_banks} out of range 0..25")
        self.em_banks = em_banks
        self._clock = clock
        self._stores: dict[str, array[int]] = {k: _words(n) for k, n in _WORD_COUNTS.items()}
        for bank in range(em_banks):
            self._stores[f"E{bank}"] = _words(EM_BANK_WORDS)
        self._forced: dict[str, array[int]] = {k: _words(_WORD_COUNTS[k]) for k in _FORCEABLE}
        self.pv = _words(2 * TIMER_COUNTER_COUNT)
        self.completion = bytearray(2 * TIMER_COUNTER_COUNT)
        self.completion_forced = bytearray(2 * TIMER_COUNTER_COUNT)
        self.task_flags = bytearray(32)
        self.task_status = bytearray(32)
        self.condition_flags = bytearray(16)
        self.access_error = False
        self.data_registers = _words(16)
        self.index_registers = [0] * 16
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

    def _segments(self, area: Area) -> _Segments:
        if area.kind in (Kind.FLAG, Kind.FLAG_FORCED, Kind.PV):
            return _TC_SEGMENTS
        if area.kind is Kind.SYSTEM:
            return _SYSTEM_SEGMENTS
        if area.kind is Kind.REGISTER:
            return _DR_SEGMENTS
        if area.kind is Kind.INDEX:
            return _IR_SEGMENTS
        if area.kind in (Kind.TASK, Kind.TASK_STATUS):
            return _TASK_SEGMENTS
        n = EM_BANK_WORDS if area.store.startswith("E") else _WORD_COUNTS[area.store]
        return ((0, n, 0),)

    def locate(self, area: Area, word: int, bit: int, count: int) -> int:
        """Index of the first element; ``1103`` bad start, ``1104`` end past the area."""
        for first, n, index in self._segments(area):
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
        if i < 5:  # clock pulses: 1 min, 1 s, 0.2 s, 0.1 s, 0.02 s; ON for half the period
            period = (60.0, 1.0, 0.2, 0.1, 0.02)[i]
            return int((self._clock() % period) < period / 2)
        if i < 21:
            n = i - 5
            if n == _ALWAYS_OFF:
                return 0
            if n == _ALWAYS_ON:
                return 1
            return self.condition_flags[n]
        return int(self.access_error)

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

    def _check_writable(self, area: Area, word: int) -> None:
        # A run that starts in A0-A447 touches a read-only word (runs only grow upwards).
        if area.store == "A" and word < A_READ_ONLY_WORDS:
            raise CommandFailed(READ_ONLY, message="A0-A447 are read-only")

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
        self._check_writable(area, word)
        if area.kind is Kind.WORD and not self._any_forced(area, start, count):
            chunk = array("H", data[: 2 * count])  # fast path: one slice assignment
            if sys.byteorder == "little":
                chunk.byteswap()
            self._store(area)[start : start + count] = chunk
            return
        size = area.element_size
        values = [int.from_bytes(data[j * size : (j + 1) * size], "big") for j in range(count)]
        if area.is_bit and any(v > 1 for v in values):
            raise CommandFailed(PARAMETER_ERROR, message="bit data must be 00 or 01")
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
        self._check_writable(area, word)
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
        self._check_writable(d_area, dst[1])
        values = [self._get(s_area, i) for i in range(s, s + count)]
        for j, v in enumerate(values):
            self._set(d_area, d + j, v)

    # ---- typed helpers (tests, servers, CLI) -----------------------------------------------

    def read_words(self, code: int, word: int, count: int) -> list[int]:
        area = self.area(code)
        start = self.locate(area, word, 0, max(count, 1))
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
        area = self.area(code, frozenset((0x30, 0x31, 0x32, 0x09)))
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
