"""File memory: 2201-2208, 220A-220C, 2215 (manual 5-3-32 to 5-3-42).

The codec has already checked disk numbers, 8.3 names and directory paths.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ...protocol.commands.file import (
    CreateDeleteDirectory,
    FileCopy,
    FileDelete,
    FileDeleteResult,
    FileMemoryFormat,
    FileNameChange,
    FileNameRead,
    FileTransferResult,
    MemoryAreaFileTransfer,
    ParameterAreaFileTransfer,
    ProgramAreaFileTransfer,
    ProgramAreaFileTransferResult,
    SingleFileRead,
    SingleFileReadResult,
    SingleFileWrite,
)
from ...protocol.files import (
    DirectoryOperation,
    DiskData,
    FileDate,
    FileEntry,
    FileNameReadResult,
    FileTransferMode,
)
from ..codes import by_command_code
from ..filememory import FileMemory
from ..memory import FILL_AREAS
from ..state import (
    ADDRESS_RANGE_ERROR,
    DATA_MISMATCH,
    FILE_DEVICE_MISSING,
    PARAMETER_ERROR,
    CommandFailed,
)
from ._call import Call, Handler, request_of
from .parameter import LAYOUT

if TYPE_CHECKING:
    from ..plc import VirtualPLC


def _device(plc: VirtualPLC, disk: int) -> FileMemory:
    device = plc.file_memory.get(int(disk))
    if device is None:
        raise CommandFailed(FILE_DEVICE_MISSING, message=f"no file device {int(disk):04X}")
    return device


def _path(directory: str) -> tuple[str, ...]:
    return tuple(p for p in directory.split("\\") if p)


def file_name_read(plc: VirtualPLC, call: Call) -> bytes:
    req = request_of(call, FileNameRead)
    device = _device(plc, req.disk)
    entries = device.listing(_path(req.directory))
    begin = req.first_file
    if begin > len(entries):
        raise CommandFailed(ADDRESS_RANGE_ERROR)
    chosen = entries[begin : begin + req.count]
    disk = DiskData(
        volume_label=device.volume_label,
        date=FileDate.from_datetime(device.label_time),
        total_capacity=device.capacity,
        unused_capacity=device.free(),
        total_files=len(entries),
    )
    files = tuple(
        FileEntry(e.name, FileDate.from_datetime(e.time), e.size, e.attribute) for e in chosen
    )
    return FileNameReadResult(disk, files, begin + len(chosen) >= len(entries)).encode()


def single_file_read(plc: VirtualPLC, call: Call) -> bytes:
    req = request_of(call, SingleFileRead)
    f = _device(plc, req.disk).file(_path(req.directory), req.name)
    if req.position > len(f.data):
        raise CommandFailed(ADDRESS_RANGE_ERROR, message="file position beyond the end")
    # a read running past the end returns what exists, flagged as including the last byte
    chunk = bytes(f.data[req.position : req.position + req.length])
    last = bool(req.length) and req.position + len(chunk) >= len(f.data)
    return SingleFileReadResult(len(f.data), req.position, chunk, last).encode()


def single_file_write(plc: VirtualPLC, call: Call) -> bytes:
    req = request_of(call, SingleFileWrite)
    device = _device(plc, req.disk)
    device.write(_path(req.directory), req.name, int(req.mode), req.position, req.data)
    return b""


def file_memory_format(plc: VirtualPLC, call: Call) -> bytes:
    _device(plc, request_of(call, FileMemoryFormat).disk).format()
    return b""


def file_delete(plc: VirtualPLC, call: Call) -> bytes:
    req = request_of(call, FileDelete)
    deleted = _device(plc, req.disk).delete(_path(req.directory), list(req.names))
    return FileDeleteResult(deleted).encode()


def file_copy(plc: VirtualPLC, call: Call) -> bytes:
    req = request_of(call, FileCopy)
    source = _device(plc, req.source_disk).file(_path(req.source_directory), req.source_name)
    destination = _device(plc, req.destination_disk)
    destination.put_copy(_path(req.destination_directory), req.destination_name, source)
    return b""


def file_name_change(plc: VirtualPLC, call: Call) -> bytes:
    req = request_of(call, FileNameChange)
    _device(plc, req.disk).rename(_path(req.directory), req.old_name, req.new_name)
    return b""


def _compare(a: bytes, b: bytes, unit: int) -> int:
    """How many leading units (of ``unit`` bytes) agree; raise 2007 with it on a mismatch."""
    n = min(len(a), len(b))
    for i in range(0, n, unit):
        if a[i : i + unit] != b[i : i + unit]:
            n = i
            break
    if n != len(a) or n != len(b):
        size = 4 if unit == 1 else 2
        raise CommandFailed(DATA_MISMATCH, (n // unit).to_bytes(size, "big"))
    return n // unit


def memory_area_file_transfer(plc: VirtualPLC, call: Call) -> bytes:
    req = request_of(call, MemoryAreaFileTransfer)
    device, path, a = _device(plc, req.disk), _path(req.directory), req.address
    if req.mode == FileTransferMode.FILE_TO_AREA:
        data = bytes(device.file(path, req.name).data[: 2 * req.count])
        n = len(data) // 2
        plc.memory.write(a.area_code, a.word, a.bit, data[: 2 * n], n, FILL_AREAS)
        return FileTransferResult(n).encode()
    words = plc.memory.read(a.area_code, a.word, a.bit, req.count, FILL_AREAS)
    if req.mode == FileTransferMode.AREA_TO_FILE:  # files are never overwritten by a transfer
        device.create(path, req.name, words)
        return FileTransferResult(req.count).encode()
    compared = _compare(words, bytes(device.file(path, req.name).data), 2)
    return FileTransferResult(compared).encode()


def parameter_area_file_transfer(plc: VirtualPLC, call: Call) -> bytes:
    req = request_of(call, ParameterAreaFileTransfer)
    if req.area_code not in LAYOUT or req.begin != 0:
        raise CommandFailed(PARAMETER_ERROR, message="parameter area or beginning word")
    device, path = _device(plc, req.disk), _path(req.directory)
    base, size = LAYOUT[req.area_code]
    area = bytes(plc.parameter_memory[2 * base : 2 * (base + size)])
    if req.mode == FileTransferMode.AREA_TO_FILE:
        device.create(path, req.name, area)
        return FileTransferResult(size).encode()
    data = bytes(device.file(path, req.name).data)
    if req.mode == FileTransferMode.FILE_TO_AREA:
        n = min(len(data), 2 * size) // 2
        plc.parameter_memory[2 * base : 2 * (base + n)] = data[: 2 * n]
        return FileTransferResult(n).encode()
    return FileTransferResult(_compare(area, data, 2)).encode()


def program_area_file_transfer(plc: VirtualPLC, call: Call) -> bytes:
    req = request_of(call, ProgramAreaFileTransfer)
    device, path = _device(plc, req.disk), _path(req.directory)
    program = bytes(plc.program[: plc.program_length])
    if req.mode == FileTransferMode.AREA_TO_FILE:
        device.create(path, req.name, program)
        return ProgramAreaFileTransferResult(len(program)).encode()
    data = bytes(device.file(path, req.name).data)
    if req.mode == FileTransferMode.FILE_TO_AREA:
        data = data[: len(plc.program)]
        plc.program[:] = bytes(len(plc.program))
        plc.program[: len(data)] = data
        plc.program_length = len(data)
        return ProgramAreaFileTransferResult(len(data)).encode()
    return ProgramAreaFileTransferResult(_compare(program, data, 1)).encode()


def create_delete_directory(plc: VirtualPLC, call: Call) -> bytes:
    req = request_of(call, CreateDeleteDirectory)
    device, path = _device(plc, req.disk), _path(req.directory)
    if req.operation == DirectoryOperation.CREATE:
        device.make_directory(path, req.name)
    else:
        device.remove_directory(path, req.name)
    return b""


HANDLERS: dict[int, Handler] = by_command_code(
    {
        FileNameRead: file_name_read,
        SingleFileRead: single_file_read,
        SingleFileWrite: single_file_write,
        FileMemoryFormat: file_memory_format,
        FileDelete: file_delete,
        FileCopy: file_copy,
        FileNameChange: file_name_change,
        MemoryAreaFileTransfer: memory_area_file_transfer,
        ParameterAreaFileTransfer: parameter_area_file_transfer,
        ProgramAreaFileTransfer: program_area_file_transfer,
        CreateDeleteDirectory: create_delete_directory,
    }
)
