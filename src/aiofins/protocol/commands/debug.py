"""Debugging (manual 5-3-44, 5-3-45): 23 01 FORCED SET/RESET, 23 02 FORCED SET/RESET CANCEL."""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Any, ClassVar

from ..areas import MemoryAddress
from ..codec import Reader, check_range
from ..errors import AddressError, CommandError, DecodeError
from ._base import ParameterlessRequest, Request, expect_no_data


class ForceSpec(enum.IntEnum):
    """Set/reset designation of one 23 01 entry (manual 5-3-44)."""

    #: Turn OFF and place in forced status.
    FORCED_RESET = 0x0000
    #: Turn ON and place in forced status.
    FORCED_SET = 0x0001
    #: Turn OFF and release the forced status.
    RELEASE_OFF = 0x8000
    #: Turn ON and release the forced status.
    RELEASE_ON = 0x8001
    #: Release the forced status, keeping the ON/OFF state.
    RELEASE = 0xFFFF


#: Memory area codes whose bits/flags can be forced: CIO, WR, HR bits and T/C completion
#: flags (CS/CJ 30, 31, 32, 09; CV-series 00, 01).
FORCEABLE_AREA_CODES = frozenset({0x30, 0x31, 0x32, 0x09, 0x00, 0x01})
#: Timer/counter completion flags (CS/CJ 09, CV 01): the bit byte is always 00 (5-3-45).
_COMPLETION_FLAGS = frozenset({0x09, 0x01})
ENTRY_SIZE = 6
#: (2000 parameter bytes - 2 count bytes) / 6 bytes per entry.
MAX_ENTRIES = 333


def _check_address(address: MemoryAddress) -> None:
    if address.area_code not in FORCEABLE_AREA_CODES:
        raise AddressError(
            f"memory area code {address.area_code:02X} cannot be force-set/reset "
            "(bits of CIO 30, WR 31, HR 32, T/C completion flags 09; CV 00, 01)"
        )
    if address.bit > 15:
        raise AddressError(f"bit number {address.bit} out of range 0..15")
    if address.area_code in _COMPLETION_FLAGS and address.bit != 0:
        raise AddressError(
            f"bit number must be 0 for a completion flag (area code {address.area_code:02X}, "
            f"got {address.bit})"
        )


@dataclass(frozen=True, slots=True)
class ForcedSetResetEntry:
    """One bit/flag to force: the set/reset designation and the bit's address."""

    spec: ForceSpec
    address: MemoryAddress

    def __post_init__(self) -> None:
        try:
            object.__setattr__(self, "spec", ForceSpec(self.spec))
        except ValueError:
            raise CommandError(
                f"set/reset designation {self.spec!r} must be one of 0000, 0001, 8000, 8001, FFFF"
            ) from None
        if not isinstance(self.address, MemoryAddress):
            raise CommandError(f"address must be a MemoryAddress, got {self.address!r}")
        _check_address(self.address)

    def encode(self) -> bytes:
        return int(self.spec).to_bytes(2, "big") + self.address.encode()


@dataclass(frozen=True)
class ForcedSetReset(Request[None]):
    """23 01 FORCED SET/RESET: force bits ON/OFF or release their forced status."""

    MRC: ClassVar[int] = 0x23
    SRC: ClassVar[int] = 0x01
    NAME: ClassVar[str] = "FORCED SET/RESET"
    METHOD: ClassVar[str] = "forced_set_reset"

    entries: tuple[ForcedSetResetEntry, ...]

    def __post_init__(self) -> None:
        entries = tuple(self.entries)
        object.__setattr__(self, "entries", entries)
        check_range("number of bits/flags", len(entries), 1, MAX_ENTRIES)
        for entry in entries:
            if not isinstance(entry, ForcedSetResetEntry):
                raise CommandError(f"entries must be ForcedSetResetEntry, got {entry!r}")

    @classmethod
    def of(cls, *pairs: tuple[ForceSpec | int, MemoryAddress]) -> ForcedSetReset:
        """``ForcedSetReset.of((ForceSpec.FORCED_SET, addr), ...)``."""
        return cls(tuple(ForcedSetResetEntry(ForceSpec(spec), addr) for spec, addr in pairs))

    def encode(self) -> bytes:
        return len(self.entries).to_bytes(2, "big") + b"".join(e.encode() for e in self.entries)

    @classmethod
    def decode(cls, params: bytes) -> ForcedSetReset:
        r = Reader(params, cls.NAME)
        count = r.u16()
        if count == 0:
            raise DecodeError(f"{cls.NAME}: number of bits/flags is 0", end_code=0x110C)
        if r.remaining < count * ENTRY_SIZE:
            raise DecodeError(
                f"{cls.NAME}: {count} bits/flags need {count * ENTRY_SIZE} bytes, "
                f"got {r.remaining}",
                end_code=0x1002,
            )
        if r.remaining > count * ENTRY_SIZE:
            raise DecodeError(
                f"{cls.NAME}: {r.remaining - count * ENTRY_SIZE} byte(s) beyond {count} entries",
                end_code=0x1001,
            )
        if count > MAX_ENTRIES:
            raise DecodeError(f"{cls.NAME}: {count} entries exceed {MAX_ENTRIES}", end_code=0x1001)
        entries = []
        for _ in range(count):
            raw_spec = r.u16()
            try:
                spec = ForceSpec(raw_spec)
            except ValueError:
                raise DecodeError(
                    f"{cls.NAME}: unknown set/reset designation {raw_spec:04X}", end_code=0x110C
                ) from None
            address = MemoryAddress.decode(r.take(4))
            if address.area_code not in FORCEABLE_AREA_CODES:
                raise DecodeError(
                    f"{cls.NAME}: area code {address.area_code:02X} cannot be forced",
                    end_code=0x1101,
                )
            if address.bit > 15:
                raise DecodeError(
                    f"{cls.NAME}: bit number {address.bit} out of range 0..15", end_code=0x1103
                )
            entries.append(ForcedSetResetEntry(spec, address))
        return cls(tuple(entries))

    def decode_response(self, data: bytes) -> None:
        expect_no_data(self, data)


@dataclass(frozen=True)
class ForcedSetResetCancel(ParameterlessRequest):
    """23 02 FORCED SET/RESET CANCEL: release every forced bit/flag."""

    MRC: ClassVar[int] = 0x23
    SRC: ClassVar[int] = 0x02
    NAME: ClassVar[str] = "FORCED SET/RESET CANCEL"
    METHOD: ClassVar[str] = "forced_set_reset_cancel"


OPERATIONS: tuple[type[Request[Any]], ...] = (ForcedSetReset, ForcedSetResetCancel)
