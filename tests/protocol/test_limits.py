"""Per-network limits (manual 5-2-2, 5-3-5, 5-3-7/8, 5-3-10/11; W342 §3-5)."""

from __future__ import annotations

import dataclasses
import itertools

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiofins.protocol import hostlink
from aiofins.protocol.errors import CommandError
from aiofins.protocol.header import MAX_FRAME_SIZE, MAX_PARAMETER_SIZE, MAX_RESPONSE_DATA_SIZE
from aiofins.protocol.limits import (
    HOST_LINK_MAX_COMMAND_CHARS,
    HOST_LINK_MAX_PARAMETER_BYTES,
    HOST_LINK_MAX_RESPONSE_CHARS,
    HOST_LINK_MAX_RESPONSE_DATA_BYTES,
    MAX_FRAME,
    NETWORK_LIMITS,
    NetworkType,
    RouteLimits,
    limits_for,
)

E = NetworkType


def test_frame_constants_agree_with_the_framing_modules() -> None:
    assert MAX_FRAME == MAX_FRAME_SIZE == 2012
    assert MAX_PARAMETER_SIZE == 2000 and MAX_RESPONSE_DATA_SIZE == 1998
    assert HOST_LINK_MAX_COMMAND_CHARS == hostlink.MAX_COMMAND_CHARS == 1114
    assert HOST_LINK_MAX_RESPONSE_CHARS == hostlink.MAX_RESPONSE_CHARS == 1115
    assert HOST_LINK_MAX_PARAMETER_BYTES == hostlink.MAX_PARAMETER_BYTES == 540
    assert HOST_LINK_MAX_RESPONSE_DATA_BYTES == hostlink.MAX_RESPONSE_DATA_BYTES == 538


@pytest.mark.parametrize(
    ("network", "read", "write", "elements"),
    [
        (E.ETHERNET, 999, 997, 167),
        (E.CONTROLLER_LINK, 999, 997, 167),
        (E.SYSMAC_LINK, 269, 267, 89),
        (E.DEVICENET, 269, 267, 89),
        (E.SYSWAY, 269, 267, 89),
        (E.HOST_LINK, 269, 267, 89),
    ],
)
def test_manual_table(network: NetworkType, read: int, write: int, elements: int) -> None:
    limits = limits_for(network)
    assert (limits.memory_read_words, limits.memory_write_words) == (read, write)
    assert limits.multiple_read_elements == elements


def test_large_frame_networks_have_the_command_limits_of_the_manual() -> None:
    for network in (E.ETHERNET, E.CONTROLLER_LINK):
        limits = limits_for(network)
        assert limits.parameter_read_words == limits.parameter_write_words == 498
        assert (limits.program_read_bytes, limits.program_write_bytes) == (992, 996)
        assert (limits.max_parameter_bytes, limits.max_response_data_bytes) == (2000, 1998)


@pytest.mark.parametrize("network", list(NetworkType))
def test_every_limit_fits_the_network_frame(network: NetworkType) -> None:
    """Each count, turned into bytes, fits the parameter / response data size of the frame."""
    lim = limits_for(network)
    params, data = lim.max_parameter_bytes, lim.max_response_data_bytes
    assert 2 * lim.memory_read_words <= data  # 0101 response: words
    assert 6 + 2 * lim.memory_write_words <= params  # 0102: area(1) addr(2) bit(1) n(2) data
    assert 4 * lim.multiple_read_elements <= params  # 0104 command: 4 bytes per element
    assert 6 + 2 * lim.parameter_read_words <= data  # 0201 response: echo(6) + data
    assert 6 + 2 * lim.parameter_write_words <= params  # 0202 command
    assert 8 + lim.program_read_bytes <= data  # 0306 response: echo(8) + data
    assert 8 + lim.program_write_bytes <= params  # 0307 command
    assert lim.program_read_bytes % 4 == 0 and lim.program_write_bytes % 4 == 0


def test_the_memory_limits_are_exact_for_the_frame() -> None:
    """999/997 and 269/267 are the largest counts that fit: one more word would not."""
    for network in NetworkType:
        lim = limits_for(network)
        assert 2 * (lim.memory_read_words + 1) > lim.max_response_data_bytes
        assert 6 + 2 * (lim.memory_write_words + 1) > lim.max_parameter_bytes


def test_no_network_means_ethernet() -> None:
    assert limits_for() == limits_for(E.ETHERNET) == NETWORK_LIMITS[E.ETHERNET]


@given(st.lists(st.sampled_from(list(NetworkType)), min_size=1, max_size=4))
def test_route_takes_the_smallest_along_the_way(route: list[NetworkType]) -> None:
    limits = limits_for(*route)
    for field in dataclasses.fields(RouteLimits):
        expected = min(getattr(NETWORK_LIMITS[n], field.name) for n in route)
        assert getattr(limits, field.name) == expected
    assert limits_for(*reversed(route)) == limits


def test_mixed_route_example() -> None:
    # Ethernet → Controller Link → DeviceNet: the DeviceNet hop decides (manual 5-2-2).
    limits = limits_for(E.ETHERNET, E.CONTROLLER_LINK, E.DEVICENET)
    assert limits.memory_read_words == 269
    assert limits.memory_write_words == 267
    assert limits.multiple_read_elements == 89
    assert limits_for(E.ETHERNET, E.CONTROLLER_LINK).memory_read_words == 999


def test_overrides() -> None:
    limits = limits_for(E.ETHERNET, E.HOST_LINK, memory_read_words=100)
    assert limits.memory_read_words == 100
    assert limits.memory_write_words == 267
    tweaked = dataclasses.replace(limits_for(), program_write_bytes=512)
    assert tweaked.program_write_bytes == 512
    with pytest.raises(CommandError, match="unknown route limit"):
        limits_for(memory_read_word=5)
    with pytest.raises(CommandError, match="positive"):
        limits_for(memory_read_words=0)


def test_route_limits_are_frozen_and_hashable() -> None:
    limits = limits_for()
    with pytest.raises(dataclasses.FrozenInstanceError):
        limits.memory_read_words = 5  # type: ignore[misc]
    assert len({limits_for(*p) for p in itertools.permutations([E.ETHERNET, E.SYSWAY])}) == 1
