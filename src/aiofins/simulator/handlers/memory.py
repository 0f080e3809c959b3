"""I/O memory area access: 0101 read, 0102 write, 0103 fill, 0104 multiple read, 0105 transfer."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ...protocol.commands.memory import (
    MemoryAreaFill,
    MemoryAreaRead,
    MemoryAreaReadResult,
    MemoryAreaTransfer,
    MemoryAreaWrite,
    MultipleMemoryAreaRead,
    MultipleMemoryAreaReadItem,
    MultipleMemoryAreaReadResult,
)
from ..codes import by_command_code
from ..memory import MULTIPLE_READ_AREAS, READ_AREAS, WRITE_AREAS
from ._call import Call, Handler, request_of

if TYPE_CHECKING:
    from ..plc import VirtualPLC


def memory_area_read(plc: VirtualPLC, call: Call) -> bytes:
    req = request_of(call, MemoryAreaRead)
    a = req.address
    data = plc.memory.read(a.area_code, a.word, a.bit, req.count, READ_AREAS)
    return MemoryAreaReadResult(data, req.element_size).encode()


def memory_area_write(plc: VirtualPLC, call: Call) -> bytes:
    req = request_of(call, MemoryAreaWrite)
    a = req.address
    plc.memory.write(a.area_code, a.word, a.bit, req.data, req.count, WRITE_AREAS)
    return b""


def memory_area_fill(plc: VirtualPLC, call: Call) -> bytes:
    req = request_of(call, MemoryAreaFill)
    a = req.address
    plc.memory.fill(a.area_code, a.word, a.bit, req.count, req.value)
    return b""


def multiple_memory_area_read(plc: VirtualPLC, call: Call) -> bytes:
    req = request_of(call, MultipleMemoryAreaRead)
    items = []
    # every item is read before anything is returned: one bad item, nothing read
    for a in req.addresses:
        raw = plc.memory.read(a.area_code, a.word, a.bit, 1, MULTIPLE_READ_AREAS)
        items.append(MultipleMemoryAreaReadItem(a.area_code, int.from_bytes(raw, "big")))
    return MultipleMemoryAreaReadResult(tuple(items)).encode()


def memory_area_transfer(plc: VirtualPLC, call: Call) -> bytes:
    req = request_of(call, MemoryAreaTransfer)
    s, d = req.source, req.destination
    plc.memory.transfer((s.area_code, s.word, s.bit), (d.area_code, d.word, d.bit), req.count)
    return b""


HANDLERS: dict[int, Handler] = by_command_code(
    {
        MemoryAreaRead: memory_area_read,
        MemoryAreaWrite: memory_area_write,
        MemoryAreaFill: memory_area_fill,
        MultipleMemoryAreaRead: multiple_memory_area_read,
        MemoryAreaTransfer: memory_area_transfer,
    }
)
