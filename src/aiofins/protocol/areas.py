"""I/O memory area codes, element sizes and ranges (manual 5-2-2), CS/CJ/CP/NSJ and CV mode.

A :class:`MemoryAddress` is the 4-byte designation on the wire: area code, word, bit.
:data:`AREAS` is the manual's table as data, one :class:`AreaSpec` per contiguous range;
:func:`check_address` validates a designation against it for one :class:`Series`.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from .errors import AddressError, DecodeError


class Series(enum.Enum):
    """Which column of manual 5-2-2 applies: CS/CJ/CP/NSJ codes or CVM1/CV-series codes."""

    #: CS, CJ, CP and NSJ CPU Units (the default).
    CS_CJ = "CS/CJ/CP/NSJ"
    #: CVM1 and CV-series CPU Units.
    CV = "CVM1/CV"


class DataType(enum.Enum):
    """The manual's *data type* column."""

    BIT = "bit"
    BIT_FORCED = "bit with forced status"
    WORD = "word"
    WORD_FORCED = "word with forced status"
    COMPLETION_FLAG = "completion flag"
    COMPLETION_FLAG_FORCED = "completion flag with forced status"
    PV = "present value"
    TASK_FLAG = "task flag"
    TASK_STATUS = "task status"
    BANK_NUMBER = "current EM bank number"
    FLAG = "clock pulse / condition flag"


#: Data types whose elements are single bits of a word (bit byte 00-0F, offsets carry).
BIT_TYPES = frozenset({DataType.BIT, DataType.BIT_FORCED})


@dataclass(frozen=True, slots=True)
class AreaSpec:
    """One row of manual 5-2-2: an area code over one contiguous range of words.

    Element ``number`` (what people write: the 448 of ``A448``) is at wire word
    ``first_word + number - first_number``. ``area`` is the canonical text prefix (or, for a
    clock pulse / condition flag, its whole name); ``digits`` is the word width of the
    manual's fixed-width notation (``CIO 001013`` = word 0010, bit 13), 0 where it has none.
    """

    series: Series
    code: int
    area: str
    name: str
    data_type: DataType
    element_size: int
    first_word: int
    count: int
    first_number: int = 0
    bank: int | None = None
    digits: int = 0
    read_only: bool = False
    alias: bool = False  # CJ2-only alternate code: accepted on the wire, never produced by text

    @property
    def last_word(self) -> int:
        return self.first_word + self.count - 1

    @property
    def last_number(self) -> int:
        return self.first_number + self.count - 1

    @property
    def max_bit(self) -> int:
        return 15 if self.data_type in BIT_TYPES else 0

    def contains(self, word: int) -> bool:
        return self.first_word <= word <= self.last_word

    def describe(self) -> str:
        """The row as the manual would print it, e.g. ``82 hex DM word D0-D32767 (0000-7FFF)``."""
        words = f"{self.first_word:04X}-{self.last_word:04X} hex"
        bits = f", bit 00-{self.max_bit:02X} hex" if self.max_bit else ", bit 00"
        return f"{self.code:02X} hex {self.name} {self.data_type.value}: words {words}{bits}"


_CS = Series.CS_CJ
_CV = Series.CV
_B, _BF, _W, _WF = DataType.BIT, DataType.BIT_FORCED, DataType.WORD, DataType.WORD_FORCED
_CF, _CFF, _PV = DataType.COMPLETION_FLAG, DataType.COMPLETION_FLAG_FORCED, DataType.PV


