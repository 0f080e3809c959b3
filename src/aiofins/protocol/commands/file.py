"""File memory commands (manual 5-3-32..5-3-43). 2201..2204 are here; 2205/2207/2208/2215
live in :mod:`._file_manage`, 220A/220B/220C/2220 in :mod:`._file_transfer`, and all are
exported here. Names, dates, disks and directories are in :mod:`..files`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from ..codec import Reader
from ..decoding import as_decode_error
from ..errors import CommandError
from ..files import (
    Disk,
    DiskData,
    FileEntry,
    FileNameReadResult,
    FileWriteMode,
    check_directory,
    check_disk,
    check_file_name,
    check_u,
    coerce_enum,
    encode_directory,
    encode_file_name,
    read_directory,
    read_disk,
    read_file_name,
)
from ..header import MAX_PARAMETER_SIZE, MAX_RESPONSE_DATA_SIZE
from ._base import Request, finish
from ._file_common import FileCommand, FileOperation, set_field, u16, u32
from ._file_manage import (
    CreateDeleteDirectory,
    FileCopy,
    FileDelete,
    FileDeleteResult,
    FileNameChange,
)
from ._file_transfer import (
    FILE_TRANSFER_AREA_CODES,
    FILE_TRANSFER_PARAMETER_AREAS,
    FileTransferResult,
    MemoryAreaFileTransfer,
    MemoryCassetteDataType,
    MemoryCassetteTransfer,
    ParameterAreaFileTransfer,
    ProgramAreaFileTransfer,
    ProgramAreaFileTransferResult,
)

#: Most file names 2201 reads at once (0014 hex).
MAX_FILE_NAMES = 20
#: Most bytes 2202 can return in one response (1998 - 10 bytes of header fields).
#: Response bytes of 2202 besides the file data.
FILE_READ_OVERHEAD = 10
MAX_FILE_READ = MAX_RESPONSE_DATA_SIZE - FILE_READ_OVERHEAD
#: Parameter bytes of 2203 besides the data and the directory path.
FILE_WRITE_OVERHEAD = 2 + 2 + 12 + 4 + 2 + 2
#: Most file data 2203 can carry with the root directory (2000 - 24).
MAX_FILE_WRITE = MAX_PARAMETER_SIZE - FILE_WRITE_OVERHEAD


# --------------------------------------------------------------------------- 2201


@dataclass(frozen=True)
class FileNameRead(FileCommand[FileNameReadResult]):
    """2201: disk data and up to 20 file entries of a directory, from ``first_file`` on.

    ``first_file=0, count=0`` reads the disk data only.
    """

    SRC: ClassVar[int] = 0x01
    NAME: ClassVar[str] = "FILE NAME READ"
    METHOD: ClassVar[str] = "file_name_read"
    IDEMPOTENT: ClassVar[bool] = True

    disk: Disk
    first_file: int = 0
    count: int = MAX_FILE_NAMES
    directory: str = ""

    def __post_init__(self) -> None:
        set_field(self, "disk", check_disk(self.disk))
        check_u("beginning file position", self.first_file, 16)
        check_u("number of files", self.count, 16)
        if self.count > MAX_FILE_NAMES:
            raise CommandError(f"number of files {self.count} out of range 0..{MAX_FILE_NAMES}")
        set_field(self, "directory", check_directory(self.directory))

    def encode(self) -> bytes:
        return (
            u16(self.disk)
            + u16(self.first_file)
            + u16(self.count)
            + encode_directory(self.directory)
        )

    @classmethod
    def decode(cls, params: bytes) -> FileNameRead:
        r = Reader(params, cls.NAME)
        return finish(cls, r, read_disk(r), r.u16(), r.u16(), read_directory(r))

    def decode_response(self, data: bytes) -> FileNameReadResult:
        return FileNameReadResult.decode(data)


# --------------------------------------------------------------------------- 2202


@dataclass(frozen=True, slots=True)
class SingleFileReadResult:
    """2202 response: the file's size, where the data starts, the data, and whether it
    includes the file's last byte (bit 15 of the data length)."""

    file_capacity: int
    position: int
    data: bytes = b""
    last: bool = False

    def __post_init__(self) -> None:
        check_u("file capacity", self.file_capacity, 32)
        check_u("file position", self.position, 32)
        object.__setattr__(self, "data", bytes(self.data))
        check_u("data length", len(self.data), 15)

    def encode(self) -> bytes:
        length = len(self.data) | (0x8000 if self.last else 0)
        return u32(self.file_capacity) + u32(self.position) + u16(length) + self.data

    @classmethod
    def decode(cls, data: bytes) -> SingleFileReadResult:
        r = Reader(data, "SINGLE FILE READ response")
        capacity, position, length = r.u32(), r.u32(), r.u16()
        chunk = r.take(length & 0x7FFF)
        r.end()
        return cls(capacity, position, chunk, bool(length & 0x8000))


