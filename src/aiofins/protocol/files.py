"""File-memory data shared by the 22xx commands (manual 5-2-3 and 5-3-32..5-3-43).

* **Disk numbers**: ``8000`` memory card, ``8001`` EM file memory, ``8003`` the Memory
  Cassette of a CP-series CPU Unit (2220 only).
* **File names** (also directory names and volume labels) are 12 bytes: an 8-character name
  and a 3-character extension, each left-aligned and padded with spaces (20 hex), separated by
  a period (2E hex). Without an extension the period and the extension are spaces:
  ``"ASCII.DAT"`` → ``ASCII   .DAT``; ``"DATA"`` → ``DATA        ``.
* **File date/time**: 4 bytes, binary, MS-DOS layout (year since 1980, month, day, hour,
  minute, seconds / 2).
* **Directory**: length (2 bytes, 0 = root, at most 65) then the absolute path, starting with
  ``\\``, no drive letter, no trailing ``\\``.

Also here: the parameter codes of 2203/220A-220C/2215/2220 and the 2201 result types
(:class:`DiskData`, :class:`FileEntry`, :class:`FileNameReadResult`).
"""

from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass
from enum import IntEnum, IntFlag
from typing import TypeVar

from .codec import Reader
from .decoding import PARAMETER_ERROR, as_decode_error
from .errors import CommandError, DecodeError

FILE_NAME_SIZE = 12
FILE_DATE_SIZE = 4
#: Longest absolute directory path (characters).
MAX_DIRECTORY_LENGTH = 65


class Disk(IntEnum):
    """Disk number: the file memory a command works on."""

    #: The Memory Card in the CPU Unit.
    MEMORY_CARD = 0x8000
    #: EM banks formatted as file memory.
    EM_FILE_MEMORY = 0x8001
    #: CP-series Memory Cassette (2220 MEMORY CASSETTE TRANSFER only).
    MEMORY_CASSETTE = 0x8003


#: Disks the 2201..2215 commands accept.
FILE_DISKS: frozenset[Disk] = frozenset({Disk.MEMORY_CARD, Disk.EM_FILE_MEMORY})


class FileAttribute(IntFlag):
    """Attribute bits of a file entry (2201); the first byte of the field is reserved."""

    READ_ONLY = 0x01
    HIDDEN = 0x02
    SYSTEM = 0x04
    VOLUME_LABEL = 0x08
    DIRECTORY = 0x10
    ARCHIVE = 0x20


NO_ATTRIBUTES = FileAttribute(0)


# --------------------------------------------------------------------------- disks


def check_disk(value: int, allowed: frozenset[Disk] = FILE_DISKS, what: str = "disk") -> Disk:
    """``value`` as a :class:`Disk` if it is one of ``allowed``; :class:`CommandError` if not."""
    try:
        disk = Disk(value)
    except ValueError:
        disk = None
    if disk is None or disk not in allowed:
        names = ", ".join(f"{d:04X} ({d.name})" for d in sorted(allowed))
        raise CommandError(f"{what} number {value:#06x} is not one of {names}")
    return disk


def read_disk(reader: Reader, allowed: frozenset[Disk] = FILE_DISKS) -> Disk:
    """Read a disk number; :class:`DecodeError` (``110C``) unless it is one of ``allowed``."""
    value = reader.u16()
    with as_decode_error("disk"):
        return check_disk(value, allowed)


# --------------------------------------------------------------------------- file names

_NAME_CHARS = frozenset(
    "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789!#$%&'()-@^_`{}~"
)


def check_file_name(name: str, what: str = "file name") -> str:
    """Validate an 8.3 name given in a command; returns it unchanged.

    Name 1-8 characters, optional extension 1-3 characters; letters, digits and
    ``! # $ % & ' ( ) - @ ^ _ ` { } ~``; must not start with ``~~`` (manual 5-2-3).
    """
    if not isinstance(name, str):
        raise CommandError(f"{what} must be a str, got {type(name).__name__}")
    base, dot, ext = name.partition(".")
    if "." in ext:
        raise CommandError(f"{what} {name!r} has more than one '.'")
    if not base or len(base) > 8:
        raise CommandError(f"{what} {name!r}: the name part must be 1 to 8 characters")
    if dot and not 1 <= len(ext) <= 3:
        raise CommandError(f"{what} {name!r}: the extension must be 1 to 3 characters")
    bad = sorted({c for c in base + ext if c not in _NAME_CHARS})
    if bad:
        raise CommandError(f"{what} {name!r}: invalid character(s) {''.join(bad)!r}")
    if base.startswith("~~"):
        raise CommandError(f"{what} {name!r} must not start with '~~'")
    return name


def _layout(base: str, ext: str) -> bytes:
    period = "." if ext else " "
    return (base.ljust(8) + period + ext.ljust(3)).encode("latin-1")