def _rows() -> tuple[AreaSpec, ...]:
    rows: list[AreaSpec] = []
    add = rows.append
    # (series, mnemonic, name, words, digits, bit, bit+forced, word, word+forced)
    for series, area, name, count, digits, bit, bitf, word, wordf in (
        (_CS, "CIO", "CIO Area", 6144, 4, 0x30, 0x70, 0xB0, 0xF0),
        (_CS, "W", "Work Area", 512, 3, 0x31, 0x71, 0xB1, 0xF1),
        (_CS, "H", "Holding Bit Area", 512, 3, 0x32, 0x72, 0xB2, 0xF2),
        # CV: CIO 0000-2555 = 09FB hex. The manual prints the C0 row's range as
        # "CIO 000000 to CIO 255515" (a bit range); its memory address column is words.
        (_CV, "CIO", "CIO Area", 2556, 4, 0x00, 0x40, 0x80, 0xC0),
    ):
        add(AreaSpec(series, bit, area, name, _B, 1, 0, count, digits=digits))
        add(AreaSpec(series, bitf, area, name, _BF, 1, 0, count, digits=digits))
        add(AreaSpec(series, word, area, name, _W, 2, 0, count, digits=digits))
        add(AreaSpec(series, wordf, area, name, _WF, 4, 0, count, digits=digits))
    # Auxiliary Area: A000-A447 read only, A448-A959 read/write; no forced-status codes.
    # CS/CJ at words 0000-03BF hex; CV inside area 00/80 at 0B00-0EBF hex.
    for series, bit, word, base in ((_CS, 0x33, 0xB3, 0x0000), (_CV, 0x00, 0x80, 0x0B00)):
        for dtype, code, size in ((_B, bit, 1), (_W, word, 2)):
            add(AreaSpec(series, code, "A", "Auxiliary Bit Area", dtype, size, base, 448,
                         digits=3, read_only=True))  # fmt: skip
            add(AreaSpec(series, code, "A", "Auxiliary Bit Area", dtype, size, base + 448, 512,
                         first_number=448, digits=3))  # fmt: skip
    # Timers and counters: one code for both, counters at a word offset.
    # Manual typo: the CS/CJ 49 and 89 rows end "0FFFF0"/"8FFFF0"; the bit byte of a
    # completion flag or PV is always 00 (5-2-1), so the last designations are 0FFF00/8FFF00.
    # CV: T/C 0000-2047 (the manual's parenthesised 0000-1023 is for smaller CPUs).
    for series, flag, flagf, pv, count, c_base in (
        (_CS, 0x09, 0x49, 0x89, 4096, 0x8000),
        (_CV, 0x01, 0x41, 0x81, 2048, 0x0800),
    ):
        for area, name, base in (("T", "Timer Area", 0), ("C", "Counter Area", c_base)):
            add(AreaSpec(series, flag, area, name, _CF, 1, base, count))
            add(AreaSpec(series, flagf, area, name, _CFF, 1, base, count))
            add(AreaSpec(series, pv, area, name, _PV, 2, base, count))
    # DM: bit access only on CS/CJ.
    add(AreaSpec(_CS, 0x02, "D", "DM Area", _B, 1, 0, 32768, digits=5))
    add(AreaSpec(_CS, 0x82, "D", "DM Area", _W, 2, 0, 32768, digits=5))
    add(AreaSpec(_CV, 0x82, "D", "DM Area", _W, 2, 0, 32768, digits=5))
    # EM banks 0-18 hex (0-24). Bit 20-2F then E0-E8; word A0-AF then 60-68; CJ2 also
    # accepts 50-5F for the words of banks 0-F (manual note 2). CV: words of banks 0-7, 90-97.
    # manual wins: fins-wire-format.md 5.1 lists only banks 0-C (20-2C / A0-AC).
    for bank in range(0x19):
        name = f"EM Area bank {bank:X}"
        bit = 0x20 + bank if bank < 16 else 0xE0 + bank - 16
        word = 0xA0 + bank if bank < 16 else 0x60 + bank - 16
        add(AreaSpec(_CS, bit, "E", name, _B, 1, 0, 32768, bank=bank, digits=5))
        add(AreaSpec(_CS, word, "E", name, _W, 2, 0, 32768, bank=bank, digits=5))
        if bank < 16:
            add(AreaSpec(_CS, 0x50 + bank, "E", name, _W, 2, 0, 32768, bank=bank, digits=5,
                         alias=True))  # fmt: skip
        if bank < 8:
            add(AreaSpec(_CV, 0x90 + bank, "E", name, _W, 2, 0, 32768, bank=bank, digits=5))
    # Current EM bank. Manual typo: the CV 98 row starts at "E000000" (one zero too many).
    add(AreaSpec(_CS, 0x0A, "E", "EM Area current bank", _B, 1, 0, 32768, digits=5))
    add(AreaSpec(_CS, 0x98, "E", "EM Area current bank", _W, 2, 0, 32768, digits=5))
    add(AreaSpec(_CV, 0x98, "E", "EM Area current bank", _W, 2, 0, 32768, digits=5))
    bank_no = DataType.BANK_NUMBER
    add(AreaSpec(_CS, 0xBC, "EMBANK", "EM current bank No.", bank_no, 2, 0x0F00, 1))
    add(AreaSpec(_CV, 0x9C, "EMBANK", "EM current bank No.", bank_no, 2, 0x0006, 1))
    # Task flags TK0000-TK0031, registers.
    add(AreaSpec(_CS, 0x06, "TK", "Task Flag", DataType.TASK_FLAG, 1, 0, 32))
    add(AreaSpec(_CS, 0x46, "TK", "Task Flag", DataType.TASK_STATUS, 1, 0, 32))
    add(AreaSpec(_CS, 0xDC, "IR", "Index Register", _PV, 4, 0x0100, 16))
    add(AreaSpec(_CS, 0xBC, "DR", "Data Register", _PV, 2, 0x0200, 16))
    add(AreaSpec(_CV, 0x9C, "DR", "Data Register", _PV, 2, 0x0003, 3))
    # Clock pulses and condition flags, area 07, each at a fixed word with bit 00.
    for word, area, name in FLAGS:
        add(AreaSpec(_CS, 0x07, area, name, DataType.FLAG, 1, word, 1))
    return tuple(rows)