@dataclass(frozen=True)
class SingleFileRead(FileCommand[SingleFileReadResult]):
    """2202: read ``length`` bytes of a file from byte ``position`` (0, 0 = existence check)."""

    SRC: ClassVar[int] = 0x02
    NAME: ClassVar[str] = "SINGLE FILE READ"
    METHOD: ClassVar[str] = "single_file_read"
    IDEMPOTENT: ClassVar[bool] = True

    disk: Disk
    name: str
    position: int = 0
    length: int = MAX_FILE_READ
    directory: str = ""

    def __post_init__(self) -> None:
        set_field(self, "disk", check_disk(self.disk))
        check_file_name(self.name)
        check_u("file position", self.position, 32)
        check_u("data length", self.length, 16)
        if self.length > MAX_FILE_READ:
            raise CommandError(f"data length {self.length} out of range 0..{MAX_FILE_READ}")
        set_field(self, "directory", check_directory(self.directory))

    def encode(self) -> bytes:
        return (
            u16(self.disk)
            + encode_file_name(self.name)
            + u32(self.position)
            + u16(self.length)
            + encode_directory(self.directory)
        )

    @classmethod
    def decode(cls, params: bytes) -> SingleFileRead:
        r = Reader(params, cls.NAME)
        return finish(cls, r, read_disk(r), read_file_name(r), r.u32(), r.u16(), read_directory(r))

    def decode_response(self, data: bytes) -> SingleFileReadResult:
        return SingleFileReadResult.decode(data)


# --------------------------------------------------------------------------- 2203


@dataclass(frozen=True)
class SingleFileWrite(FileOperation):
    """2203: write ``data`` to a file; ``mode`` picks new / new-overwrite / append / overwrite.

    ``position`` (byte offset) only matters for :attr:`FileWriteMode.OVERWRITE`; the manual
    requires 0 for the other modes.
    """

    SRC: ClassVar[int] = 0x03
    NAME: ClassVar[str] = "SINGLE FILE WRITE"
    METHOD: ClassVar[str] = "single_file_write"

    disk: Disk
    name: str
    data: bytes
    mode: FileWriteMode = FileWriteMode.NEW
    position: int = 0
    directory: str = ""

    def __post_init__(self) -> None:
        set_field(self, "disk", check_disk(self.disk))
        check_file_name(self.name)
        set_field(self, "data", bytes(self.data))
        set_field(self, "mode", coerce_enum(FileWriteMode, self.mode, "file write parameter code"))
        check_u("file position", self.position, 32)
        if self.position and self.mode is not FileWriteMode.OVERWRITE:
            raise CommandError(
                f"file position must be 0 for {self.mode.name} (only OVERWRITE takes one)"
            )
        set_field(self, "directory", check_directory(self.directory))
        size = FILE_WRITE_OVERHEAD + len(self.data) + len(self.directory)
        if size > MAX_PARAMETER_SIZE:
            room = MAX_PARAMETER_SIZE - FILE_WRITE_OVERHEAD - len(self.directory)
            raise CommandError(
                f"{len(self.data)} bytes of file data do not fit one command (at most {room})"
            )

    def encode(self) -> bytes:
        return (
            u16(self.disk)
            + u16(self.mode)
            + encode_file_name(self.name)
            + u32(self.position)
            + u16(len(self.data))
            + self.data
            + encode_directory(self.directory)
        )

    @classmethod
    def decode(cls, params: bytes) -> SingleFileWrite:
        r = Reader(params, cls.NAME)
        disk = read_disk(r)
        mode = r.u16()
        name = read_file_name(r)
        position, length = r.u32(), r.u16()
        data = r.take(length)
        directory = read_directory(r)
        r.end()
        with as_decode_error(cls.NAME):
            write_mode = coerce_enum(FileWriteMode, mode, "file write parameter code")
            return cls(disk, name, data, write_mode, position, directory)


# --------------------------------------------------------------------------- 2204


@dataclass(frozen=True)
class FileMemoryFormat(FileOperation):
    """2204: format (initialise) a file memory; every file on it is lost."""

    SRC: ClassVar[int] = 0x04
    NAME: ClassVar[str] = "FILE MEMORY FORMAT"
    METHOD: ClassVar[str] = "file_memory_format"

    disk: Disk

    def __post_init__(self) -> None:
        set_field(self, "disk", check_disk(self.disk))

    def encode(self) -> bytes:
        return u16(self.disk)

    @classmethod
    def decode(cls, params: bytes) -> FileMemoryFormat:
        r = Reader(params, cls.NAME)
        return finish(cls, r, read_disk(r))


OPERATIONS: tuple[type[Request[Any]], ...] = (
    FileNameRead,
    SingleFileRead,
    SingleFileWrite,
    FileMemoryFormat,
    FileDelete,
    FileCopy,
    FileNameChange,
    MemoryAreaFileTransfer,
    ParameterAreaFileTransfer,
    ProgramAreaFileTransfer,
    CreateDeleteDirectory,
    MemoryCassetteTransfer,
)

__all__ = [
    "FILE_READ_OVERHEAD",
    "FILE_TRANSFER_AREA_CODES",
    "FILE_TRANSFER_PARAMETER_AREAS",
    "FILE_WRITE_OVERHEAD",
    "MAX_FILE_NAMES",
    "MAX_FILE_READ",
    "MAX_FILE_WRITE",
    "OPERATIONS",
    "CreateDeleteDirectory",
    "DiskData",
    "FileCopy",
    "FileDelete",
    "FileDeleteResult",
    "FileEntry",
    "FileMemoryFormat",
    "FileNameChange",
    "FileNameRead",
    "FileNameReadResult",
    "FileTransferResult",
    "MemoryAreaFileTransfer",
    "MemoryCassetteDataType",
    "MemoryCassetteTransfer",
    "ParameterAreaFileTransfer",
    "ProgramAreaFileTransfer",
    "ProgramAreaFileTransferResult",
    "SingleFileRead",
    "SingleFileReadResult",
    "SingleFileWrite",
]
