"""Bulk transfers against the virtual PLC: program, parameters and file memory."""

from __future__ import annotations

import re

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
from aiofins.protocol.errors import CommandError
from aiofins.protocol.files import Disk
from aiofins.protocol.limits import NetworkType

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
