"""Small pure helpers shared by the command codecs: a bounds-checked reader and BCD."""

from __future__ import annotations

from .errors import CommandError, DecodeError
from .inputs import shown


class Reader:
    """Reads big-endian fields from bytes; every short read raises :class:`DecodeError`.

    ``short_end_code`` is the FINS end code a server answers when a *command* is too short
    (``0x1002``); it rides on the raised error.
    """

    __slots__ = ("_data", "_pos", "_what")

    def __init__(self, data: bytes, what: str = "data") -> None:
        self._data = data
        self._pos = 0
        self._what = what

    @property
    def remaining(self) -> int:
        return len(self._data) - self._pos

    @property
    def position(self) -> int:
        return self._pos

    def _need(self, n: int) -> None:
        if self._pos + n > len(self._data):
            raise DecodeError(
                f"{self._what}: needs {n} more byte(s) at offset {self._pos}, "
                f"only {len(self._data) - self._pos} left",
                end_code=0x1002,
            )

    def take(self, n: int) -> bytes:
        self._need(n)
        out = self._data[self._pos : self._pos + n]
        self._pos += n
        return bytes(out)

    def u8(self) -> int:
        self._need(1)
        v = self._data[self._pos]
        self._pos += 1
        return v

    def u16(self) -> int:
        self._need(2)
        p = self._pos
        self._pos = p + 2
        return (self._data[p] << 8) | self._data[p + 1]

    def u24(self) -> int:
        self._need(3)
        v = int.from_bytes(self._data[self._pos : self._pos + 3], "big")
        self._pos += 3
        return v

    def u32(self) -> int:
        self._need(4)
        v = int.from_bytes(self._data[self._pos : self._pos + 4], "big")
        self._pos += 4
        return v

    def rest(self) -> bytes:
        out = bytes(self._data[self._pos :])
        self._pos = len(self._data)
        return out

    def end(self) -> None:
        """Require that everything was consumed (``0x1001`` *command too long* otherwise)."""
        if self._pos != len(self._data):
            raise DecodeError(
                f"{self._what}: {len(self._data) - self._pos} unexpected trailing byte(s)",
                end_code=0x1001,
            )


def check_range(name: str, value: int, low: int, high: int) -> None:
    """Raise :class:`CommandError` unless ``low <= value <= high``."""
    if not low <= value <= high:
        raise CommandError(f"{name} {shown(value)} out of range {low}..{high}")


def to_bcd(value: int, digits: int = 2) -> int:
    """``to_bcd(59) == 0x59``. Raises :class:`CommandError` if it does not fit."""
    if value < 0 or value >= 10**digits:
        raise CommandError(f"{shown(value)} does not fit in {digits} BCD digits")
    out = 0
    for shift in range(digits):
        out |= (value % 10) << (4 * shift)
        value //= 10
    return out


def from_bcd(value: int, digits: int = 2) -> int:
    """``from_bcd(0x59) == 59``. Raises :class:`DecodeError` on a non-decimal nibble."""
    out = 0
    for shift in reversed(range(digits)):
        nibble = (value >> (4 * shift)) & 0xF
        if nibble > 9:
            raise DecodeError(f"{value:0{digits}X} is not a valid {digits}-digit BCD value")
        out = out * 10 + nibble
    return out


def ascii_field(raw: bytes) -> str:
    """Decode a fixed-width ASCII field, dropping space and NUL padding on the right."""
    return raw.decode("ascii", "replace").rstrip(" \x00")


def pad_ascii(text: str, size: int, what: str = "text", pad: bytes = b" ") -> bytes:
    """Encode ``text`` as ASCII right-padded to ``size`` bytes (error if too long)."""
    try:
        raw = text.encode("ascii")
    except UnicodeEncodeError as exc:
        raise CommandError(f"{what} {text!r} is not ASCII") from exc
    if len(raw) > size:
        raise CommandError(f"{what} {text!r} is longer than {size} characters")
    return raw + pad * (size - len(raw))
