"""Codec helpers shared by the file memory command modules (:mod:`.file`,
:mod:`._file_manage`, :mod:`._file_transfer`)."""

from __future__ import annotations

from typing import ClassVar, TypeVar

from ..codec import Reader
from ._base import Request, expect_no_data

R = TypeVar("R")


class FileCommand(Request[R]):
    """A file memory command: MRC 22."""

    MRC: ClassVar[int] = 0x22


class FileOperation(FileCommand[None]):
    """A file memory command whose normal response carries no data."""

    def decode_response(self, data: bytes) -> None:
        expect_no_data(self, data)


def set_field(obj: object, name: str, value: object) -> None:
    """Set a field of a frozen dataclass from its ``__post_init__``."""
    object.__setattr__(obj, name, value)


def u16(value: int) -> bytes:
    return value.to_bytes(2, "big")


def u32(value: int) -> bytes:
    return value.to_bytes(4, "big")


def read_number(data: bytes, what: str, size: int = 2) -> int:
    """The one ``size``-byte number that makes up a response; :class:`DecodeError` if the
    data is shorter or longer."""
    r = Reader(data, what)
    value = r.u32() if size == 4 else r.u16()
    r.end()
    return value