#: Clock pulses and condition flags of area 07 (CS/CJ only): wire word, name, manual's name.
#: Manual typo: it prints "Always OFF Flag (ON) 100E00" and "Always ON Flag (OFF) 100F00";
#: the parenthesised symbols are swapped. We follow the flag names: 100E = Always OFF,
#: 100F = Always ON (not verified on hardware; reading P_On must give 01).
#: The Access Error Flag row (200100) lost its area and data type columns in the text;
#: it sits under "Condition Flags" and is taken as area 07, bit.
FLAGS: tuple[tuple[int, str, str], ...] = (
    (0x0000, "P_1min", "1-min clock pulse"),
    (0x0001, "P_1s", "1-s clock pulse"),
    (0x0002, "P_0_2s", "0.2-s clock pulse"),
    (0x0003, "P_0_1s", "0.1-s clock pulse"),
    (0x0004, "P_0_02s", "0.02-s clock pulse"),
    (0x1000, "P_ER", "Error Flag (ER)"),
    (0x1001, "P_CY", "Carry Flag (CY)"),
    (0x1002, "P_GT", "Greater Than Flag (>)"),
    (0x1003, "P_EQ", "Equals Flag (=)"),
    (0x1004, "P_LT", "Less Than Flag (<)"),
    (0x1005, "P_N", "Negative Flag (N)"),
    (0x1006, "P_OF", "Overflow Flag (OF)"),
    (0x1007, "P_UF", "Underflow Flag (UF)"),
    (0x1008, "P_GE", "Greater Than or Equals Flag (>=)"),
    (0x1009, "P_NE", "Not Equal Flag (<>)"),
    (0x100A, "P_LE", "Less Than or Equals Flag (<=)"),
    (0x100E, "P_Off", "Always OFF Flag"),
    (0x100F, "P_On", "Always ON Flag"),
    (0x2001, "P_AER", "Access Error Flag"),
)

