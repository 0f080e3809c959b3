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

from typing import Any, ClassVar, Generic, Protocol, TypeVar

from ..errors import DecodeError

R = TypeVar("R")
Q = TypeVar("Q", bound="Request[Any]")


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
