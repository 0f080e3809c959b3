"""read_array / write_array against the virtual PLC over loopback UDP and FINS/TCP (asyncio,
uvloop, trio): words, bytes, typed arrays, chunking and progress."""

from __future__ import annotations

from array import array
from typing import cast

import pytest

from aiofins.connection import connect
from aiofins.protocol.arrays import word_bytes
from aiofins.protocol.errors import AddressError, CommandError, DecodeError
from aiofins.protocol.limits import NetworkType
from aiofins.simulator.faults import FaultRule
from aiofins.simulator.plc import VirtualPLC
from aiofins.simulator.runner import Simulator

from ..session.test_session_udp import Reply, reply, udp_responder, word_data

pytestmark = pytest.mark.anyio

DM = 0x82


def memory(sim: Simulator) -> VirtualPLC:
    return cast(VirtualPLC, sim.plc)


async def test_a_full_dm_read_is_an_array_of_the_plcs_words_in_33_frames(
    sim: Simulator, url: str
) -> None:
    data = [(i * 7 + 3) & 0xFFFF for i in range(32768)]
    memory(sim).memory.write_words(DM, 0, data)
    async with connect(url, timeout=2) as plc:
        before = plc.session.stats.completed
        words = await plc.read_array("D0", 32768)
        assert plc.session.stats.completed - before == 33  # ceil(32768 / 999), as read()
        assert words.typecode == "H" and len(words) == 32768
        assert words.tolist() == data
        words.append(1)  # an array of its own: no buffer of it left exported
        # The bytes: what the PLC sent (big-endian words) is word_bytes() of the array.
        raw = (await plc.memory_area_read("D1000", 999)).data
        assert word_bytes(words[1000:1999]) == raw
        assert raw[:2] == data[1000].to_bytes(2, "big")


async def test_a_route_of_smaller_frames_chunks_the_same_way(sim: Simulator, url: str) -> None:
    memory(sim).memory.write_words(DM, 0, list(range(32768)))
    async with connect(url, timeout=2, networks=(NetworkType.SYSMAC_LINK,)) as plc:
        before = plc.session.stats.completed
        words = await plc.read_array("D0", 32768)
        assert plc.session.stats.completed - before == 122  # ceil(32768 / 269)
        assert words == array("H", range(32768))
        before = plc.session.stats.completed
        await plc.write_array("D0", array("H", [9] * 600), allow_split=True)
        assert plc.session.stats.completed - before == 3  # ceil(600 / 267)
        assert memory(sim).memory.read_words(DM, 0, 601) == [9] * 600 + [600]


async def test_write_array_writes_the_words_and_leaves_the_array_as_it_was(
    sim: Simulator, url: str
) -> None:
    words = array("H", [0, 1, 0x1234, 0xFFFF] * 500)  # 2,000 words: three frames
    async with connect(url, timeout=2) as plc:
        with pytest.raises(CommandError, match="not atomic"):
            await plc.write_array("D100", words)
        assert memory(sim).memory.read_words(DM, 100, 4) == [0, 0, 0, 0]  # nothing sent
        seen: list[tuple[int, int]] = []
        await plc.write_array(
            "D100", words, allow_split=True, progress=lambda d, t: seen.append((d, t))
        )
        assert seen == [(997, 2000), (1994, 2000), (2000, 2000)]  # 997 words per 0102
        assert words.tolist() == [0, 1, 0x1234, 0xFFFF] * 500  # swapped in copies only
        assert memory(sim).memory.read_words(DM, 100, 2000) == words.tolist()
        assert (await plc.memory_area_read("D102", 1)).data == b"\x12\x34"
        await plc.write_array("D0", array("H"))  # nothing: the normal empty write
        assert len(await plc.read_array("D0", 0)) == 0


async def test_typed_arrays_in_the_clients_and_the_specs_word_order(
    sim: Simulator, url: str
) -> None:
    async with connect(url, timeout=2) as plc:
        await plc.write_values("D200", [-2.5, 0.75, 1e6], "float32")
        floats = await plc.read_array("D200", 3, "float32")
        assert floats.typecode == "f" and floats.tolist() == [-2.5, 0.75, 1e6]
        assert memory(sim).memory.read_words(DM, 200, 2) == [0x0000, 0xC020]  # CDAB
        await plc.write_array("D300", array("i", [-1, 70000]), "int32:ABCD")
        assert memory(sim).memory.read_words(DM, 300, 4) == [0xFFFF, 0xFFFF, 0x0001, 0x1170]
        assert await plc.read_values("D300", "int32:ABCD", 2) == [-1, 70000]
        assert (await plc.read_array("D300", 2, "int32:ABCD")).tolist() == [-1, 70000]
        await plc.write_array("D400", [1.5, -1.0], "float64")
        assert await plc.read_values("D400", "float64", 2) == [1.5, -1.0]
    async with connect(url, timeout=2, word_order="ABCD") as plc:
        assert (await plc.read_array("D300", 2, "int32")).tolist() == [-1, 70000]
        assert (await plc.read_array("D200", 1, "float32:CDAB")).tolist() == [-2.5]