#: Every row of manual 5-2-2, both series.
AREAS: tuple[AreaSpec, ...] = _rows()

_BY_CODE: dict[Series, dict[int, tuple[AreaSpec, ...]]] = {}
for _spec in AREAS:
    _series_map = _BY_CODE.setdefault(_spec.series, {})
    _series_map[_spec.code] = (*_series_map.get(_spec.code, ()), _spec)

_ELEMENT_SIZE: dict[int, int] = {spec.code: spec.element_size for spec in AREAS}

#: Area codes whose elements are single bits (both series): offsets carry from bit 15.
BIT_AREA_CODES = frozenset(spec.code for spec in AREAS if spec.data_type in BIT_TYPES)


def element_size(area_code: int) -> int:
    """Bytes per element for ``area_code``; :class:`AddressError` if the code is unknown.

    CS/CJ and CV codes never disagree where they overlap (82 DM words, 98 current EM bank).
    """
    try:
        return _ELEMENT_SIZE[area_code]
    except KeyError:
        raise AddressError(f"unknown memory area code {area_code:02X} hex") from None


def is_known_area_code(area_code: int, series: Series | None = None) -> bool:
    """Whether ``area_code`` is in manual 5-2-2 (for ``series``, or for either series)."""
    if series is None:
        return area_code in _ELEMENT_SIZE
    return area_code in _BY_CODE[series]


def area_specs(area_code: int, series: Series = Series.CS_CJ) -> tuple[AreaSpec, ...]:
    """The rows of ``area_code`` in ``series`` (empty when the code does not exist there)."""
    return _BY_CODE[series].get(area_code, ())


def area_codes(series: Series = Series.CS_CJ) -> frozenset[int]:
    """Every memory area code of ``series``."""
    return frozenset(_BY_CODE[series])


def find_spec(area_code: int, word: int, series: Series = Series.CS_CJ) -> AreaSpec | None:
    """The row holding ``word`` of ``area_code`` in ``series``, or ``None``."""
    for spec in _BY_CODE[series].get(area_code, ()):
        if spec.contains(word):
            return spec
    return None


def check_address(address: MemoryAddress, series: Series = Series.CS_CJ) -> AreaSpec:
    """Validate ``address`` against manual 5-2-2 for ``series``; return its row.

    Raises :class:`AddressError` naming the valid codes, word ranges or bits.
    """
    specs = _BY_CODE[series].get(address.area_code)
    if not specs:
        codes = " ".join(f"{c:02X}" for c in sorted(_BY_CODE[series]))
        raise AddressError(
            f"memory area code {address.area_code:02X} hex does not exist in the "
            f"{series.value} series (valid codes: {codes} hex)"
        )
    spec = find_spec(address.area_code, address.word, series)
    if spec is None:
        ranges = "; ".join(s.describe() for s in specs)
        raise AddressError(
            f"word {address.word:04X} hex is out of range for area code "
            f"{address.area_code:02X} hex in the {series.value} series (valid: {ranges})"
        )
    if address.bit > spec.max_bit:
        raise AddressError(
            f"bit {address.bit:02X} hex is out of range for {spec.describe()}"
            if spec.max_bit
            else f"bit must be 00 for {spec.describe()}, got {address.bit:02X} hex"
        )
    return spec


def check_span(address: MemoryAddress, count: int, series: Series = Series.CS_CJ) -> None:
    """Refuse ``count`` elements from ``address`` that run past the end of its area.

    The area is the run of manual 5-2-2 rows of the address's area code that follow one
    another without a gap (A0-A447 and A448-A959 read as one). Elements are bits in a bit
    area, else words (or flags). A PLC answers such a command with end code 1104 (address
    range exceeded); this raises :class:`AddressError` carrying that end code instead. An
    address outside every row is left to :func:`check_address`.
    """
    spec = find_spec(address.area_code, address.word, series)
    if spec is None or count <= 1:
        return
    last_word = spec.last_word
    following = find_spec(address.area_code, last_word + 1, series)
    while following is not None:
        last_word = following.last_word
        following = find_spec(address.area_code, last_word + 1, series)
    per_word = 16 if spec.max_bit else 1
    room = (last_word - address.word + 1) * per_word - (address.bit if spec.max_bit else 0)
    if count > room:
        unit = "bits" if spec.max_bit else "words" if spec.element_size >= 2 else "flags"
        raise AddressError(
            f"{count} {unit} from {address} run past the end of the {spec.name} "
            f"(word {last_word:04X} hex): at most {room} from there",
            end_code=0x1104,
        )


