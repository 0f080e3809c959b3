"""Address text ("D100", "CIO 10.13", "E3_100", "T10.C", "P_On") <-> :class:`MemoryAddress`.

The syntax is documented in ``docs/addresses.md``. In short, after removing whitespace and
ignoring case: ``<area><number>[.<bit>][!]`` where ``.<bit>`` is a decimal bit 00-15 (a bit
designation), ``.C`` the Completion Flag of a timer/counter, ``.S`` the status of a task flag,
and a trailing ``!`` (or the word ``forced``) asks for the forced-status variant. EM banks are
written ``E<bank>_<word>`` with the bank in hex as in the manual (``E3_100``, ``E10_100`` =
bank 10 hex = 16). The manual's fixed-width form (``CIO 001013``, ``D0001013``, ``W01013``:
the word digits then two bit digits) is accepted too. ``#82:0064:00`` is a raw designation.
"""

from __future__ import annotations

import difflib
import re
from functools import lru_cache

from .areas import (
    AREAS,
    AreaSpec,
    DataType,
    MemoryAddress,
    Series,
    check_address,
    check_span,
    find_spec,
)
from .errors import AddressError

__all__ = ["format_address", "parse_address", "parse_span", "suggest_address"]

# Accepted prefixes -> the table's area mnemonic. "" (a bare number) is CIO.
_PREFIXES: dict[str, str] = {
    "": "CIO",
    "CIO": "CIO",
    "W": "W",
    "WR": "W",
    "H": "H",
    "HR": "H",
    "A": "A",
    "AR": "A",
    "T": "T",
    "TIM": "T",
    "C": "C",
    "CNT": "C",
    "D": "D",
    "DM": "D",
    "E": "E",
    "EM": "E",
    "TK": "TK",
    "IR": "IR",
    "DR": "DR",
}
_BIT_AREAS = frozenset({"CIO", "W", "H", "A", "D", "E"})

# ASCII only: no Unicode digits; at most 9 digits so int() stays cheap and bounded.
_RAW = re.compile(r"#([0-9A-F]{2}):?([0-9A-F]{4}):?([0-9A-F]{2})", re.ASCII)
_FORCED = re.compile(r"(.*?)(?:!|[_,/]?FORCED)", re.ASCII)
_BANKED = re.compile(r"EM?_?([0-9A-F]{1,2})_(\d{1,9})(?:\.(\d{1,2}))?", re.ASCII)
_GENERIC = re.compile(r"([A-Z]*)(\d{1,9})(?:\.(\d{1,2}|[A-Z]+))?", re.ASCII)

# (series, area, data type, bank) -> rows the parser may produce (never the CJ2 aliases).
_INDEX: dict[tuple[Series, str, DataType, int | None], tuple[AreaSpec, ...]] = {}
# (series, area mnemonic, bank) -> digits of the manual's fixed-width notation.
_DIGITS: dict[tuple[Series, str], int] = {}
# Names written without a number: P_On, EMBANK, ... (upper case) -> row per series.
_NAMED: dict[tuple[Series, str], AreaSpec] = {}
for _spec in AREAS:
    if _spec.alias:
        continue
    if _spec.data_type in (DataType.FLAG, DataType.BANK_NUMBER):
        _NAMED[(_spec.series, _spec.area.upper())] = _spec
        continue
    _key = (_spec.series, _spec.area, _spec.data_type, _spec.bank)
    _INDEX[_key] = (*_INDEX.get(_key, ()), _spec)
    if _spec.digits:
        _DIGITS[(_spec.series, _spec.area)] = _spec.digits

_NAMES: dict[str, str] = {}
for _spec in AREAS:
    if _spec.bank is None:
        _NAMES.setdefault(_spec.area, _spec.name)

_FORCED_OF = {
    DataType.BIT: DataType.BIT_FORCED,
    DataType.WORD: DataType.WORD_FORCED,
    DataType.COMPLETION_FLAG: DataType.COMPLETION_FLAG_FORCED,
}


def parse_address(text: str, series: Series = Series.CS_CJ) -> MemoryAddress:
    """Parse address text into the designation of manual 5-2-2 for ``series``.

    Raises :class:`AddressError` (a ``ValueError``) naming the valid range when the text does
    not parse or the address is outside its area.
    """
    if not isinstance(text, str):
        raise AddressError(f"address text must be str, got {type(text).__name__}")
    return _parse_text(text, series)