async def test_progress_counts_words_as_the_replies_come(url: str) -> None:
    async with connect(url, timeout=2) as plc:
        seen: list[tuple[int, int]] = []
        words = await plc.read_array(
            "D0", 1000, "float32", progress=lambda d, t: seen.append((d, t))
        )
        assert len(words) == 1000
        assert sorted(seen) == [(999, 2000), (1998, 2000), (2000, 2000)]
        seen.clear()
        await plc.read_array("D0", 10, progress=lambda d, t: seen.append((d, t)))
        assert seen == [(10, 10)]


async def test_what_read_array_cannot_take_is_refused_before_sending(url: str) -> None:
    async with connect(url, timeout=2) as plc:
        stats = plc.session.stats
        sent = (stats.completed, stats.end_code_errors, stats.timeouts)
        with pytest.raises(CommandError, match="a bit address"):
            await plc.read_array("CIO 0.01", 4)
        with pytest.raises(CommandError, match="no array form"):
            await plc.read_array("D0", 4, "bcd16")
        with pytest.raises(AddressError):
            await plc.read_array("D32767", 2)  # past the end of DM
        with pytest.raises(CommandError, match="count"):
            await plc.read_array("D0", -1)
        with pytest.raises(CommandError, match="sequence of numbers, got bytes"):
            await plc.write_array("D0", b"\x00\x01")
        with pytest.raises(CommandError, match="70000"):
            await plc.write_array("D0", [70000])
        assert (stats.completed, stats.end_code_errors, stats.timeouts) == sent


async def test_arrays_keep_to_each_destinations_route() -> None:
    """The route map of the plant's example: Ethernet-sized frames to the gateway itself,
    SYSMAC LINK-sized (269 words read, 267 written) to the press two networks away."""
    from .test_routes import largest_on, plant_client

    async with plant_client() as (plant, plc):
        assert (await plc.read_array("D0", 2, dest="3.5.0")).tolist() == [1234, 5678]
        plant.trace.clear()
        assert len(await plc.read_array("D0", 999, dest="3.5.0")) == 999
        replies = [h for h in plant.trace if h.network == 3 and h.frame[0] & 0x40]
        assert len(replies) == 4  # ceil(999 / 269)
        assert largest_on(plant, 3) == 538
        plant.trace.clear()
        assert len(await plc.read_array("D0", 999)) == 999  # one frame to the gateway
        assert largest_on(plant, 1) == 1998
        with pytest.raises(CommandError, match="267"):
            await plc.write_array("D0", array("H", [1] * 268), dest="3.5.0")
        await plc.write_array("D10", array("H", [7, 8, 9]), dest="3.5.0")
        assert plant.station("press").plc.read("D10", 3) == [7, 8, 9]


async def test_a_big_read_keeps_the_cpu_flags_of_its_last_reply(sim: Simulator, url: str) -> None:
    memory(sim).memory.write_words(DM, 0, list(range(3000)))
    sim.plan.rule = FaultRule(flags=0x40)  # non-fatal CPU error: every reply still normal
    async with connect(url, timeout=2) as plc:
        assert await plc.read_array("D0", 3000) == array("H", range(3000))
        assert plc.last_end_code is not None and plc.last_end_code.raw == 0x0040
        assert await plc.read("D0", 3000) == list(range(3000))
        assert plc.last_end_code.raw == 0x0040
        sim.plan.rule = FaultRule()
        assert await plc.read_array("D0", 3000) == array("H", range(3000))
        assert plc.last_end_code.raw == 0


async def test_a_reply_of_the_wrong_size_is_a_decode_error_and_ends_the_read() -> None:
    """Each frame's data is checked for its size before it is copied into the array: the
    second frame (words 999-1997) answered a word short ends the read with the error."""

    def one_short(cmd: bytes) -> list[Reply]:
        data = word_data(cmd)
        return [(0.0, reply(cmd, 0, data[:-2] if cmd[13:15] == b"\x03\xe7" else data))]

    async with (
        udp_responder(one_short) as peer,
        connect(f"udp://127.0.0.1:{peer.port}?node=1", timeout=2) as plc,
    ):
        for read in (plc.read_array, plc.read):
            with pytest.raises(DecodeError, match=r"expected 999 x 2 = 1998 data bytes, got 1996"):
                await read("D0", 3000)
            assert plc.session.stats.in_flight == 0
        assert (await plc.read_array("D0", 998)).tolist() == [(1 << 12) ^ w for w in range(998)]
