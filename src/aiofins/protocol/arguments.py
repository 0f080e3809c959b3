"""What a user types, turned into the typed arguments of the operations (one layer for all).

The manual-named client methods take address text (``"D10"``, ``"CIO 1.02"``) as well as
:class:`MemoryAddress`, lists of ints as well as bytes, enum members by name (``"card"``,
``"monitor"``, ``"area_to_file"``) as well as by value, and ISO text for a time. The operation
classes themselves stay strict; these functions convert before building them and raise
:class:`CommandError` (or :class:`AddressError`) saying what was expected.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from datetime import datetime
from enum import IntEnum
from typing import TypeVar, cast

from .addresses import parse_address
from .areas import MemoryAddress, element_size
from .commands.debug import ForcedSetResetEntry, ForceSpec
from .errors import CommandError
from .files import Disk
from .inputs import shown

E = TypeVar("E", bound=IntEnum)

#: Address text (CS/CJ notation) or a :class:`MemoryAddress`.
AddressLike = str | MemoryAddress
#: Raw bytes, or one int per element (a word, a bit 0/1, a 4-byte element).
DataLike = bytes | bytearray | memoryview | Sequence[int]

#: Short names people use for enum members, besides the members' own names.
_ALIASES: dict[type[IntEnum], dict[str, int]] = {
    Disk: {"CARD": Disk.MEMORY_CARD, "EM": Disk.EM_FILE_MEMORY, "CASSETTE": Disk.MEMORY_CASSETTE},
}


def address(value: AddressLike, what: str = "address") -> MemoryAddress:
    """A :class:`MemoryAddress` from address text or itself."""
    if isinstance(value, MemoryAddress):
        return value
    if isinstance(value, str):
        return parse_address(value)
    raise CommandError(
        f"{what} must be address text such as 'D100' or a MemoryAddress; got {shown(value)}"
    )


def addresses(value: AddressLike | Iterable[AddressLike]) -> tuple[MemoryAddress, ...]:
    """Several addresses (one address alone is one address)."""
    if isinstance(value, (str, MemoryAddress)):
        return (address(value),)
    try:
        items = list(value)
    except TypeError:
        raise CommandError(
            f"addresses must be a list of address texts or MemoryAddress; got {shown(value)}"
        ) from None
    return tuple(address(item) for item in items)


def element_data(start: MemoryAddress, data: DataLike) -> bytes:
    """The data bytes of a memory write at ``start``: bytes as they are, or one int per
    element, packed to the area's element size (2 bytes a word, 1 a bit)."""
    if isinstance(data, (bytes, bytearray, memoryview)):
        return bytes(data)
    if isinstance(data, str) or not isinstance(data, Sequence):
        raise CommandError(f"data must be bytes or a list of ints; got {shown(data)}")
    size = element_size(start.area_code)
    limit = (1 << (8 * size)) - 1
    out = bytearray()
    for value in data:
        if (isinstance(value, bool) and size != 1) or not isinstance(value, int):
            raise CommandError(f"data value {shown(value)} is no element value (an int)")
        if not 0 <= value <= limit:
            raise CommandError(f"data value {shown(value)} out of range 0..{limit}")
        out += value.to_bytes(size, "big")
    return bytes(out)


def words(value: Iterable[int], what: str = "words") -> tuple[int, ...]:
    """A tuple of word values from any iterable of ints (a list, a tuple, a range)."""
    if isinstance(value, (str, bytes, bytearray)):
        raise CommandError(f"{what} must be a list of ints; got {shown(value)}")
    try:
        return tuple(value)
    except TypeError:
        raise CommandError(f"{what} must be a list of ints; got {shown(value)}") from None


def member(kind: type[E], value: E | int | str, what: str) -> E:
    """An enum member from its name in any case (``"area-to-file"``, ``"card"``); a member or
    a number is passed on as it is, for the operation to check (with the end code a PLC would
    answer)."""
    if not isinstance(value, str):
        return cast(E, value)
    key = value.strip().upper().replace("-", "_").replace(" ", "_")
    found = kind.__members__.get(key)
    if found is None and key in _ALIASES.get(kind, {}):
        found = kind(_ALIASES[kind][key])
    if found is not None:
        return found
    names = [m.lower() for m in kind.__members__] + [a.lower() for a in _ALIASES.get(kind, {})]
    raise CommandError(f"{what} must be one of {', '.join(names)}; got {shown(value)}")


def names(value: str | Iterable[str], what: str = "file names") -> tuple[str, ...]:
    """File names: one name alone, or a list of them."""
    if isinstance(value, str):
        return (value,)
    items = tuple(value)
    if not all(isinstance(item, str) for item in items):
        raise CommandError(f"{what} must be text; got {shown(items)}")
    return items


def moment(value: datetime | str) -> datetime:
    """A time from a :class:`datetime` or ISO text (``"2026-01-02T03:04:05"``)."""
    if isinstance(value, datetime):
        return value
    if isinstance(value, str):
        try:
            return datetime.fromisoformat(value)
        except ValueError:
            pass
    raise CommandError(
        f"time must be a datetime or ISO text such as '2026-01-02T03:04:05'; got {shown(value)}"
    )


def payload(value: bytes | bytearray | memoryview | Sequence[int], what: str = "data") -> bytes:
    """Bytes from bytes-like data or a list of byte values."""
    if isinstance(value, (bytes, bytearray, memoryview)):
        return bytes(value)
    if isinstance(value, str):
        raise CommandError(f"{what} must be bytes or a list of byte values; got {shown(value)}")
    try:
        return bytes(value)
    except (TypeError, ValueError):
        raise CommandError(
            f"{what} must be bytes or a list of byte values 0..255; got {shown(value)}"
        ) from None


#: A forced set/reset entry, or a pair (designation, bit address) of what users type.
ForceLike = ForcedSetResetEntry | tuple[ForceSpec | int | str, AddressLike]


def force_entries(value: ForceLike | Iterable[ForceLike]) -> tuple[ForcedSetResetEntry, ...]:
    """Entries of 23 01: entries, or ``("forced_set", "CIO 0.01")`` pairs; one alone too."""
    if isinstance(value, ForcedSetResetEntry) or (
        isinstance(value, tuple) and len(value) == 2 and isinstance(value[1], (str, MemoryAddress))
    ):
        value = [value]
    out = []
    for item in value:
        if isinstance(item, ForcedSetResetEntry):
            out.append(item)
            continue
        if not isinstance(item, tuple) or len(item) != 2:
            raise CommandError(
                "forced set/reset entries must be ForcedSetResetEntry or (designation, address) "
                f"pairs such as ('forced_set', 'CIO 0.01'); got {shown(item)}"
            )
        spec, where = item
        out.append(ForcedSetResetEntry(member(ForceSpec, spec, "designation"), address(where)))
    return tuple(out)


__all__ = [
    "AddressLike",
    "DataLike",
    "ForceLike",
    "address",
    "addresses",
    "element_data",
    "force_entries",
    "member",
    "moment",
    "names",
    "payload",
    "words",
]