@lru_cache(maxsize=4096)
def _parse_text(text: str, series: Series) -> MemoryAddress:
    """:func:`parse_address` of str text, once per distinct text (errors are not kept)."""
    norm = "".join(text.split()).upper()
    if not norm:
        raise AddressError("empty address text")
    try:
        return _parse(norm, series)
    except AddressError as exc:
        shown = text.strip()
        shown = shown if len(shown) <= 40 else shown[:37] + "..."
        meant = suggest_address(norm, series)
        hint = f"; did you mean {meant}?" if meant else ""
        raise AddressError(f"{shown!r}: {exc}{hint}", end_code=exc.end_code) from None


#: Characters typed for one another: the letter O and the digit 0, I or l and 1.
_LOOKALIKES = {"O": "0", "0": "O", "I": "1", "L": "1", "1": "I"}
#: The most look-alike characters tried together (2**6 candidates at most).
_MAX_LOOKALIKES = 6


def suggest_address(text: str, series: Series = Series.CS_CJ) -> str | None:
    """The address text most like ``text`` that parses (``D1OO``: ``D100``; ``CI0 10``:
    ``CIO 10``; ``DN100``: ``DM100``), or ``None``: for a "did you mean" in errors."""
    norm = "".join(text.split()).upper()
    places = [i for i, ch in enumerate(norm) if ch in _LOOKALIKES][:_MAX_LOOKALIKES]
    found: list[tuple[int, str]] = []
    for mask in range(1, 1 << len(places)):
        chars = list(norm)
        for n, i in enumerate(places):
            if mask >> n & 1:
                chars[i] = _LOOKALIKES[chars[i]]
        found += [(bin(mask).count("1"), "".join(chars))]
    generic = re.fullmatch(r"([A-Z]+)(\d.*)", norm)
    if generic and generic.group(1) not in _PREFIXES:
        for prefix in difflib.get_close_matches(generic.group(1), _PREFIXES, n=3, cutoff=0.5):
            found.append((2, prefix + generic.group(2)))
    # Fewest changes first; of those, the one keeping the longest area name (CI0 10 is
    # CIO 10, not C1010).
    for _, _, candidate in sorted((n, -len(_letters(c)), c) for n, c in found):
        try:
            _parse(candidate, series)
        except AddressError:
            continue
        return _readable(candidate, series)
    return None


def _letters(norm: str) -> str:
    """The letters an address text starts with (its area)."""
    return norm[: len(norm) - len(norm.lstrip("ABCDEFGHIJKLMNOPQRSTUVWXYZ_"))]


def _readable(norm: str, series: Series) -> str:
    """``CIO10.01`` as ``CIO 10.01``, the way the manual and the docs write CIO; a flag by
    its name (``P_On``)."""
    named = _NAMED.get((series, norm))
    if named is not None:
        return named.area
    return f"CIO {norm[3:]}" if norm.startswith("CIO") and norm[3:4].isdigit() else norm


def parse_span(text: str, count: int, series: Series = Series.CS_CJ) -> MemoryAddress:
    """Parse address text for the first of ``count`` elements and check they all fit in its
    area (:func:`check_span`: :class:`AddressError` with end code 1104, naming the text)."""
    if not isinstance(text, str):
        raise AddressError(f"address text must be str, got {type(text).__name__}")
    return _parse_span(text, count, series)


@lru_cache(maxsize=4096)
def _parse_span(text: str, count: int, series: Series) -> MemoryAddress:
    address = _parse_text(text, series)
    try:
        check_span(address, count, series)
    except AddressError as exc:
        raise AddressError(f"{text!r}: {exc}", end_code=exc.end_code) from None
    return address


def _parse(norm: str, series: Series) -> MemoryAddress:
    raw = _RAW.fullmatch(norm)
    if raw:
        address = MemoryAddress(*(int(group, 16) for group in raw.groups()))
        check_address(address, series)
        return address
    forced = _FORCED.fullmatch(norm)
    if forced:
        norm = forced.group(1)
    named = _NAMED.get((series, norm))
    if named is None:
        other = _NAMED.get((Series.CV if series is Series.CS_CJ else Series.CS_CJ, norm))
        if other is not None:
            raise AddressError(f"{other.name} does not exist in the {series.value} series")
    else:
        if forced:
            raise AddressError(f"{named.name} has no forced-status designation")
        return MemoryAddress(named.code, named.first_word, 0)
    banked = _BANKED.fullmatch(norm)
    if banked:
        bank_text, number, bit = banked.groups()
        bank = int(bank_text, 16)
        if bank > 0x18:
            raise AddressError(f"EM bank {bank_text} hex out of range 0-18 hex")
        return _build(series, "E", bank, number, bit, bool(forced))
    generic = _GENERIC.fullmatch(norm)
    if not generic:
        raise AddressError("not an address (examples: D100, CIO 10.13, W5.01, E3_100, T10.C)")
    prefix, number, sub = generic.groups()
    area = _PREFIXES.get(prefix)
    if area is None:
        known = ", ".join(sorted(p for p in _PREFIXES if p))
        raise AddressError(f"unknown area {prefix!r} (known: {known}, P_... flags, EMBANK)")
    return _build(series, area, None, number, sub, bool(forced))