def encode_file_name(name: str, what: str = "file name") -> bytes:
    """The 12-byte form of a command's 8.3 name (validated by :func:`check_file_name`)."""
    base, _, ext = check_file_name(name, what).partition(".")
    return _layout(base, ext)


def decode_file_name(raw: bytes) -> str:
    """The name in a 12-byte field, leniently (responses may hold any bytes).

    ``ASCII   .DAT`` → ``"ASCII.DAT"``, ``DATA        `` → ``"DATA"``, all spaces → ``""``.
    A field that is not in the 8.3 layout comes back as its text without trailing spaces.
    """
    if len(raw) != FILE_NAME_SIZE:
        raise DecodeError(f"a file name needs {FILE_NAME_SIZE} bytes, got {len(raw)}")
    text = raw.decode("latin-1")
    base, period, ext = text[:8].rstrip(" "), text[8], text[9:].rstrip(" ")
    if (
        " " not in base + ext
        and "." not in base + ext
        and (period == "." or (period == " " and not ext))
    ):
        return f"{base}.{ext}" if ext else base
    return text.rstrip(" ")


def encode_entry_name(name: str, what: str = "file name") -> bytes:
    """The 12-byte field for a name in a response (file entry, volume label).

    Accepts whatever :func:`decode_file_name` can return: 8.3 names, ``"."``, ``".."``,
    ``""`` and up to 12 other characters (written as they are, space padded).
    """
    try:
        name.encode("latin-1")
    except UnicodeEncodeError as exc:
        raise CommandError(f"{what} {name!r} has characters outside latin-1") from exc
    if name != name.rstrip(" "):
        raise CommandError(f"{what} {name!r} ends with a space")
    base, dot, ext = name.partition(".")
    if name in (".", ".."):
        return _layout(name, "")
    fits = " " not in name and "." not in ext and len(base) <= 8 and len(ext) <= 3
    if fits and (ext or not dot):
        return _layout(base, ext)
    if len(name) > FILE_NAME_SIZE:
        raise CommandError(f"{what} {name!r} is longer than {FILE_NAME_SIZE} characters")
    return name.ljust(FILE_NAME_SIZE).encode("latin-1")


# --------------------------------------------------------------------------- directories


def check_directory(path: str, what: str = "directory") -> str:
    """Validate an absolute directory path; returns it with ``/`` turned into ``\\``.

    ``""`` (or ``"\\"``) is the root. Otherwise ``\\NAME\\NAME...``, each part an 8.3 name,
    no trailing ``\\``, at most 65 characters.
    """
    if not isinstance(path, str):
        raise CommandError(f"{what} must be a str, got {type(path).__name__}")
    norm = path.replace("/", "\\")
    if norm == "\\":
        return ""
    if not norm:
        return norm
    if len(norm) > MAX_DIRECTORY_LENGTH:
        raise CommandError(
            f"{what} {path!r} is {len(norm)} characters, at most {MAX_DIRECTORY_LENGTH}"
        )
    if not norm.startswith("\\"):
        raise CommandError(f"{what} {path!r} must be absolute (start with '\\')")
    for part in norm[1:].split("\\"):
        if not part:
            raise CommandError(f"{what} {path!r} has an empty part (or a trailing '\\')")
        check_file_name(part, f"{what} part")
    return norm


def encode_directory(path: str) -> bytes:
    """Directory length (2 bytes) and path; ``""`` gives ``00 00`` (the root)."""
    raw = check_directory(path).encode("ascii")
    return len(raw).to_bytes(2, "big") + raw


def read_directory(reader: Reader) -> str:
    """Read a directory length and path; :class:`DecodeError` (``110C``) if invalid."""
    length = reader.u16()
    if length > MAX_DIRECTORY_LENGTH:
        raise DecodeError(
            f"directory length {length} over {MAX_DIRECTORY_LENGTH}", end_code=PARAMETER_ERROR
        )
    text = reader.take(length).decode("latin-1")
    if text == "\\" or "/" in text:
        message = f"directory {text!r}: separator is '\\', the root is length 0"
        raise DecodeError(message, end_code=PARAMETER_ERROR)
    with as_decode_error("directory"):
        return check_directory(text)


def read_file_name(reader: Reader, what: str = "file name") -> str:
    """Read a command's 12-byte 8.3 name; :class:`DecodeError` (``110C``) if invalid."""
    raw = reader.take(FILE_NAME_SIZE)
    name = decode_file_name(raw)
    with as_decode_error(what):
        if encode_file_name(name, what) != raw:
            raise CommandError(f"{what} field {raw!r} is not in the 8.3 layout")
    return name


# --------------------------------------------------------------------------- date/time


