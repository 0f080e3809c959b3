"""Bulk transfers with progress: program area and parameter area backup/restore, file memory.

Every function takes an optional ``progress(done, total)`` callback (``total`` is ``None`` when
the size is not known in advance, as for a program area read that ends at the PLC's
last-block bit). Frames go one at a time: these transfers are ordered by the PLC.

Restoring a program needs PROGRAM mode (the manual refuses 0307 otherwise); we check it before
sending anything.

Nothing the PLC echoes is trusted: every block address, file position, size and count in a
response is compared with what was asked (:class:`~aiofins.DecodeError` otherwise), a transfer
stops at the size or number of files the PLC announced, and the total size is bounded
(``max_size``), so a confused or hostile peer can neither splice the wrong bytes into a backup
nor keep a transfer going for ever.
"""

from __future__ import annotations

import json
from collections.abc import Callable

from .chunking import PROGRAM_BLOCK_UNIT, plan_parameter, plan_program
from .client import Client
from .protocol.commands.file import (
    FILE_READ_OVERHEAD,
    FILE_WRITE_OVERHEAD,
    MAX_FILE_NAMES,
    MAX_FILE_READ,
    MAX_FILE_WRITE,
    SingleFileWrite,
)
from .protocol.commands.parameter import PARAMETER_AREA_WORDS, ParameterArea, ParameterAreaWrite
from .protocol.commands.program import ProgramAreaWrite
from .protocol.commands.status import CpuMode
from .protocol.errors import CommandError, DecodeError, EndCodeError
from .protocol.files import Disk, FileEntry, FileWriteMode

#: ``progress(done, total)``: bytes (or words) transferred so far, of ``total`` (``None``
#: when the size is not known in advance).
Progress = Callable[[int, "int | None"], None]

__all__ = [
    "MAX_FILE_BYTES",
    "MAX_PROGRAM_BYTES",
    "Progress",
    "backup_parameters",
    "backup_program",
    "check_parameter_backup",
    "check_program_image",
    "download_file",
    "list_files",
    "restore_parameters",
    "restore_program",
    "upload_file",
]

#: Largest program image :func:`backup_program` reads by default (4 MiB: several times the
#: UM of the largest CS/CJ CPU Units).
MAX_PROGRAM_BYTES = 4 * 1024 * 1024
#: Largest file :func:`download_file` accepts by default (64 MiB); pass ``max_size`` for more.
MAX_FILE_BYTES = 64 * 1024 * 1024


def _max_size(value: object, low: int) -> int:
    """``max_size`` checked before anything is sent (:class:`CommandError`)."""
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise CommandError(
            f"max_size must be a whole number of bytes, at least {low}; got {value!r}"
        )
    return value


def _report(progress: Progress | None, done: int, total: int | None) -> None:
    if progress is not None:
        progress(done, total)


async def backup_program(
    client: Client, progress: Progress | None = None, *, max_size: int = MAX_PROGRAM_BYTES
) -> bytes:
    """Read the whole user program (0306 in blocks up to the last-block bit 15).

    Each response must echo the address asked and carry the bytes asked, in whole 4-byte
    units (fewer only with the last-block bit); more than ``max_size`` bytes without the
    last-block bit is refused. ``max_size`` (at least 4) is checked before anything is sent
    (:class:`CommandError`).
    :class:`~aiofins.DecodeError` in every case.
    """
    max_size = _max_size(max_size, PROGRAM_BLOCK_UNIT)
    limit = client.limits.program_read_bytes - client.limits.program_read_bytes % PROGRAM_BLOCK_UNIT
    room = max_size - max_size % PROGRAM_BLOCK_UNIT
    out = bytearray()
    while True:
        address = len(out)
        size = min(limit, room - address)
        if size <= 0:
            raise DecodeError(
                f"program area read: no last-block bit within {max_size} bytes (max_size)"
            )
        result = await client.program_area_read(address, size)
        if result.address != address:
            raise DecodeError(
                f"program area read: asked for address {address:08X}, "
                f"the PLC answered for {result.address:08X}"
            )
        got = len(result.data)
        if got > size or got % PROGRAM_BLOCK_UNIT:
            raise DecodeError(
                f"program area read at {address:08X}: asked for {size} bytes, "
                f"the PLC answered {got}"
            )
        if got < size and not result.last:  # a PLC answers less only with the last block
            raise DecodeError(
                f"program area read at {address:08X}: asked for {size} bytes, the PLC "
                f"answered {got} without the last-block bit"
            )
        out += result.data
        _report(progress, len(out), len(out) if result.last else None)
        if result.last:
            return bytes(out)


def check_program_image(program: bytes) -> None:
    """Refuse a program image :func:`restore_program` cannot write (before anything is sent):
    empty, not whole 4-byte units, or a JSON document (a parameter backup, most likely)."""
    if not program:
        raise CommandError("program image is empty")
    if len(program) % PROGRAM_BLOCK_UNIT:
        raise CommandError(f"program image must be a multiple of 4 bytes, got {len(program)}")
    if program.lstrip()[:1] in (b"{", b"["):
        try:
            json.loads(program)
        except ValueError:
            return
        raise CommandError(
            "this is a JSON document (a parameter backup?), not a program image; a parameter "
            "backup goes to restore_parameters (on the command line: --what parameters)"
        )


