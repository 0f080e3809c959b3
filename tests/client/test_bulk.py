"""Bulk transfers against the virtual PLC: program, parameters and file memory."""

from __future__ import annotations

import dataclasses
import re
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from datetime import datetime
from typing import Any

import anyio
import pytest

from aiofins.bulk import (
    backup_parameters,
    backup_program,
    check_program_image,
    download_file,
    list_files,
    restore_parameters,
    restore_program,
    upload_file,
)
from aiofins.connection import connect
from aiofins.protocol.commands._base import Request
from aiofins.protocol.commands.file import (
    FileNameRead,
    SingleFileRead,
    SingleFileReadResult,
)
from aiofins.protocol.commands.parameter import ParameterAreaRead
from aiofins.protocol.commands.program import ProgramAreaRead, ProgramAreaWrite
from aiofins.protocol.errors import CommandError, DecodeError
from aiofins.protocol.files import Disk, DiskData, FileDate, FileEntry, FileNameReadResult
from aiofins.protocol.header import CommandFrame, ResponseFrame
from aiofins.protocol.limits import NetworkType
from aiofins.simulator.plc import VirtualPLC
from aiofins.simulator.runner import run_simulator

pytestmark = pytest.mark.anyio


async def test_program_backup_clear_restore_gives_identical_bytes(url: str) -> None:
    async with connect(url, timeout=2) as plc:
        await plc.stop()
        image = bytes((i * 13) & 0xFF for i in range(5000 * 4))
        await restore_program(plc, image)
        steps: list[tuple[int, int | None]] = []
        backup = await backup_program(plc, progress=lambda d, t: steps.append((d, t)))
        assert backup[: len(image)] == image
        assert steps[-1][1] == len(backup)
        await plc.program_area_clear()
        assert await backup_program(plc) != backup
        await restore_program(plc, backup)
        assert await backup_program(plc) == backup


async def test_program_restore_refuses_run_mode_before_sending(url: str) -> None:
    async with connect(url, timeout=2) as plc:
        await plc.run()
        with pytest.raises(CommandError, match="PROGRAM mode"):
            await restore_program(plc, b"\0" * 8)


async def test_parameter_backup_and_restore(url: str) -> None:
    async with connect(url, timeout=2) as plc:
        await plc.stop()
        backup = await backup_parameters(plc)
        assert {k: len(v) for k, v in backup.items()} == {
            0x8010: 512,
            0x8012: 1280,
            0x8013: 512,
            0x8002: 5184,
        }
        changed = dict(backup)
        changed[0x8010] = tuple((i * 3) & 0xFFFF for i in range(512))
        await restore_parameters(plc, changed)
        assert (await backup_parameters(plc))[0x8010] == changed[0x8010]


async def test_a_bad_area_in_a_parameter_backup_writes_nothing(url: str) -> None:
    """The whole backup is checked first: no area restored before the bad one."""
    async with connect(url, timeout=2) as plc:
        await plc.stop()
        before = await backup_parameters(plc)
        good = tuple((i * 7) & 0xFFFF for i in range(512))
        for bad, said in (
            ({0x8012: (1, 2)}, "parameter area 8012: backup has 2 words, the area 1280"),
            ({0x8099: (0,) * 512}, "parameter area 8099 unknown"),
            ({0x8013: (0x10000,) * 512}, "word 65536 out of range 0..FFFF"),
        ):
            with pytest.raises(CommandError, match=re.escape(said)):
                await restore_parameters(plc, {0x8010: good, **bad})
        assert await backup_parameters(plc) == before
        # Not in PROGRAM mode: nothing written (the I/O table would be refused half-way).
        await plc.run()
        with pytest.raises(CommandError, match="restoring parameter areas needs PROGRAM mode"):
            await restore_parameters(plc, {0x8010: good, 0x8012: before[0x8012]})
        assert await backup_parameters(plc) == before


