"""FINS end codes (manual 5-1-3): the whole table as data, and the flag bits.

The end code travels as two bytes, MRES and SRES::

    MRES: bit 7 relay error | bits 6-0 main code
    SRES: bit 7 fatal CPU error | bit 6 non-fatal CPU error | bits 5-0 sub code

``0x0040`` and ``0x0080`` are *normal completions* that carry a CPU error flag: the command
worked, and the PLC currently has a (non-)fatal error.
"""

from __future__ import annotations

from dataclasses import dataclass

RELAY_ERROR_FLAG = 0x8000
FATAL_CPU_ERROR_FLAG = 0x0080
NON_FATAL_CPU_ERROR_FLAG = 0x0040
END_CODE_MASK = 0x7F3F


@dataclass(frozen=True, slots=True)
class EndCodeCause:
    """One row of the manual's table: where to look, why, and what to do."""

    check_point: str
    cause: str
    correction: str


@dataclass(frozen=True, slots=True)
class EndCodeInfo:
    """The manual's description of one end code (main code + sub code)."""

    code: int
    main_name: str
    sub_name: str
    causes: tuple[EndCodeCause, ...]


# Filled in from manual 5-1-3 (every main/sub code). Keyed by the masked code, e.g. 0x1104.
END_CODES: dict[int, EndCodeInfo] = {}

MAIN_CODE_NAMES: dict[int, str] = {}


@dataclass(frozen=True, slots=True)
class EndCode:
    """A decoded end code: ``raw`` is the 16-bit word as received, flags included."""

    raw: int

    @classmethod
    def from_bytes(cls, mres: int, sres: int) -> EndCode:
        return cls((mres << 8) | sres)

    @property
    def code(self) -> int:
        """The end code with the flag bits masked off (``0x7F3F``)."""
        return self.raw & END_CODE_MASK

    @property
    def main(self) -> int:
        return (self.raw >> 8) & 0x7F

    @property
    def sub(self) -> int:
        return self.raw & 0x3F

    @property
    def relay_error(self) -> bool:
        """Bit 15: a relay point failed to forward the command (a 2-byte trailer follows)."""
        return bool(self.raw & RELAY_ERROR_FLAG)

    @property
    def fatal_cpu_error(self) -> bool:
        """Bit 7: the destination CPU Unit has a fatal error."""
        return bool(self.raw & FATAL_CPU_ERROR_FLAG)

    @property
    def non_fatal_cpu_error(self) -> bool:
        """Bit 6: the destination CPU Unit has a non-fatal error (e.g. battery)."""
        return bool(self.raw & NON_FATAL_CPU_ERROR_FLAG)

    @property
    def is_normal(self) -> bool:
        """True for a normal completion (``0000``, also with bit 6/7 flags set)."""
        return self.code == 0x0000 and not self.relay_error

    @property
    def info(self) -> EndCodeInfo | None:
        return END_CODES.get(self.code)

    @property
    def name(self) -> str:
        info = self.info
        if info is not None:
            return f"{info.main_name}: {info.sub_name}"
        main = MAIN_CODE_NAMES.get(self.main)
        return f"{main}: unknown sub code {self.sub:02X}" if main else "unknown end code"

    @property
    def cause(self) -> str:
        info = self.info
        return " / ".join(c.cause for c in info.causes if c.cause) if info else ""

    @property
    def correction(self) -> str:
        info = self.info
        return " / ".join(c.correction for c in info.causes if c.correction) if info else ""

    def __str__(self) -> str:
        flags = []
        if self.relay_error:
            flags.append("relay error")
        if self.fatal_cpu_error:
            flags.append("fatal CPU error")
        if self.non_fatal_cpu_error:
            flags.append("non-fatal CPU error")
        suffix = f" [{', '.join(flags)}]" if flags else ""
        return f"{self.code:04X} {self.name}{suffix}"


NORMAL = EndCode(0x0000)