async def restore_program(client: Client, program: bytes, progress: Progress | None = None) -> None:
    """Write a program backup (0307, last block flagged); the PLC must be in PROGRAM mode."""
    check_program_image(program)
    client.guard(ProgramAreaWrite)
    status = await client.cpu_unit_status_read()
    if status.mode != CpuMode.PROGRAM:
        raise CommandError(
            f"the PLC is in {status.mode.name} mode; program area writes need PROGRAM mode "
            "(send STOP first: client.stop())"
        )
    blocks = plan_program(0, len(program), client.limits.program_write_bytes)
    for block in blocks:
        data = program[block.start : block.start + block.size]
        echo = await client.program_area_write(block.start, data, last=block.last)
        if (echo.address, echo.byte_count, echo.last) != (block.start, block.size, block.last):
            raise DecodeError(
                f"program area write: sent {block.size} bytes at {block.start:08X}"
                f"{' (last)' if block.last else ''}, the PLC echoed {echo.byte_count} at "
                f"{echo.address:08X}{' (last)' if echo.last else ''}"
            )
        _report(progress, block.start + block.size, len(program))


async def backup_parameters(
    client: Client,
    areas: tuple[int, ...] = (
        ParameterArea.PLC_SETUP,
        ParameterArea.IO_TABLE,
        ParameterArea.ROUTING_TABLES,
        ParameterArea.CPU_BUS_UNIT_SETUP,
    ),
    progress: Progress | None = None,
) -> dict[int, tuple[int, ...]]:
    """Read whole parameter areas (0201, 498 words a frame) → words by area code."""
    total = sum(PARAMETER_AREA_WORDS[a] for a in areas)
    done = 0
    out: dict[int, tuple[int, ...]] = {}
    for area in areas:
        words: list[int] = []
        for block in plan_parameter(
            0, PARAMETER_AREA_WORDS[area], client.limits.parameter_read_words
        ):
            result = await client.parameter_area_read(area, block.start, block.size)
            echo = (result.area_code, result.begin_word, len(result.words))
            if echo != (area, block.start, block.size):
                raise DecodeError(
                    f"parameter area read: asked for {block.size} words of area {area:04X} "
                    f"from word {block.start}, the PLC answered {len(result.words)} words of "
                    f"area {result.area_code:04X} from word {result.begin_word}"
                )
            words.extend(result.words)
            done += len(result.words)
            _report(progress, done, total)
        out[int(area)] = tuple(words)
    return out


def check_parameter_backup(backup: dict[int, tuple[int, ...]]) -> None:
    """Refuse a parameter backup with an unknown area, a wrong size or a word out of 0..FFFF."""
    for area, words in backup.items():
        expected = PARAMETER_AREA_WORDS.get(area)
        if expected is None:
            known = ", ".join(f"{a:04X}" for a in PARAMETER_AREA_WORDS)
            raise CommandError(f"parameter area {area:04X} unknown (known: {known})")
        if len(words) != expected:
            raise CommandError(
                f"parameter area {area:04X}: backup has {len(words)} words, the area {expected}"
            )
        bad = next((w for w in words if not (isinstance(w, int) and 0 <= w <= 0xFFFF)), None)
        if bad is not None:
            raise CommandError(f"parameter area {area:04X}: word {bad!r} out of range 0..FFFF")


async def restore_parameters(
    client: Client, backup: dict[int, tuple[int, ...]], progress: Progress | None = None
) -> None:
    """Write parameter areas back (0202, 498 words a frame); the PLC must be in PROGRAM mode.

    The whole backup is checked first (:func:`check_parameter_backup`), and so is the mode
    (the I/O table and some PLC Setup words are written in PROGRAM mode only, manual 5-3-8),
    so a bad area or a wrong mode never leaves the PLC with some areas restored and the rest
    not.
    """
    check_parameter_backup(backup)
    client.guard(ParameterAreaWrite)
    status = await client.cpu_unit_status_read()
    if status.mode != CpuMode.PROGRAM:
        raise CommandError(
            f"the PLC is in {status.mode.name} mode; restoring parameter areas needs PROGRAM "
            "mode (send STOP first: client.stop())"
        )
    total = sum(len(w) for w in backup.values())
    done = 0
    for area, words in backup.items():
        for block in plan_parameter(0, len(words), client.limits.parameter_write_words):
            await client.parameter_area_write(
                area, block.start, tuple(words[block.start : block.start + block.size])
            )
            done += block.size
            _report(progress, done, total)


# -- file memory ---------------------------------------------------------------------------

#: End code of a file that does not exist (manual 5-1-3: "File missing").
FILE_NOT_FOUND = 0x2006