@pytest.mark.parametrize("networks", [(), (NetworkType.SYSMAC_LINK,)])
async def test_file_upload_list_download(url: str, networks: tuple[NetworkType, ...]) -> None:
    data = bytes(range(256)) * 40
    async with connect(url, timeout=2, networks=networks) as plc:
        await upload_file(plc, Disk.MEMORY_CARD, "DATA.BIN", data)
        names = [e.name for e in await list_files(plc, Disk.MEMORY_CARD)]
        assert "DATA.BIN" in names
        seen: list[int] = []
        got = await download_file(
            plc, Disk.MEMORY_CARD, "DATA.BIN", progress=lambda d, t: seen.append(d)
        )
        assert got == data
        assert len(seen) == (6 if not networks else 20)


def test_program_images_that_are_not_programs_are_refused() -> None:
    check_program_image(bytes(range(8)))
    check_program_image(b"{not json}  ")  # binary that happens to start with '{'
    for image, said in (
        (b"", "empty"),
        (b"123", "multiple of 4"),
        (b'{"8010": [1, 2, 3, 4]}  ', "JSON document"),
        (b"[1, 2, 3, 4]", "JSON document"),
    ):
        with pytest.raises(CommandError, match=said):
            check_program_image(image)


async def test_an_upload_that_does_not_fit_leaves_the_old_file(url: str) -> None:
    """The first frame replaces the old file: running out of space half-way left a truncated
    file of zeros under its name (1104 at the 60th frame). The space is checked first."""
    async with connect(url, timeout=2) as plc:
        disk = Disk.EM_FILE_MEMORY
        await upload_file(plc, disk, "CFG.BIN", b"good old contents")
        free = (await plc.file_name_read(disk, 0, 1)).disk_data.unused_capacity
        await upload_file(plc, disk, "FILL.BIN", bytes(free - 1000))
        with pytest.raises(CommandError, match=r"CFG\.BIN: 2017 bytes do not fit: .* nothing"):
            await upload_file(plc, disk, "CFG.BIN", bytes(2017))
        assert await download_file(plc, disk, "CFG.BIN") == b"good old contents"
        await upload_file(plc, disk, "CFG.BIN", bytes(1000))  # fits with the old file's room
        assert await download_file(plc, disk, "CFG.BIN") == bytes(1000)


# -- a PLC that lies in its echoes ------------------------------------------------------------

#: Rewrites the result of one command (the request as decoded, the true result).
Lie = Callable[[Any, Any], Any]


class LyingPLC:
    """The virtual PLC, except that one command's results pass through ``lie`` first (with
    ``invent``, the lie alone answers that command: it gets ``None`` for the true result)."""

    def __init__(self, command: type[Request[Any]], lie: Lie, *, invent: bool = False) -> None:
        self.plc = VirtualPLC()
        self.command = command
        self.lie = lie
        self.invent = invent
        #: The distinct frames of ``command`` received: a UDP retransmission (same frame,
        #: same SID, sent again when a reply is late, as on a loaded machine) is one request.
        self.frames: set[bytes] = set()

    @property
    def asked(self) -> int:
        """How many requests of ``command`` the PLC received (retransmissions not counted)."""
        return len(self.frames)

    def handle_frame(self, frame: bytes, *, from_network: bool = True) -> bytes | None:
        cmd = CommandFrame.decode(frame)
        mine = (cmd.mrc, cmd.src) == (self.command.MRC, self.command.SRC)
        if mine:
            self.frames.add(bytes(frame))
        if mine and self.invent:
            result = self.lie(self.command.decode(cmd.params), None)
            return ResponseFrame.reply_to(cmd, 0, result.encode()).encode()
        reply = self.plc.handle_frame(frame, from_network=from_network)
        if not mine or reply is None:
            return reply
        request = self.command.decode(cmd.params)
        response = ResponseFrame.decode(reply)
        if response.end_code.code:  # an error answer: nothing to lie about
            return reply
        result = self.lie(request, request.decode_response(response.data))
        return dataclasses.replace(response, data=result.encode()).encode()