@dataclass(frozen=True, slots=True)
class FileDate:
    """A file's date and time as stored (binary, two-second resolution).

    Every field accepts the whole range its bits can hold, because file memory may report
    values that are no calendar date (``00000000`` has month 0, day 0); use
    :meth:`to_datetime` for a :class:`datetime.datetime` (``None`` if it is no real date).
    """

    year: int
    month: int
    day: int
    hour: int = 0
    minute: int = 0
    second: int = 0

    def __post_init__(self) -> None:
        for name, value, low, high in (
            ("year", self.year, 1980, 2107),
            ("month", self.month, 0, 15),
            ("day", self.day, 0, 31),
            ("hour", self.hour, 0, 31),
            ("minute", self.minute, 0, 63),
            ("second", self.second, 0, 62),
        ):
            if not isinstance(value, int) or not low <= value <= high:
                raise CommandError(f"file date {name} {value!r} out of range {low}..{high}")
        if self.second % 2:
            raise CommandError(f"file date second {self.second} is odd (2-second resolution)")

    @property
    def raw(self) -> int:
        """The packed 32-bit value."""
        return (
            (self.year - 1980) << 25
            | self.month << 21
            | self.day << 16
            | self.hour << 11
            | self.minute << 5
            | self.second // 2
        )

    @classmethod
    def from_raw(cls, raw: int) -> FileDate:
        if not 0 <= raw <= 0xFFFFFFFF:
            raise CommandError(f"packed file date {raw} out of range 0..0xFFFFFFFF")
        return cls(
            1980 + (raw >> 25),
            (raw >> 21) & 0x0F,
            (raw >> 16) & 0x1F,
            (raw >> 11) & 0x1F,
            (raw >> 5) & 0x3F,
            (raw & 0x1F) * 2,
        )

    def encode(self) -> bytes:
        return self.raw.to_bytes(FILE_DATE_SIZE, "big")

    @classmethod
    def decode(cls, raw: bytes) -> FileDate:
        if len(raw) != FILE_DATE_SIZE:
            raise DecodeError(f"a file date needs {FILE_DATE_SIZE} bytes, got {len(raw)}")
        return cls.from_raw(int.from_bytes(raw, "big"))

    @classmethod
    def from_datetime(cls, value: _dt.datetime) -> FileDate:
        """Pack ``value`` (seconds rounded down to even); years 1980..2107 only."""
        return cls(
            value.year,
            value.month,
            value.day,
            value.hour,
            value.minute,
            value.second - value.second % 2,
        )

    def to_datetime(self) -> _dt.datetime | None:
        """A naive :class:`datetime.datetime`, or ``None`` if the fields are no real date."""
        try:
            return _dt.datetime(
                self.year, self.month, self.day, self.hour, self.minute, self.second
            )
        except ValueError:
            return None

    def __str__(self) -> str:
        return (
            f"{self.year:04d}-{self.month:02d}-{self.day:02d} "
            f"{self.hour:02d}:{self.minute:02d}:{self.second:02d}"
        )


# --------------------------------------------------------------------------- codes


class FileWriteMode(IntEnum):
    """Parameter code of 2203 SINGLE FILE WRITE."""

    #: Write a new file; nothing is written if the name exists (end code 2107).
    NEW = 0x0000
    #: Write a new file, overwriting one of the same name.
    NEW_OVERWRITE = 0x0001
    #: Add data to the end of an existing file.
    APPEND = 0x0002
    #: Overwrite part of an existing file from the file position.
    OVERWRITE = 0x0003


class FileTransferMode(IntEnum):
    """Parameter code of 220A/220B/220C (area ↔ file transfers)."""

    AREA_TO_FILE = 0x0000
    FILE_TO_AREA = 0x0001
    COMPARE = 0x0002


class DirectoryOperation(IntEnum):
    """Parameter of 2215 CREATE/DELETE DIRECTORY."""

    CREATE = 0x0000
    DELETE = 0x0001


class CassetteOperation(IntEnum):
    """Parameter of 2220 MEMORY CASSETTE TRANSFER."""

    TO_CASSETTE = 0x0000  # CPU Unit → Memory Cassette
    FROM_CASSETTE = 0x0001  # Memory Cassette → CPU Unit
    VERIFY = 0x0002
    INITIALIZE = 0x0003
    READ_DATA_TYPE = 0x8000


class CassetteArea(IntFlag):
    """Data type designation of 2220: no bit = all areas; INDIVIDUAL + bits = those areas."""

    USER_PROGRAM = 0x0001  # user program + function block sources
    PARAMETER_AREA = 0x0004
    SYMBOL_TABLE = 0x0008
    COMMENTS = 0x0010
    PROGRAM_INDICES = 0x0020
    DATA_MEMORY = 0x0040
    DM_INITIAL_VALUES = 0x0080
    INDIVIDUAL = 0x8000