async def list_files(client: Client, disk: Disk, directory: str = "") -> list[FileEntry]:
    """Every file entry of a directory (2201, 20 names a frame).

    Reading stops at the number of files the first response announces (``total_files``) or
    at the last-file bit, whichever comes first; a page with more entries than asked or than
    announced, or with fewer than asked but no last-file bit, is refused
    (:class:`~aiofins.DecodeError`).
    """
    entries: list[FileEntry] = []
    total: int | None = None
    while total is None or len(entries) < total:
        count = MAX_FILE_NAMES if total is None else min(MAX_FILE_NAMES, total - len(entries))
        result = await client.file_name_read(disk, len(entries), count, directory)
        if total is None:
            total = result.disk_data.total_files
        got = len(result.files)
        if got > count or len(entries) + got > total:
            raise DecodeError(
                f"file name read: asked for {count} of {total} files from file {len(entries)}, "
                f"the PLC answered {got}"
            )
        # a PLC answers fewer than asked only with the last page (or the last announced file:
        # an empty directory's one page may well not flag a last file it does not have)
        if got < count and not result.last and len(entries) + got < total:
            raise DecodeError(
                f"file name read: asked for {count} of {total} files from file {len(entries)}, "
                f"the PLC answered {got} without the last-file bit"
            )
        entries.extend(result.files)
        if result.last:
            break
    return entries


async def download_file(
    client: Client,
    disk: Disk,
    name: str,
    directory: str = "",
    progress: Progress | None = None,
    *,
    max_size: int = MAX_FILE_BYTES,
) -> bytes:
    """A whole file from file memory (2202 in blocks as large as the route allows).

    The first response announces the file's size (file capacity): a size over ``max_size``
    is refused before more is read, and reading stops there. Every response must echo the
    position asked, the same file capacity, and carry exactly the bytes asked (the rest of
    the file, if less), with the last-byte bit only at the end (:class:`~aiofins.DecodeError`).
    ``max_size`` (at least 1) is checked before anything is sent (:class:`CommandError`).
    """
    max_size = _max_size(max_size, 1)
    limit = min(MAX_FILE_READ, client.limits.max_response_data_bytes - FILE_READ_OVERHEAD)
    out = bytearray()
    capacity: int | None = None
    while capacity is None or len(out) < capacity:
        position = len(out)
        size = limit if capacity is None else min(limit, capacity - position)
        result = await client.single_file_read(disk, name, position, size, directory)
        if capacity is None:
            capacity = result.file_capacity
            if capacity > max_size:
                raise DecodeError(
                    f"{name}: the PLC announces {capacity} bytes, more than max_size "
                    f"({max_size}); pass a larger max_size to read it"
                )
        got = len(result.data)
        end = position + got
        if result.position != position or result.file_capacity != capacity:
            raise DecodeError(
                f"{name}: asked for position {position} of a {capacity}-byte file, the PLC "
                f"answered position {result.position} of {result.file_capacity} bytes"
            )
        if got != min(size, capacity - position):
            raise DecodeError(
                f"{name}: asked for {size} bytes at position {position} of a {capacity}-byte "
                f"file, the PLC answered {got}"
            )
        if result.last and end < capacity:
            raise DecodeError(
                f"{name}: the PLC flags byte {end} the last of a {capacity}-byte file"
            )
        out += result.data
        _report(progress, len(out), capacity)
    return bytes(out)


async def upload_file(
    client: Client,
    disk: Disk,
    name: str,
    data: bytes,
    directory: str = "",
    progress: Progress | None = None,
    *,
    overwrite: bool = True,
) -> None:
    """Write a whole file (2203: a new file, then appends), replacing it if ``overwrite``.

    The disk's free space is checked first (2201; with ``overwrite``, plus the old file's
    size, 2202): the first frame replaces the old file, so running out of space half-way
    would leave a truncated file under its name and the old contents gone.
    """
    client.guard(SingleFileWrite)
    room = client.limits.max_parameter_bytes - FILE_WRITE_OVERHEAD - len(directory)
    limit = min(MAX_FILE_WRITE - len(directory), room)
    if limit < 1:
        raise CommandError(f"directory {directory!r} leaves no room for file data")
    free = (await client.file_name_read(disk, 0, 1, directory)).disk_data.unused_capacity
    old = 0
    if overwrite:
        try:
            old = (await client.single_file_read(disk, name, 0, 0, directory)).file_capacity
        except EndCodeError as exc:
            if exc.end_code.code != FILE_NOT_FOUND:
                raise
    if len(data) > free + old:
        raise CommandError(
            f"{name}: {len(data)} bytes do not fit: the disk has {free} bytes free"
            + (f" and the old file frees {old}" if old else "")
            + "; nothing written"
        )
    first_mode = FileWriteMode.NEW_OVERWRITE if overwrite else FileWriteMode.NEW
    offset = 0
    while True:
        block = data[offset : offset + limit]
        mode = first_mode if offset == 0 else FileWriteMode.APPEND
        await client.single_file_write(disk, name, block, mode, 0, directory)
        offset += len(block)
        _report(progress, offset, len(data))
        if offset >= len(data):
            return