@asynccontextmanager
async def lying(
    scheme: str, command: type[Request[Any]], lie: Lie, *, invent: bool = False
) -> AsyncIterator[Any]:
    """A client of a :class:`LyingPLC` on loopback; yields ``(client, peer)``."""
    peer = LyingPLC(command, lie, invent=invent)
    where = ("127.0.0.1", 0)
    async with run_simulator(
        peer, udp=where if scheme == "udp" else None, tcp=where if scheme == "tcp" else None
    ) as sim:
        port = sim.udp_port if scheme == "udp" else sim.tcp_port
        async with connect(f"{scheme}://127.0.0.1:{port}", timeout=2) as plc:
            yield plc, peer


@pytest.fixture
def anyio_scheme(anyio_backend: object, scheme: str) -> str:
    return scheme


async def test_a_program_backup_refuses_a_block_echoed_at_the_wrong_address(
    anyio_scheme: str,
) -> None:
    """A PLC echoing address 0 gave a 2,976-byte "backup" of three overlapping blocks."""

    def lie(request: ProgramAreaRead, result: Any) -> Any:
        return dataclasses.replace(result, address=0)

    async with lying(anyio_scheme, ProgramAreaRead, lie) as (plc, peer):
        await restore_program(plc, bytes(range(256)) * 10)  # 3 blocks of 992 bytes
        with pytest.raises(DecodeError, match=r"asked for address 000003E0, .* for 00000000"):
            await backup_program(plc)
        assert peer.asked == 2


async def test_a_program_backup_without_a_last_block_stops_at_max_size(
    anyio_scheme: str,
) -> None:
    def lie(request: ProgramAreaRead, result: Any) -> Any:
        return dataclasses.replace(result, last=False)

    async with lying(anyio_scheme, ProgramAreaRead, lie) as (plc, peer):
        with pytest.raises(DecodeError, match="no last-block bit within 4002 bytes"):
            await backup_program(plc, max_size=4002)
        assert peer.asked == 5  # 992 * 4 + 32


async def test_a_program_backup_refuses_more_bytes_than_asked(anyio_scheme: str) -> None:
    def lie(request: ProgramAreaRead, result: Any) -> Any:
        return dataclasses.replace(result, data=bytes(request.byte_count + 4))

    async with lying(anyio_scheme, ProgramAreaRead, lie) as (plc, _):
        with pytest.raises(DecodeError, match="asked for 992 bytes, the PLC answered 996"):
            await backup_program(plc)


async def test_a_program_restore_refuses_a_wrong_echo(anyio_scheme: str) -> None:
    def lie(request: ProgramAreaWrite, result: Any) -> Any:
        return dataclasses.replace(result, address=0)

    async with lying(anyio_scheme, ProgramAreaWrite, lie) as (plc, peer):
        with pytest.raises(DecodeError, match=r"sent 996 bytes at 000003E4, .* echoed 996 at 0"):
            await restore_program(plc, bytes(4000))
        assert peer.asked == 2


async def test_a_parameter_backup_refuses_a_wrong_echo(anyio_scheme: str) -> None:
    def lie(request: ParameterAreaRead, result: Any) -> Any:
        return dataclasses.replace(result, begin_word=0)

    async with lying(anyio_scheme, ParameterAreaRead, lie) as (plc, _):
        with pytest.raises(DecodeError, match=r"from word 498, the PLC answered 14 words .* 0$"):
            await backup_parameters(plc, (0x8010,))


def _endless_file(request: SingleFileRead, result: Any) -> SingleFileReadResult:
    """A 4 GiB file that never ends: whatever was asked, never the last byte."""
    return SingleFileReadResult(0xFFFFFFFF, request.position, bytes(request.length), False)


async def test_a_download_refuses_a_file_larger_than_max_size(anyio_scheme: str) -> None:
    """173,000 requests in 20 s, RSS growing, until "last" that never came."""
    async with lying(anyio_scheme, SingleFileRead, _endless_file) as (plc, peer):
        await upload_file(plc, Disk.MEMORY_CARD, "A.BIN", b"x")
        with anyio.fail_after(5), pytest.raises(DecodeError, match="4294967295 bytes, more"):
            await download_file(plc, Disk.MEMORY_CARD, "A.BIN")
        assert peer.asked == 2  # the upload's existence check, then one read
        with anyio.fail_after(5), pytest.raises(DecodeError, match="4294967295 bytes, more"):
            await download_file(plc, Disk.MEMORY_CARD, "A.BIN", max_size=10_000_000)