def _build(
    series: Series, area: str, bank: int | None, number: str, sub: str | None, forced: bool
) -> MemoryAddress:
    digits = _DIGITS.get((series, area), 0)
    bit: int | None = None
    if sub is None and digits and len(number) == digits + 2:
        number, sub = number[:-2], number[-2:]  # the manual's fixed-width bit notation
    if sub is not None and sub.isdigit():
        if area not in _BIT_AREAS:
            hint = " (write T10.C / C10.C for a Completion Flag)" if area in ("T", "C") else ""
            raise AddressError(f"{area} has no bit designations{hint}")
        bit = int(sub)
        if bit > 15:
            raise AddressError(f"bit {sub} out of range 00-15")
        dtype = DataType.BIT
    elif area in _BIT_AREAS:
        if sub is not None:
            raise AddressError(f"unknown suffix .{sub} for {area} (write a bit 00-15)")
        dtype = DataType.WORD
    elif area in ("T", "C"):
        if sub not in (None, "C"):
            raise AddressError(f"unknown suffix .{sub} (.C is the Completion Flag)")
        dtype = DataType.PV if sub is None else DataType.COMPLETION_FLAG
    elif area == "TK":
        if sub not in (None, "S"):
            raise AddressError(f"unknown suffix .{sub} (.S is the task status)")
        dtype = DataType.TASK_FLAG if sub is None else DataType.TASK_STATUS
    else:  # IR, DR
        if sub is not None:
            raise AddressError(f"{area} has no suffixes")
        dtype = DataType.PV
    if forced:
        if dtype not in _FORCED_OF:
            raise AddressError(f"{area} {dtype.value} has no forced-status designation")
        dtype = _FORCED_OF[dtype]
    specs = _INDEX.get((series, area, dtype, bank))
    if not specs:
        where = f"EM Area bank {bank:X}" if bank is not None else _NAMES[area]
        raise AddressError(f"{where} {dtype.value} does not exist in the {series.value} series")
    value = int(number)
    for spec in specs:
        if spec.first_number <= value <= spec.last_number:
            word = spec.first_word + value - spec.first_number
            return MemoryAddress(spec.code, word, 0 if bit is None else bit)
    ranges = ", ".join(
        f"{_text(s, s.first_word, None)}-{_text(s, s.last_word, None)}"
        + (" (read only)" if s.read_only else "")
        for s in specs
    )
    raise AddressError(
        f"{value} out of range for {specs[0].name} {dtype.value} in the {series.value} "
        f"series (valid: {ranges}; area code {specs[0].code:02X} hex)"
    )


def _text(spec: AreaSpec, word: int, bit: int | None) -> str:
    """Canonical text of ``word``/``bit`` in ``spec`` (``bit=None``: number only)."""
    dtype = spec.data_type
    if dtype in (DataType.FLAG, DataType.BANK_NUMBER):
        return spec.area
    prefix = spec.area if spec.bank is None else f"E{spec.bank:X}_"
    text = f"{prefix}{word - spec.first_word + spec.first_number}"
    if bit is None:
        return text
    if dtype in (DataType.BIT, DataType.BIT_FORCED):
        text += f".{bit:02d}"
    elif dtype in (DataType.COMPLETION_FLAG, DataType.COMPLETION_FLAG_FORCED):
        text += ".C"
    elif dtype is DataType.TASK_STATUS:
        text += ".S"
    if dtype in (DataType.BIT_FORCED, DataType.WORD_FORCED, DataType.COMPLETION_FLAG_FORCED):
        text += "!"
    return text


def format_address(address: MemoryAddress, series: Series | None = None) -> str:
    """Canonical text of ``address``: ``parse_address(format_address(a, s), s) == a``.

    With ``series=None`` the CS/CJ table is tried, then CV (their codes differ except 82 and
    98, which read the same). Designations outside the table, and the CJ2-only EM codes
    50-5F hex, come out raw: ``#53:000A:00``.
    """
    for candidate in (Series.CS_CJ, Series.CV) if series is None else (series,):
        spec = find_spec(address.area_code, address.word, candidate)
        if spec is not None and not spec.alias and address.bit <= spec.max_bit:
            return _text(spec, address.word, address.bit)
    return f"#{address.area_code:02X}:{address.word:04X}:{address.bit:02X}"
