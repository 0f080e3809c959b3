"""Operating mode changes, 04 01 RUN and 04 02 STOP (manual 5-3-13, 5-3-14).

Both carry the program number ``FFFF``; the manual lets a sender omit it (and RUN's mode
byte), so the server side accepts the short forms: RUN alone means MONITOR mode.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Any, ClassVar

from ..codec import Reader
from ._base import Request, _member, expect_no_data, finish
from .program import PROGRAM_NUMBER, _read_program_number


# manual wins: CV's 01 DEBUG mode (wire-format notes) is not a CS/CJ mode (manual 5-3-13).
class RunMode(IntEnum):
    """The mode byte of 04 01 RUN."""

    #: Run the program; online changes allowed.
    MONITOR = 0x02
    #: Run the program; online changes refused.
    RUN = 0x04


def _program_number(r: Reader, name: str) -> None:
    """Read the optional program number (absent, or exactly ``FFFF``)."""
    if r.remaining:
        _read_program_number(r, name)


@dataclass(frozen=True)
class Run(Request[None]):
    """04 01: change to MONITOR (the manual's default) or RUN mode."""

    MRC: ClassVar[int] = 0x04
    SRC: ClassVar[int] = 0x01
    NAME: ClassVar[str] = "RUN"
    METHOD: ClassVar[str] = "run"

    mode: int = RunMode.MONITOR

    def __post_init__(self) -> None:
        mode = _member(RunMode, self.mode, "mode", "02 (MONITOR), 04 (RUN)")
        object.__setattr__(self, "mode", mode)

    def encode(self) -> bytes:
        return PROGRAM_NUMBER.to_bytes(2, "big") + bytes((self.mode,))

    @classmethod
    def decode(cls, params: bytes) -> Run:
        r = Reader(params, cls.NAME)
        _program_number(r, cls.NAME)
        return finish(cls, r, r.u8() if r.remaining else RunMode.MONITOR)

    def decode_response(self, data: bytes) -> None:
        expect_no_data(self, data)


@dataclass(frozen=True)
class Stop(Request[None]):
    """04 02: change to PROGRAM mode."""

    MRC: ClassVar[int] = 0x04
    SRC: ClassVar[int] = 0x02
    NAME: ClassVar[str] = "STOP"
    METHOD: ClassVar[str] = "stop"

    def encode(self) -> bytes:
        return PROGRAM_NUMBER.to_bytes(2, "big")

    @classmethod
    def decode(cls, params: bytes) -> Stop:
        r = Reader(params, cls.NAME)
        _program_number(r, cls.NAME)
        r.end()
        return cls()

    def decode_response(self, data: bytes) -> None:
        expect_no_data(self, data)


OPERATIONS: tuple[type[Request[Any]], ...] = (Run, Stop)
