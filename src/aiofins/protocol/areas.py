"""I/O memory area codes, element sizes and ranges (manual 5-2-2), CS/CJ/CP/NSJ and CV mode.

A :class:`MemoryAddress` is the 4-byte designation on the wire: area code, word, bit.
"""

from __future__ import annotations

from dataclasses import dataclass

from .errors import AddressError, DecodeError

# Bytes per element by memory area code, CS/CJ and CV codes together (they never
# disagree where they overlap: 0x82 and 0x98 are words in both).
_ELEMENT_SIZE: dict[int, int] = {}
for _code in (
    0x30,
    0x31,
    0x32,
    0x33,
    0x70,
    0x71,
    0x72,
    0x09,
    0x49,
    0x02,
    0x0A,
    0x06,
    0x46,
    0x07,
    *range(0x20, 0x30),
    *range(0xE0, 0xE9),
    0x00,
    0x40,
    0x01,
    0x41,
):  # CV: bit, bit+forced, completion flag (+forced)
    _ELEMENT_SIZE[_code] = 1
for _code in (
    0xB0,
    0xB1,
    0xB2,
    0xB3,
    0x89,
    0x82,
    0x98,
    0xBC,
    *range(0xA0, 0xB0),
    *range(0x50, 0x60),
    *range(0x60, 0x69),
    0x80,
    0x81,
    *range(0x90, 0x98),
    0x9C,
):  # CV: word, PV, EM banks, registers
    _ELEMENT_SIZE[_code] = 2
for _code in (0xF0, 0xF1, 0xF2, 0xDC, 0xC0):
    _ELEMENT_SIZE[_code] = 4


def element_size(area_code: int) -> int:
    """Bytes per element for ``area_code``; :class:`AddressError` if the code is unknown."""
    try:
        return _ELEMENT_SIZE[area_code]
    except KeyError:
        raise AddressError(f"unknown memory area code {area_code:02X}") from None


def is_known_area_code(area_code: int) -> bool:
    return area_code in _ELEMENT_SIZE


@dataclass(frozen=True, slots=True)
class MemoryAddress:
    """An I/O memory designation: area code (1 byte), word (2 bytes), bit (1 byte).

    ``str()`` gives the canonical address text when the designation came from the parser
    (``text``); otherwise a hex form such as ``82:0064.00``.
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
        return element_size(self.area_code)

    def encode(self) -> bytes:
        return bytes((self.area_code, self.word >> 8, self.word & 0xFF, self.bit))

    @classmethod
    def decode(cls, raw: bytes) -> MemoryAddress:
        if len(raw) != 4:
            raise DecodeError(f"memory address needs 4 bytes, got {len(raw)}", end_code=0x1002)
        return cls(raw[0], (raw[1] << 8) | raw[2], raw[3])

    def __str__(self) -> str:
        return f"{self.area_code:02X}:{self.word:04X}.{self.bit:02X}"
