"""The shape every FINS operation's codec follows.

An operation is a frozen dataclass subclassing :class:`Request`. It knows

* its command code (``MRC``/``SRC``), manual name and client method name;
* how to encode its parameters (``encode``) and decode them back (``decode``, used by the
  virtual PLC; a malformed parameter block raises :class:`DecodeError` whose ``end_code`` is
  what a PLC would answer, e.g. ``0x1002`` command too short);
* how to decode the response data that follows the end code (``decode_response``) into an
  immutable, typed result. Result types have ``encode()`` so that a server (the simulator)
  can produce the same bytes; operations whose response carries no data use ``None``.

Builders validate their arguments in ``__post_init__`` and raise :class:`CommandError` (or
:class:`AddressError`) before anything is sent.
"""

from __future__ import annotations

from collections.abc import Callable
from enum import IntEnum
from typing import Any, ClassVar, Generic, Protocol, TypeVar

from ..codec import Reader
from ..decoding import as_decode_error
from ..errors import CommandError, DecodeError

R = TypeVar("R")
Q = TypeVar("Q", bound="Request[Any]")
E = TypeVar("E", bound=IntEnum)


class Encodable(Protocol):
    def encode(self) -> bytes: ...


class Request(Generic[R]):
    """Base of every operation's request. Subclasses are ``@dataclass(frozen=True)``."""

    MRC: ClassVar[int]
    SRC: ClassVar[int]
    #: The manual's name, e.g. ``"MEMORY AREA READ"``.
    NAME: ClassVar[str]
    #: The client method name, e.g. ``"memory_area_read"``.
    METHOD: ClassVar[str]
    #: Safe to send twice (reads): the session retries these by default.
    IDEMPOTENT: ClassVar[bool] = False

    @classmethod
    def command_code(cls) -> int:
        return (cls.MRC << 8) | cls.SRC

    @classmethod
    def matches(cls, params: bytes) -> bool:
        """Whether ``params`` belong to this operation (only 09 20 has several)."""
        return True

    def encode(self) -> bytes:
        """The parameter bytes that follow MRC/SRC."""
        raise NotImplementedError

    @classmethod
    def decode(cls: type[Q], params: bytes) -> Q:
        """Parse parameter bytes (server side). Raises :class:`DecodeError`."""
        raise NotImplementedError

    def decode_response(self, data: bytes) -> R:
        """Parse the response data that follows the end code."""
        raise NotImplementedError


def expect_no_data(request: Request[Any], data: bytes) -> None:
    """For operations whose normal response carries no data."""
    if data:
        raise DecodeError(f"{request.NAME}: expected no response data, got {len(data)} bytes")


def encode_result(result: Encodable | None) -> bytes:
    """Response data bytes of a result (``None`` → no data)."""
    return b"" if result is None else result.encode()


class NoParameters(Request[R]):
    """Base of operations whose command carries no parameters (e.g. 07 01 CLOCK READ)."""

    def encode(self) -> bytes:
        return b""

    @classmethod
    def decode(cls: type[Q], params: bytes) -> Q:
        Reader(params, cls.NAME).end()
        return cls()


class ParameterlessRequest(NoParameters[None]):
    """Base of operations with no parameters and no response data (e.g. the log clears)."""

    def decode_response(self, data: bytes) -> None:
        expect_no_data(self, data)


def finish(cls: type[Q], r: Reader, *args: Any, **kwargs: Any) -> Q:
    """End of a command's decoding: no bytes may follow (end code 1001), then build
    ``cls(*args, **kwargs)`` with invalid values turned into :class:`DecodeError` (110C).

    The arguments are read from ``r`` in the order they are written, e.g.
    ``finish(cls, r, read_disk(r), read_directory(r))``.
    """
    r.end()
    make: Callable[..., Q] = cls
    with as_decode_error(cls.NAME):
        return make(*args, **kwargs)


def _decode_fields(op: type[Q], params: bytes, *fields: Callable[[Reader], Any]) -> Q:
    """Read ``fields`` in order from all of ``params`` and build ``op`` from the values.

    Short or long parameters raise :class:`DecodeError` (1002 / 1001); argument errors of the
    builder become :class:`DecodeError` (see :func:`.as_decode_error`).
    """
    r = Reader(params, op.NAME)
    return finish(op, r, *[read(r) for read in fields])


def _member(kind: type[E], value: int, what: str, choices: str) -> E:
    """``kind(value)``; a value not in ``kind`` is rejected with end code 110C."""
    try:
        return kind(value)
    except ValueError:
        raise CommandError(f"{what} {value!r} not one of {choices}", end_code=0x110C) from None