@dataclass(frozen=True, slots=True)
class MemoryAddress:
    """An I/O memory designation: area code (1 byte), word (2 bytes), bit (1 byte).

    ``str()`` gives the canonical address text (``D100``, ``CIO10.13``, ``E3_100``; see
    :mod:`aiofins.protocol.addresses`) and, for designations outside manual 5-2-2, the raw
    form ``#82:0064:00`` (area code, word, bit in hex). Only the byte ranges are checked
    here; :func:`check_address` checks a series' table.
    """

    area_code: int
    word: int
    bit: int = 0

    def __post_init__(self) -> None:
        if not 0 <= self.area_code <= 0xFF:
            raise AddressError(f"memory area code {self.area_code} out of range 0..255")
        if not 0 <= self.word <= 0xFFFF:
            raise AddressError(f"word address {self.word} out of range 0..65535")
        if not 0 <= self.bit <= 0xFF:
            raise AddressError(f"bit number {self.bit} out of range 0..255")

    @property
    def element_size(self) -> int:
        """Bytes per element of this area code (1, 2 or 4)."""
        return element_size(self.area_code)

    @property
    def is_bit(self) -> bool:
        """Whether elements are single bits of a word (bit codes, with or without forcing)."""
        return self.area_code in BIT_AREA_CODES

    def encode(self) -> bytes:
        return bytes((self.area_code, self.word >> 8, self.word & 0xFF, self.bit))

    @classmethod
    def decode(cls, raw: bytes, series: Series | None = None) -> MemoryAddress:
        """Decode 4 bytes; with ``series``, also check them against manual 5-2-2.

        Raises :class:`DecodeError` only, with the end code a PLC answers: 1002/1001 for a
        short/long field, 1101 for an area code the series lacks, 1103 for a word or bit out
        of the area's range.
        """
        if len(raw) != 4:
            raise DecodeError(
                f"memory address needs 4 bytes, got {len(raw)}",
                end_code=0x1002 if len(raw) < 4 else 0x1001,
            )
        address = cls(raw[0], (raw[1] << 8) | raw[2], raw[3])
        if series is not None:
            try:
                check_address(address, series)
            except AddressError as exc:
                known = raw[0] in _BY_CODE[series]
                raise DecodeError(str(exc), end_code=0x1103 if known else 0x1101) from None
        return address

    def offset(self, n: int) -> MemoryAddress:
        """The designation ``n`` elements further on (negative: back).

        Bit designations advance by bits and carry into the word (CIO 0.15 + 1 = CIO 1.00);
        everything else advances by words (one timer, register or word per element).
        """
        if self.is_bit:
            position = self.word * 16 + self.bit + n
            word, bit = divmod(position, 16)
        else:
            word, bit = self.word + n, self.bit
        if not 0 <= word <= 0xFFFF:
            raise AddressError(f"{self} offset by {n} leaves the word range 0000-FFFF hex")
        return MemoryAddress(self.area_code, word, bit)

    def __add__(self, n: int) -> MemoryAddress:
        if not isinstance(n, int):
            return NotImplemented
        return self.offset(n)

    def __sub__(self, n: int) -> MemoryAddress:
        if not isinstance(n, int):
            return NotImplemented
        return self.offset(-n)

    def __str__(self) -> str:
        from .addresses import format_address  # text syntax lives with the parser

        return format_address(self)
