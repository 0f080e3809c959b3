"""File memory commands 2205, 2207, 2208 and 2215 (manual 5-3-36..5-3-38, 5-3-42): delete,
copy, rename, create/delete directory. Exported through :mod:`.file`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from ..codec import Reader
from ..decoding import as_decode_error
from ..errors import CommandError
from ..files import (
    DirectoryOperation,
    Disk,
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
from ..header import MAX_PARAMETER_SIZE
from ._base import finish
from ._file_common import FileCommand, FileOperation, read_number, set_field, u16

# --------------------------------------------------------------------------- 2205


@dataclass(frozen=True, slots=True)
class FileDeleteResult:
    """2205 response: how many files were deleted (names that did not exist are skipped)."""

    deleted: int

    def __post_init__(self) -> None:
        check_u("number of files deleted", self.deleted, 16)

    def encode(self) -> bytes:
        return u16(self.deleted)

    @classmethod
    def decode(cls, data: bytes) -> FileDeleteResult:
        return cls(read_number(data, "FILE DELETE response"))


@dataclass(frozen=True)
class FileDelete(FileCommand[FileDeleteResult]):
    """2205: delete the named files of one directory."""

    SRC: ClassVar[int] = 0x05
    NAME: ClassVar[str] = "FILE DELETE"
    METHOD: ClassVar[str] = "file_delete"

    disk: Disk
    names: tuple[str, ...]
    directory: str = ""

    def __post_init__(self) -> None:
        set_field(self, "disk", check_disk(self.disk))
        if isinstance(self.names, str):
            raise CommandError("names must be a sequence of file names, not one str")
        set_field(self, "names", tuple(self.names))
        for name in self.names:
            check_file_name(name)
        set_field(self, "directory", check_directory(self.directory))
        most = (MAX_PARAMETER_SIZE - 6 - len(self.directory)) // 12
        if not 1 <= len(self.names) <= most:
            raise CommandError(f"number of files {len(self.names)} out of range 1..{most}")

    def encode(self) -> bytes:
        return (
            u16(self.disk)
            + u16(len(self.names))
            + b"".join(encode_file_name(n) for n in self.names)
            + encode_directory(self.directory)
        )

    @classmethod
    def decode(cls, params: bytes) -> FileDelete:
        r = Reader(params, cls.NAME)
        disk = read_disk(r)
        names = tuple(read_file_name(r) for _ in range(r.u16()))
        return finish(cls, r, disk, names, read_directory(r))

    def decode_response(self, data: bytes) -> FileDeleteResult:
        return FileDeleteResult.decode(data)


# --------------------------------------------------------------------------- 2207


@dataclass(frozen=True)
class FileCopy(FileOperation):
    """2207: copy a file, possibly to the other file memory; the copy keeps the date."""

    SRC: ClassVar[int] = 0x07
    NAME: ClassVar[str] = "FILE COPY"
    METHOD: ClassVar[str] = "file_copy"

    source_disk: Disk
    source_name: str
    destination_disk: Disk
    destination_name: str
    source_directory: str = ""
    destination_directory: str = ""

    def __post_init__(self) -> None:
        set_field(self, "source_disk", check_disk(self.source_disk, what="source disk"))
        set_field(
            self, "destination_disk", check_disk(self.destination_disk, what="destination disk")
        )
        check_file_name(self.source_name, "source file name")
        check_file_name(self.destination_name, "destination file name")
        set_field(
            self, "source_directory", check_directory(self.source_directory, "source directory")
        )
        set_field(
            self,
            "destination_directory",
            check_directory(self.destination_directory, "destination directory"),
        )

    def encode(self) -> bytes:
        return (
            u16(self.source_disk)
            + encode_file_name(self.source_name)
            + u16(self.destination_disk)
            + encode_file_name(self.destination_name)
            + encode_directory(self.source_directory)
            + encode_directory(self.destination_directory)
        )

    @classmethod
    def decode(cls, params: bytes) -> FileCopy:
        r = Reader(params, cls.NAME)
        source_disk, source_name = read_disk(r), read_file_name(r)
        destination_disk, destination_name = read_disk(r), read_file_name(r)
        source_directory, destination_directory = read_directory(r), read_directory(r)
        return finish(
            cls,
            r,
            source_disk,
            source_name,
            destination_disk,
            destination_name,
            source_directory,
            destination_directory,
        )


# --------------------------------------------------------------------------- 2208


@dataclass(frozen=True)
class FileNameChange(FileOperation):
    """2208: rename a file or a directory; the date stays."""

    SRC: ClassVar[int] = 0x08
    NAME: ClassVar[str] = "FILE NAME CHANGE"
    METHOD: ClassVar[str] = "file_name_change"

    disk: Disk
    old_name: str
    new_name: str
    directory: str = ""

    def __post_init__(self) -> None:
        set_field(self, "disk", check_disk(self.disk))
        check_file_name(self.old_name, "old file name")
        check_file_name(self.new_name, "new file name")
        set_field(self, "directory", check_directory(self.directory))

    def encode(self) -> bytes:
        return (
            u16(self.disk)
            + encode_file_name(self.old_name)
            + encode_file_name(self.new_name)
            + encode_directory(self.directory)
        )

    @classmethod
    def decode(cls, params: bytes) -> FileNameChange:
        r = Reader(params, cls.NAME)
        disk = read_disk(r)
        old_name = read_file_name(r, "old file name")
        new_name = read_file_name(r, "new file name")
        return finish(cls, r, disk, old_name, new_name, read_directory(r))


# --------------------------------------------------------------------------- 2215


@dataclass(frozen=True)
class CreateDeleteDirectory(FileOperation):
    """2215: create or delete directory ``name`` inside ``directory`` (its parent)."""

    SRC: ClassVar[int] = 0x15
    NAME: ClassVar[str] = "CREATE/DELETE DIRECTORY"
    METHOD: ClassVar[str] = "create_delete_directory"

    disk: Disk
    operation: DirectoryOperation
    name: str
    directory: str = ""

    def __post_init__(self) -> None:
        set_field(self, "disk", check_disk(self.disk))
        op = coerce_enum(DirectoryOperation, self.operation, "directory parameter")
        set_field(self, "operation", op)
        check_file_name(self.name, "directory name")
        set_field(self, "directory", check_directory(self.directory))

    def encode(self) -> bytes:
        return (
            u16(self.disk)
            + u16(self.operation)
            + encode_file_name(self.name, "directory name")
            + encode_directory(self.directory)
        )

    @classmethod
    def decode(cls, params: bytes) -> CreateDeleteDirectory:
        r = Reader(params, cls.NAME)
        disk = read_disk(r)
        value = r.u16()
        with as_decode_error("parameter"):
            operation = coerce_enum(DirectoryOperation, value, "directory parameter")
        name = read_file_name(r, "directory name")
        return finish(cls, r, disk, operation, name, read_directory(r))
