"""I/O memory area access, 01 01 .. 01 05 (manual 5-3-2 .. 5-3-6).

Addresses are :class:`~aiofins.protocol.areas.MemoryAddress` values; the element size of the
area code decides the data layout (bit 1 byte ``00``/``01``, word 2 bytes, word with forced
status / IR 4 bytes). Limits are those of a 2012-byte frame (Ethernet, Controller Link); slower
networks (SYSMAC LINK, DeviceNet, Host Link: 269 / 267 words, 89 elements for 01 04) are the
chunking layer's business.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

from ..areas import MemoryAddress, element_size
from ..codec import Reader
from ..decoding import as_decode_error
from ..errors import AddressError, CommandError, DecodeError
from ..header import MAX_PARAMETER_SIZE, MAX_RESPONSE_DATA_SIZE
from ..inputs import shown
from ..wordcodec import pack_elements, unpack_elements
from ._base import (
    Request,
    _decode_fields,
    expect_no_data,
)

#: 01 01: elements per command on a 2012-byte frame (manual 5-2-2 table, Ethernet/CLK).
MAX_READ_ELEMENTS = 999
#: 01 02: elements per command on a 2012-byte frame.
MAX_WRITE_ELEMENTS = 997
#: 01 04: elements per command on Ethernet / Controller Link (89 on SYSMAC LINK, DeviceNet).
MAX_MULTIPLE_READ_ELEMENTS = 167
#: Response data bytes after the end code in a 2012-byte frame.
MAX_RESPONSE_DATA = MAX_RESPONSE_DATA_SIZE
#: Command parameter bytes after MRC/SRC in a 2012-byte frame.
MAX_COMMAND_PARAMS = MAX_PARAMETER_SIZE

# Area codes 01 02 cannot write (manual 5-3-3 table): forced-status views, completion flags,
# task flags, clock pulses / condition flags (CS/CJ and CV codes), and CV bits (00: "---").
_NOT_WRITABLE = frozenset(
    (0x70, 0x71, 0x72, 0xF0, 0xF1, 0xF2, 0x09, 0x49, 0x06, 0x46, 0x07, 0x40, 0xC0, 0x01, 0x41, 0x00)
)
# Forced-status designations: read by 01 04 only (its table lists them; 01 01's does not).
_FORCED_STATUS = frozenset((0x70, 0x71, 0x72, 0xF0, 0xF1, 0xF2, 0x49, 0x40, 0xC0, 0x41))
# The EM current bank number word, under the DR area code (CS/CJ BC 0F00, CV 9C 0006): read
# by 01 01 and 01 04, absent from 01 02's table (manual 5-3-2, 5-3-3, 5-3-5).
_BANK_NUMBER_WORD = {0xBC: 0x0F00, 0x9C: 0x0006}
# One-byte codes whose bit byte is always 00 (manual 5-2-1: completion flags; 5-2-2: task
# flags, clock pulses / condition flags are addressed by word with bit 00).
_BIT_ALWAYS_ZERO = frozenset({0x09, 0x49, 0x01, 0x41, 0x06, 0x46, 0x07})
# Two-byte codes that are not plain word areas (EM current bank no. / DR), refused by
# 01 03 and 01 05 (manual 5-3-4, 5-3-6 tables).
_NOT_WORD_AREA = frozenset({0xBC, 0x9C})


def _read_address(r: Reader) -> MemoryAddress:
    return MemoryAddress.decode(r.take(4))


def _size_of(address: MemoryAddress) -> int:
    try:
        return element_size(address.area_code)
    except AddressError as exc:
        raise AddressError(str(exc), end_code=0x1101) from None


def _check_address(address: MemoryAddress, what: str = "address") -> int:
    """Check the area code is known and the bit fits its element type; return the size."""
    if not isinstance(address, MemoryAddress):
        raise CommandError(f"{what} must be a MemoryAddress, got {type(address).__name__}")
    size = _size_of(address)
    if size == 1 and address.bit > 0x0F:
        raise AddressError(
            f"{what} {address}: bit number {address.bit} out of range 0..15", end_code=0x1103
        )
    if (size != 1 or address.area_code in _BIT_ALWAYS_ZERO) and address.bit != 0:
        raise AddressError(
            f"{what} {address}: bit number must be 0 for area code {address.area_code:02X} "
            f"(got {address.bit})",
            end_code=0x1103,
        )
    return size


def _check_writable(address: MemoryAddress, what: str = "address") -> int:
    size = _check_address(address, what)
    if address.area_code in _NOT_WRITABLE:
        raise AddressError(
            f"{what} {address}: memory area code {address.area_code:02X} cannot be written",
            end_code=0x1101,
        )
    return size


def _check_word_area(address: MemoryAddress, what: str) -> None:
    size = _check_writable(address, what)
    if size != 2 or address.area_code in _NOT_WORD_AREA:
        raise AddressError(
            f"{what} {address}: memory area code {address.area_code:02X} is not a word area",
            end_code=0x1101,
        )


def _check_count(name: str, value: int, high: int, end_code: int) -> None:
    if not isinstance(value, int) or not 0 <= value <= high:
        raise CommandError(f"{name} {shown(value)} out of range 0..{high}", end_code=end_code)


def _element_values(data: bytes, size: int) -> tuple[int, ...]:
    return unpack_elements(data, size)


def _element_bytes(values: Iterable[int], size: int, what: str) -> bytes:
    if not isinstance(values, Sequence):
        values = list(values)
    packed = pack_elements(values, size)
    if packed is not None:
        return packed
    out = bytearray()  # one by one, to name the value that is wrong
    limit = (1 << (8 * size)) - 1
    for value in values:
        if not isinstance(value, int) or not 0 <= value <= limit:
            raise CommandError(f"{what} value {shown(value)} out of range 0..{limit}")
        out += value.to_bytes(size, "big")
    return bytes(out)


def _check_bit_data(address: MemoryAddress, data: bytes, size: int) -> None:
    """Bit data (1-byte elements of a writable area) must be 00 or 01."""
    if size == 1 and data and max(data) > 1:
        for index, byte in enumerate(data):
            if byte > 1:
                raise CommandError(
                    f"bit value {byte} at element {index} of {address} out of range 0..1",
                    end_code=0x110C,
                )


@dataclass(frozen=True, slots=True)
class MemoryAreaReadResult:
    """Data of 01 01: ``count`` elements of ``element_size`` bytes each."""

    data: bytes
    element_size: int

    def __post_init__(self) -> None:
        object.__setattr__(self, "data", bytes(self.data))
        if self.element_size not in (1, 2, 4):
            raise CommandError(f"element size {self.element_size} not one of 1, 2, 4")
        if len(self.data) % self.element_size:
            raise CommandError(
                f"{len(self.data)} data bytes are not a multiple of the element size "
                f"{self.element_size}"
            )

    @classmethod
    def from_values(cls, values: Iterable[int], element_size: int) -> MemoryAreaReadResult:
        """Build from element values (bits 0/1, words 0..FFFF, 4-byte elements 0..FFFFFFFF)."""
        return cls(_element_bytes(values, element_size, "element"), element_size)

    @property
    def count(self) -> int:
        return len(self.data) // self.element_size

    @property
    def values(self) -> tuple[int, ...]:
        """One unsigned big-endian integer per element.

        For a word with forced status (4 bytes) the high 16 bits are the forced mask and the
        low 16 bits the value; a bit with forced status has the value in bit 0, forced in bit 1.
        """
        return _element_values(self.data, self.element_size)

    def encode(self) -> bytes:
        return self.data


@dataclass(frozen=True)
class MemoryAreaRead(Request[MemoryAreaReadResult]):
    """01 01: read ``count`` consecutive elements starting at ``address``."""

    MRC: ClassVar[int] = 0x01
    SRC: ClassVar[int] = 0x01
    NAME: ClassVar[str] = "MEMORY AREA READ"
    METHOD: ClassVar[str] = "memory_area_read"
    IDEMPOTENT: ClassVar[bool] = True

    address: MemoryAddress
    count: int

    def __post_init__(self) -> None:
        size = _check_address(self.address)
        if self.address.area_code in _FORCED_STATUS:
            raise AddressError(
                f"{self.address}: forced status (area code {self.address.area_code:02X}) is "
                "read with MULTIPLE MEMORY AREA READ (01 04, multiple_memory_area_read), not "
                "01 01",
                end_code=0x1101,
            )
        _check_count("number of elements", self.count, MAX_READ_ELEMENTS, 0x110B)
        if self.count * size > MAX_RESPONSE_DATA:
            raise CommandError(
                f"{self.count} elements of {size} bytes exceed the {MAX_RESPONSE_DATA}-byte "
                f"response: number of elements out of range 0..{MAX_RESPONSE_DATA // size}",
                end_code=0x110B,
            )

    @property
    def element_size(self) -> int:
        return element_size(self.address.area_code)

    def encode(self) -> bytes:
        return self.address.encode() + self.count.to_bytes(2, "big")

    @classmethod
    def decode(cls, params: bytes) -> MemoryAreaRead:
        return _decode_fields(cls, params, _read_address, Reader.u16)

    def decode_response(self, data: bytes) -> MemoryAreaReadResult:
        size = self.element_size
        if len(data) != self.count * size:
            raise DecodeError(
                f"{self.NAME}: expected {self.count} x {size} = {self.count * size} data "
                f"bytes, got {len(data)}"
            )
        return MemoryAreaReadResult(data, size)


@dataclass(frozen=True)
class MemoryAreaWrite(Request[None]):
    """01 02: write ``data`` (whole elements of the area's size) starting at ``address``.

    Bit areas take one byte per bit, ``00`` or ``01``. The number of elements is derived from
    the data length.
    """

    MRC: ClassVar[int] = 0x01
    SRC: ClassVar[int] = 0x02
    NAME: ClassVar[str] = "MEMORY AREA WRITE"
    METHOD: ClassVar[str] = "memory_area_write"

    address: MemoryAddress
    data: bytes

    def __post_init__(self) -> None:
        if not isinstance(self.data, (bytes, bytearray, memoryview)):
            raise CommandError(f"data must be bytes, got {type(self.data).__name__}")
        object.__setattr__(self, "data", bytes(self.data))
        size = _check_writable(self.address)
        if len(self.data) % size:
            raise CommandError(
                f"{len(self.data)} data bytes are not a multiple of the element size {size} "
                f"of area {self.address.area_code:02X}",
                end_code=0x1003,
            )
        count = len(self.data) // size
        high = min(MAX_WRITE_ELEMENTS, (MAX_COMMAND_PARAMS - 6) // size)
        _check_count("number of elements", count, high, 0x1001)
        _check_bit_data(self.address, self.data, size)
        bank_word = _BANK_NUMBER_WORD.get(self.address.area_code)
        if bank_word is not None and self.address.word <= bank_word < self.address.word + count:
            raise AddressError(
                f"{self.address}: the EM current bank number (area {self.address.area_code:02X} "
                f"word {bank_word:04X}) cannot be written with 01 02",
                end_code=0x1101,
            )

    @classmethod
    def from_values(cls, address: MemoryAddress, values: Iterable[int]) -> MemoryAreaWrite:
        """Build from element values: bits 0/1, words 0..FFFF, 4-byte elements 0..FFFFFFFF."""
        size = _check_writable(address)
        return cls(address, _element_bytes(values, size, "element"))

    @property
    def element_size(self) -> int:
        return element_size(self.address.area_code)

    @property
    def count(self) -> int:
        return len(self.data) // self.element_size

    @property
    def values(self) -> tuple[int, ...]:
        return _element_values(self.data, self.element_size)

    def encode(self) -> bytes:
        return self.address.encode() + self.count.to_bytes(2, "big") + self.data

    @classmethod
    def decode(cls, params: bytes) -> MemoryAreaWrite:
        r = Reader(params, cls.NAME)
        address = _read_address(r)
        count = r.u16()
        data = r.rest()
        with as_decode_error(cls.NAME):
            size = _check_writable(address)
        if count * size != len(data):
            raise DecodeError(
                f"{cls.NAME}: {count} elements of {size} bytes need {count * size} data "
                f"bytes, got {len(data)}",
                end_code=0x1003,
            )
        with as_decode_error(cls.NAME):
            return cls(address, data)

    def decode_response(self, data: bytes) -> None:
        expect_no_data(self, data)


@dataclass(frozen=True)
class MemoryAreaFill(Request[None]):
    """01 03: write ``value`` to ``count`` consecutive words starting at ``address``."""

    MRC: ClassVar[int] = 0x01
    SRC: ClassVar[int] = 0x03
    NAME: ClassVar[str] = "MEMORY AREA FILL"
    METHOD: ClassVar[str] = "memory_area_fill"

    address: MemoryAddress
    count: int
    value: int

    def __post_init__(self) -> None:
        _check_word_area(self.address, "address")
        _check_count("number of elements", self.count, 0xFFFF, 0x110C)
        _check_count("fill value", self.value, 0xFFFF, 0x110C)

    def encode(self) -> bytes:
        return self.address.encode() + self.count.to_bytes(2, "big") + self.value.to_bytes(2, "big")

    @classmethod
    def decode(cls, params: bytes) -> MemoryAreaFill:
        return _decode_fields(cls, params, _read_address, Reader.u16, Reader.u16)

    def decode_response(self, data: bytes) -> None:
        expect_no_data(self, data)


@dataclass(frozen=True, slots=True)
class MultipleMemoryAreaReadItem:
    """One element of a 01 04 response: the echoed area code and the element's value."""

    area_code: int
    value: int

    def __post_init__(self) -> None:
        size = element_size(self.area_code)  # AddressError for an unknown code
        limit = (1 << (8 * size)) - 1
        if not isinstance(self.value, int) or not 0 <= self.value <= limit:
            raise CommandError(
                f"value {shown(self.value)} of area {self.area_code:02X} out of range 0..{limit}"
            )

    @property
    def element_size(self) -> int:
        return element_size(self.area_code)

    def encode(self) -> bytes:
        return bytes((self.area_code,)) + self.value.to_bytes(self.element_size, "big")


@dataclass(frozen=True, slots=True)
class MultipleMemoryAreaReadResult:
    """Data of 01 04: one item per requested address, in request order."""

    items: tuple[MultipleMemoryAreaReadItem, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "items", tuple(self.items))

    @property
    def values(self) -> tuple[int, ...]:
        return tuple(item.value for item in self.items)

    def encode(self) -> bytes:
        return b"".join(item.encode() for item in self.items)


@dataclass(frozen=True)
class MultipleMemoryAreaRead(Request[MultipleMemoryAreaReadResult]):
    """01 04: read single elements at up to 167 non-consecutive addresses.

    The manual's limit is 167 elements on Ethernet / Controller Link and 89 on SYSMAC LINK /
    DeviceNet; the codec enforces 167. No addresses at all is a valid no-op command.
    """

    MRC: ClassVar[int] = 0x01
    SRC: ClassVar[int] = 0x04
    NAME: ClassVar[str] = "MULTIPLE MEMORY AREA READ"
    METHOD: ClassVar[str] = "multiple_memory_area_read"
    IDEMPOTENT: ClassVar[bool] = True

    addresses: tuple[MemoryAddress, ...]

    def __post_init__(self) -> None:
        if isinstance(self.addresses, MemoryAddress):
            raise CommandError("addresses must be a sequence of MemoryAddress, got one address")
        object.__setattr__(self, "addresses", tuple(self.addresses))
        _check_count("number of elements", len(self.addresses), MAX_MULTIPLE_READ_ELEMENTS, 0x1001)
        for index, address in enumerate(self.addresses):
            _check_address(address, f"address {index}")

    def encode(self) -> bytes:
        return b"".join(address.encode() for address in self.addresses)

    @classmethod
    def decode(cls, params: bytes) -> MultipleMemoryAreaRead:
        r = Reader(params, cls.NAME)
        addresses: list[MemoryAddress] = []
        while r.remaining:
            addresses.append(MemoryAddress.decode(r.take(min(4, r.remaining))))
        with as_decode_error(cls.NAME):
            return cls(tuple(addresses))

    def decode_response(self, data: bytes) -> MultipleMemoryAreaReadResult:
        r = Reader(data, f"{self.NAME} response")
        items: list[MultipleMemoryAreaReadItem] = []
        while r.remaining:
            code = r.u8()
            try:
                size = element_size(code)
            except AddressError as exc:
                raise DecodeError(f"{self.NAME}: response item {len(items)}: {exc}") from None
            value = int.from_bytes(r.take(size), "big")
            items.append(MultipleMemoryAreaReadItem(code, value))
        if len(items) != len(self.addresses):
            raise DecodeError(
                f"{self.NAME}: expected {len(self.addresses)} items, got {len(items)}"
            )
        return MultipleMemoryAreaReadResult(tuple(items))


@dataclass(frozen=True)
class MemoryAreaTransfer(Request[None]):
    """01 05: copy ``count`` words from ``source`` to ``destination``."""

    MRC: ClassVar[int] = 0x01
    SRC: ClassVar[int] = 0x05
    NAME: ClassVar[str] = "MEMORY AREA TRANSFER"
    METHOD: ClassVar[str] = "memory_area_transfer"

    source: MemoryAddress
    destination: MemoryAddress
    count: int

    def __post_init__(self) -> None:
        _check_word_area(self.source, "source")
        _check_word_area(self.destination, "destination")
        _check_count("number of elements", self.count, 0xFFFF, 0x110C)

    def encode(self) -> bytes:
        return self.source.encode() + self.destination.encode() + self.count.to_bytes(2, "big")

    @classmethod
    def decode(cls, params: bytes) -> MemoryAreaTransfer:
        return _decode_fields(cls, params, _read_address, _read_address, Reader.u16)

    def decode_response(self, data: bytes) -> None:
        expect_no_data(self, data)


OPERATIONS: tuple[type[Request[Any]], ...] = (
    MemoryAreaRead,
    MemoryAreaWrite,
    MemoryAreaFill,
    MultipleMemoryAreaRead,
    MemoryAreaTransfer,
)