@pytest.mark.parametrize(
    ("lie", "said"),
    [
        (
            lambda q, r: dataclasses.replace(r, position=0),
            "asked for position 1988 of a 5000-byte file, the PLC answered position 0 of 5000",
        ),
        (
            lambda q, r: dataclasses.replace(r, file_capacity=r.file_capacity + q.position),
            "asked for position 1988 of a 5000-byte file, the PLC answered position 1988 of 6988",
        ),
        (
            # the last request asks for what remains (a full frame + 1 would not fit a frame)
            lambda q, r: dataclasses.replace(r, data=r.data + b"!") if q.length < 1988 else r,
            "asked for 1024 bytes at position 3976 of a 5000-byte file, the PLC answered 1025",
        ),
        (
            lambda q, r: dataclasses.replace(r, data=b"", last=False) if q.position else r,
            "asked for 1988 bytes at position 1988 of a 5000-byte file, the PLC answered 0",
        ),
        (
            lambda q, r: dataclasses.replace(r, last=True),
            "the PLC flags byte 1988 the last of a 5000-byte file",
        ),
    ],
    ids=["position", "capacity", "more-data", "no-data", "last-early"],
)
async def test_a_download_checks_every_echo(anyio_scheme: str, lie: Lie, said: str) -> None:
    async with lying(anyio_scheme, SingleFileRead, lie) as (plc, _):
        await upload_file(plc, Disk.MEMORY_CARD, "A.BIN", bytes(5000), overwrite=False)
        with anyio.fail_after(5), pytest.raises(DecodeError, match=re.escape(said)):
            await download_file(plc, Disk.MEMORY_CARD, "A.BIN")


def _pages_for_ever(total: int) -> Lie:
    """A directory of ``total`` files that never flags its last page: it answers as many
    made-up entries as asked, whatever the position."""
    date = FileDate.from_datetime(datetime(2024, 1, 1))

    def lie(request: FileNameRead, result: None) -> FileNameReadResult:
        disk = DiskData("CARD", date, 1 << 20, 1 << 19, total)
        files = tuple(
            FileEntry(f"F{request.first_file + i}.BIN", date, 1) for i in range(request.count)
        )
        return FileNameReadResult(disk, files, last=False)

    return lie


async def test_a_listing_stops_at_the_announced_number_of_files(anyio_scheme: str) -> None:
    """65,536 requests against a PLC that never flags the last page."""
    async with lying(anyio_scheme, FileNameRead, _pages_for_ever(45), invent=True) as (
        plc,
        peer,
    ):
        with anyio.fail_after(5):
            entries = await list_files(plc, Disk.MEMORY_CARD)
        assert [e.name for e in entries] == [f"F{i}.BIN" for i in range(45)]
        assert peer.asked == 3


async def test_a_listing_refuses_more_files_than_announced(anyio_scheme: str) -> None:
    async with lying(anyio_scheme, FileNameRead, _pages_for_ever(3), invent=True) as (plc, _):
        with pytest.raises(DecodeError, match=r"asked for 20 of 3 files from file 0, .* 20"):
            await list_files(plc, Disk.MEMORY_CARD)


# -- a PLC that answers a little at a time: every short answer must be the end -----------------


async def test_a_program_backup_refuses_a_short_block_without_the_last_bit(
    anyio_scheme: str,
) -> None:
    """4 bytes an answer, never the last: 1,048,576 requests before max_size stopped it."""

    def lie(request: ProgramAreaRead, result: Any) -> Any:
        return dataclasses.replace(result, data=result.data[:4], last=False)

    async with lying(anyio_scheme, ProgramAreaRead, lie) as (plc, peer):
        with (
            anyio.fail_after(5),
            pytest.raises(
                DecodeError, match=r"at 00000000: asked for 992 bytes, the PLC answered 4 .* last"
            ),
        ):
            await backup_program(plc)
        assert peer.asked == 1


