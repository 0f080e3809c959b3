"""Access rights (manual 5-3-24..5-3-26): 0C 01 ACQUIRE, 0C 02 FORCED ACQUIRE, 0C 03 RELEASE.

Each command carries a program number: always ``FFFF`` on CS/CJ (CV-series used ``0000``).
When another device holds the access right, 0C 01 fails with end code 3001 and the response
names the holder: network, node and unit address, one byte each.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, TypeVar

from ..codec import Reader, check_range
from ._base import R, Request, _decode_fields, expect_no_data
from .program import PROGRAM_NUMBER


@dataclass(frozen=True, slots=True)
class AccessRightHolder:
    """The device holding the access right (data after end code 3001 of 0C 01)."""

    network: int
    node: int
    unit: int

    def __post_init__(self) -> None:
        check_range("network address", self.network, 0, 0xFF)
        check_range("node address", self.node, 0, 0xFF)
        check_range("unit address", self.unit, 0, 0xFF)

    def encode(self) -> bytes:
        return bytes((self.network, self.node, self.unit))

    @classmethod
    def decode(cls, data: bytes) -> AccessRightHolder:
        r = Reader(data, "access right holder")
        out = cls(r.u8(), r.u8(), r.u8())
        r.end()
        return out


_AccessT = TypeVar("_AccessT", bound="_AccessRightRequest[Any]")


@dataclass(frozen=True)
class _AccessRightRequest(Request[R]):
    """The parameters all three access right commands share: the program number."""

    program_number: int = PROGRAM_NUMBER

    def __post_init__(self) -> None:
        check_range("program number", self.program_number, 0, 0xFFFF)

    def encode(self) -> bytes:
        return self.program_number.to_bytes(2, "big")

    @classmethod
    def decode(cls: type[_AccessT], params: bytes) -> _AccessT:
        return _decode_fields(cls, params, Reader.u16)


@dataclass(frozen=True)
class AccessRightAcquire(_AccessRightRequest["AccessRightHolder | None"]):
    """0C 01 ACCESS RIGHT ACQUIRE: take the access right unless another device holds it.

    A normal response carries no data (``None``). With end code 3001 the response data
    names the holder; :meth:`decode_response` parses it as :class:`AccessRightHolder` when
    the caller hands it such data (the session raises ``AccessRightError`` with ``holder``).
    """

    MRC: ClassVar[int] = 0x0C
    SRC: ClassVar[int] = 0x01
    NAME: ClassVar[str] = "ACCESS RIGHT ACQUIRE"
    METHOD: ClassVar[str] = "access_right_acquire"

    def decode_response(self, data: bytes) -> AccessRightHolder | None:
        if not data:
            return None
        return AccessRightHolder.decode(data)


@dataclass(frozen=True)
class AccessRightForcedAcquire(_AccessRightRequest[None]):
    """0C 02 ACCESS RIGHT FORCED ACQUIRE: take the access right even from another holder."""

    MRC: ClassVar[int] = 0x0C
    SRC: ClassVar[int] = 0x02
    NAME: ClassVar[str] = "ACCESS RIGHT FORCED ACQUIRE"
    METHOD: ClassVar[str] = "access_right_forced_acquire"

    def decode_response(self, data: bytes) -> None:
        expect_no_data(self, data)


@dataclass(frozen=True)
class AccessRightRelease(_AccessRightRequest[None]):
    """0C 03 ACCESS RIGHT RELEASE: release the access right, whoever holds it."""

    MRC: ClassVar[int] = 0x0C
    SRC: ClassVar[int] = 0x03
    NAME: ClassVar[str] = "ACCESS RIGHT RELEASE"
    METHOD: ClassVar[str] = "access_right_release"

    def decode_response(self, data: bytes) -> None:
        expect_no_data(self, data)


OPERATIONS: tuple[type[Request[Any]], ...] = (
    AccessRightAcquire,
    AccessRightForcedAcquire,
    AccessRightRelease,
)