#: The designation for all areas (no bit set).
ALL_CASSETTE_AREAS = CassetteArea(0)
#: Area bits of :class:`CassetteArea` (everything but INDIVIDUAL).
CASSETTE_AREA_BITS = 0x00FD


class CassetteContents(IntFlag):
    """Stored data type answered by 2220 READ_DATA_TYPE."""

    USER_PROGRAM = 0x0001
    FUNCTION_BLOCK_SOURCES = 0x0002
    PARAMETER_AREA = 0x0004
    SYMBOL_TABLE = 0x0008
    COMMENTS = 0x0010
    PROGRAM_INDICES = 0x0020
    DATA_MEMORY = 0x0040
    DM_INITIAL_VALUES = 0x0080


E = TypeVar("E", bound=IntEnum)


def coerce_enum(enum: type[E], value: int, what: str) -> E:
    """``enum(value)``, or :class:`CommandError` naming the allowed codes."""
    try:
        return enum(value)
    except ValueError:
        codes = ", ".join(f"{m.value:04X} ({m.name})" for m in enum)
        raise CommandError(f"{what} {value!r} is not one of {codes}") from None


def check_u(what: str, value: int, bits: int, low: int = 0) -> None:
    """:class:`CommandError` unless ``value`` is an int in ``low .. 2**bits - 1``."""
    high = (1 << bits) - 1
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise CommandError(f"{what} {value!r} out of range {low}..{high}")


# --------------------------------------------------------------------------- 2201 result


@dataclass(frozen=True, slots=True)
class DiskData:
    """Disk data of 2201: volume label, its date, capacities (bytes), files in directory."""

    volume_label: str
    date: FileDate
    total_capacity: int
    unused_capacity: int
    total_files: int

    def __post_init__(self) -> None:
        encode_entry_name(self.volume_label, "volume label")
        check_u("total capacity", self.total_capacity, 32)
        check_u("unused capacity", self.unused_capacity, 32)
        check_u("total number of files", self.total_files, 16)

    def encode(self) -> bytes:
        return (
            encode_entry_name(self.volume_label, "volume label")
            + self.date.encode()
            + self.total_capacity.to_bytes(4, "big")
            + self.unused_capacity.to_bytes(4, "big")
            + self.total_files.to_bytes(2, "big")
        )

    @classmethod
    def read(cls, reader: Reader) -> DiskData:
        return cls(
            decode_file_name(reader.take(FILE_NAME_SIZE)),
            FileDate.decode(reader.take(FILE_DATE_SIZE)),
            reader.u32(),
            reader.u32(),
            reader.u16(),
        )


@dataclass(frozen=True, slots=True)
class FileEntry:
    """One file (or directory, volume label) of a 2201 listing: 22 bytes on the wire."""

    name: str
    date: FileDate
    size: int
    attributes: FileAttribute = NO_ATTRIBUTES

    def __post_init__(self) -> None:
        encode_entry_name(self.name)
        check_u("file size", self.size, 32)
        check_u("file attributes", int(self.attributes), 16)
        object.__setattr__(self, "attributes", FileAttribute(self.attributes))

    @property
    def is_directory(self) -> bool:
        return FileAttribute.DIRECTORY in self.attributes

    def encode(self) -> bytes:
        return (
            encode_entry_name(self.name)
            + self.date.encode()
            + self.size.to_bytes(4, "big")
            + int(self.attributes).to_bytes(2, "big")
        )

    @classmethod
    def read(cls, reader: Reader) -> FileEntry:
        return cls(
            decode_file_name(reader.take(FILE_NAME_SIZE)),
            FileDate.decode(reader.take(FILE_DATE_SIZE)),
            reader.u32(),
            FileAttribute(reader.u16()),
        )


@dataclass(frozen=True, slots=True)
class FileNameReadResult:
    """2201 response: disk data, the files read, and whether the directory's last file is
    among them (bit 15 of the number of files)."""

    disk_data: DiskData
    files: tuple[FileEntry, ...] = ()
    last: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "files", tuple(self.files))
        if len(self.files) > 0x7FFF:
            raise CommandError(f"{len(self.files)} file entries, at most 32767")

    def encode(self) -> bytes:
        count = len(self.files) | (0x8000 if self.last else 0)
        return (
            self.disk_data.encode()
            + count.to_bytes(2, "big")
            + b"".join(f.encode() for f in self.files)
        )

    @classmethod
    def decode(cls, data: bytes) -> FileNameReadResult:
        r = Reader(data, "FILE NAME READ response")
        disk_data = DiskData.read(r)
        count = r.u16()
        files = tuple(FileEntry.read(r) for _ in range(count & 0x7FFF))
        r.end()
        return cls(disk_data, files, bool(count & 0x8000))