async def test_a_download_refuses_a_short_answer_before_the_end(anyio_scheme: str) -> None:
    """One byte an answer: a 64 MiB file announced took 64 million requests."""

    def lie(request: SingleFileRead, result: Any) -> Any:
        return dataclasses.replace(result, data=result.data[:1], last=False)

    async with lying(anyio_scheme, SingleFileRead, lie) as (plc, peer):
        await upload_file(plc, Disk.MEMORY_CARD, "A.BIN", bytes(5000), overwrite=False)
        with (
            anyio.fail_after(5),
            pytest.raises(
                DecodeError,
                match="asked for 1988 bytes at position 0 of a 5000-byte file, the PLC answered 1",
            ),
        ):
            await download_file(plc, Disk.MEMORY_CARD, "A.BIN")
        assert peer.asked == 1


async def test_a_listing_refuses_a_short_page_that_is_not_the_last(anyio_scheme: str) -> None:
    """One entry a page, never the last: a directory announcing 65,535 files took 65,535
    requests."""
    pages = _pages_for_ever(65_535)

    def lie(request: FileNameRead, result: None) -> FileNameReadResult:
        page: FileNameReadResult = pages(request, result)
        return dataclasses.replace(page, files=page.files[:1])

    async with lying(anyio_scheme, FileNameRead, lie, invent=True) as (plc, peer):
        with (
            anyio.fail_after(5),
            pytest.raises(
                DecodeError, match=r"asked for 20 of 65535 files from file 0, the PLC answered 1 "
            ),
        ):
            await list_files(plc, Disk.MEMORY_CARD)
        assert peer.asked == 1


async def test_short_answers_at_the_end_are_what_a_plc_sends(anyio_scheme: str) -> None:
    """The checks above leave the usual ends alone: a program, a file and a directory whose
    size is not a whole number of frames."""
    async with lying(anyio_scheme, ProgramAreaRead, lambda q, r: r) as (plc, _):
        await plc.stop()
        await restore_program(plc, bytes(range(256)) * 5)
        assert (await backup_program(plc))[:1280] == bytes(range(256)) * 5
        for size in (0, 1, 1987, 1988, 1989, 5000):
            await upload_file(plc, Disk.MEMORY_CARD, f"F{size}.BIN", bytes(size))
            assert await download_file(plc, Disk.MEMORY_CARD, f"F{size}.BIN") == bytes(size)
        names = [e.name for e in await list_files(plc, Disk.MEMORY_CARD)]
        assert {f"F{size}.BIN" for size in (0, 1, 1987, 1988, 1989, 5000)} <= set(names)


@pytest.mark.parametrize("max_size", [-1, 0, 2.5, "100", True])
async def test_a_bad_max_size_is_refused_before_anything_is_sent(
    anyio_scheme: str, max_size: Any
) -> None:
    """``max_size=-1`` sent a request and blamed the PLC (DecodeError); ``max_size=0`` did
    the same without sending anything; ``"100"`` leaked a TypeError."""
    async with lying(anyio_scheme, ProgramAreaRead, lambda q, r: r) as (plc, peer):
        sent = plc.session.stats.completed
        with pytest.raises(CommandError, match="max_size must be a whole number of bytes, at"):
            await backup_program(plc, max_size=max_size)
        with pytest.raises(CommandError, match="max_size must be a whole number of bytes, at"):
            await download_file(plc, Disk.MEMORY_CARD, "A.BIN", max_size=max_size)
        assert plc.session.stats.completed == sent and peer.asked == 0


@pytest.mark.parametrize("total", [0, 3])
async def test_a_listing_ending_at_the_announced_total_needs_no_last_bit(
    anyio_scheme: str, total: int
) -> None:
    """An empty directory's page may not flag a last file it does not have: it is the end."""
    pages = _pages_for_ever(total)

    def lie(request: FileNameRead, result: None) -> FileNameReadResult:
        page: FileNameReadResult = pages(request, result)
        return dataclasses.replace(page, files=page.files[:total])

    async with lying(anyio_scheme, FileNameRead, lie, invent=True) as (plc, peer):
        entries = await list_files(plc, Disk.MEMORY_CARD)
        assert [e.name for e in entries] == [f"F{i}.BIN" for i in range(total)]
        assert peer.asked == 1
