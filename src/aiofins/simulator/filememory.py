"""File memory of the virtual PLC (memory card 8000, EM file memory 8001), held in memory.

A tree of directories and files with 8.3 names (``"NAME.EXT"``, as the codec decodes them),
dates from the PLC clock, a capacity and a volume label.
Errors raise :class:`CommandFailed` with the CPU Unit's end code.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import datetime

from ..protocol.files import FileAttribute, FileWriteMode
from .state import (
    ADDRESS_RANGE_ERROR,
    ADDRESS_RANGE_EXCEEDED,
    CANNOT_CHANGE,
    CANNOT_REGISTER,
    FILE_EXISTS,
    PARAMETER_ERROR,
    READ_FILE_MISSING,
    WRITE_FILE_MISSING,
    CommandFailed,
)

MAX_ENTRIES = 512


@dataclass
class File:
    data: bytearray
    time: datetime


@dataclass
class Directory:
    time: datetime
    entries: dict[str, File | Directory] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class Listing:
    """One 2201 file record: name, date, size, attribute."""

    name: str
    time: datetime
    size: int
    attribute: FileAttribute


class FileMemory:
    """One file device."""

    def __init__(self, *, capacity: int, clock: Callable[[], datetime]) -> None:
        self.capacity = capacity
        self._clock = clock
        self.volume_label = ""
        self.label_time = clock()
        self.root = Directory(clock())

    # ---- navigation -------------------------------------------------------------------------

    def directory(self, path: tuple[str, ...], missing: int = READ_FILE_MISSING) -> Directory:
        d = self.root
        for part in path:
            entry = d.entries.get(part)
            if not isinstance(entry, Directory):
                raise CommandFailed(missing, message=f"no directory {part}")
            d = entry
        return d

    def file(self, path: tuple[str, ...], name: str, missing: int = READ_FILE_MISSING) -> File:
        entry = self.directory(path, missing).entries.get(name)
        if not isinstance(entry, File):
            raise CommandFailed(missing, message=f"no file {name}")
        return entry

    def used(self) -> int:
        def size(d: Directory) -> int:
            return sum(len(e.data) if isinstance(e, File) else size(e) for e in d.entries.values())

        return size(self.root)

    def free(self) -> int:
        return max(self.capacity - self.used(), 0)

    def listing(self, path: tuple[str, ...]) -> list[Listing]:
        """What 2201 counts in a directory: label (root) or ``.``/``..``, then entries."""
        d = self.directory(path)
        out: list[Listing] = []
        if not path and self.volume_label:
            out.append(Listing(self.volume_label, self.label_time, 0, FileAttribute.VOLUME_LABEL))
        if path:
            out.append(Listing(".", d.time, 0, FileAttribute.DIRECTORY))
            out.append(Listing("..", d.time, 0, FileAttribute.DIRECTORY))
        for name, e in d.entries.items():
            if isinstance(e, File):
                out.append(Listing(name, e.time, len(e.data), FileAttribute.ARCHIVE))
            else:
                out.append(Listing(name, e.time, 0, FileAttribute.DIRECTORY))
        return out

    # ---- changes ----------------------------------------------------------------------------

    def _need(self, extra: int) -> None:
        if extra > self.free():
            raise CommandFailed(ADDRESS_RANGE_EXCEEDED, message="file memory full")

    def _add(self, d: Directory, name: str, entry: File | Directory) -> None:
        if name in d.entries:
            raise CommandFailed(FILE_EXISTS, message=f"{name} exists")
        if len(d.entries) >= MAX_ENTRIES:
            raise CommandFailed(CANNOT_REGISTER, message="too many files")
        d.entries[name] = entry

    def write(
        self, path: tuple[str, ...], name: str, mode: int, position: int, data: bytes
    ) -> None:
        """2203 in ``mode`` (:class:`FileWriteMode`); another code is a parameter error."""
        d = self.directory(path, WRITE_FILE_MISSING)
        existing = d.entries.get(name)
        if mode in (FileWriteMode.NEW, FileWriteMode.NEW_OVERWRITE):
            if isinstance(existing, Directory) or (
                existing is not None and mode == FileWriteMode.NEW
            ):
                raise CommandFailed(FILE_EXISTS, message=f"{name} exists")
            old = len(existing.data) if isinstance(existing, File) else 0
            self._need(len(data) - old)
            if existing is not None:
                del d.entries[name]
            self._add(d, name, File(bytearray(data), self._clock()))
            return
        if not isinstance(existing, File):
            raise CommandFailed(WRITE_FILE_MISSING, message=f"no file {name}")
        if mode == FileWriteMode.APPEND:
            self._need(len(data))
            existing.data += data
        elif mode == FileWriteMode.OVERWRITE:
            if position > len(existing.data):
                raise CommandFailed(ADDRESS_RANGE_ERROR, message="file position beyond the end")
            self._need(max(position + len(data) - len(existing.data), 0))
            existing.data[position : position + len(data)] = data
        else:
            raise CommandFailed(PARAMETER_ERROR, message=f"parameter code {mode:04X}")
        existing.time = self._clock()

    def create(self, path: tuple[str, ...], name: str, data: bytes) -> None:
        """A new file that must not exist yet (area-to-file transfers)."""
        d = self.directory(path, WRITE_FILE_MISSING)
        self._need(len(data))
        self._add(d, name, File(bytearray(data), self._clock()))

    def put_copy(self, path: tuple[str, ...], name: str, source: File) -> None:
        """2207: a copy keeps the source's date; an existing destination is refused."""
        d = self.directory(path, WRITE_FILE_MISSING)
        self._need(len(source.data))
        self._add(d, name, File(bytearray(source.data), source.time))

    def delete(self, path: tuple[str, ...], names: list[str]) -> int:
        """2205: delete files; names that do not exist are skipped. Returns how many went."""
        d = self.directory(path, WRITE_FILE_MISSING)
        deleted = 0
        for name in names:
            if isinstance(d.entries.get(name), File):
                del d.entries[name]
                deleted += 1
        return deleted

    def rename(self, path: tuple[str, ...], old: str, new: str) -> None:
        """2208: files and directories; the date is kept."""
        d = self.directory(path, WRITE_FILE_MISSING)
        if old not in d.entries:
            raise CommandFailed(WRITE_FILE_MISSING, message=f"no file {old}")
        if new in d.entries:
            raise CommandFailed(FILE_EXISTS, message=f"{new} exists")
        d.entries[new] = d.entries.pop(old)

    def make_directory(self, path: tuple[str, ...], name: str) -> None:
        self._add(self.directory(path, WRITE_FILE_MISSING), name, Directory(self._clock()))

    def remove_directory(self, path: tuple[str, ...], name: str) -> None:
        d = self.directory(path, WRITE_FILE_MISSING)
        entry = d.entries.get(name)
        if not isinstance(entry, Directory):
            raise CommandFailed(WRITE_FILE_MISSING, message=f"no directory {name}")
        if entry.entries:
            raise CommandFailed(CANNOT_CHANGE, message=f"directory {name} is not empty")
        del d.entries[name]

    def format(self) -> None:
        """2204: everything goes."""
        self.root = Directory(self._clock())
        self.volume_label = ""
