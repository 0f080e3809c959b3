"""Rendezvous hashing of PLC names over N gateways."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiofins import CommandError
from aiofins.gateway import Shard, parse_shard, shard_from_env
from aiofins.gateway.sharding import owner

NAMES = [f"plc{i:04}" for i in range(2000)]


def test_each_plc_belongs_to_exactly_one_shard_and_they_share_evenly() -> None:
    shards = [Shard(i, 4) for i in range(4)]
    owned = [set(s.select(NAMES)) for s in shards]
    assert set().union(*owned) == set(NAMES)
    assert sum(len(o) for o in owned) == len(NAMES)
    assert all(400 < len(o) < 600 for o in owned), [len(o) for o in owned]


def test_adding_a_shard_moves_only_the_plcs_it_wins() -> None:
    before = {n: owner(n, 4) for n in NAMES}
    after = {n: owner(n, 5) for n in NAMES}
    moved = [n for n in NAMES if before[n] != after[n]]
    assert all(after[n] == 4 for n in moved)  # only to the new shard
    assert 0.15 < len(moved) / len(NAMES) < 0.25  # about 1/5


@given(st.text(min_size=1, max_size=30), st.integers(1, 16))
def test_the_owner_is_one_shard_and_stable(name: str, count: int) -> None:
    got = owner(name, count)
    assert 0 <= got < count and owner(name, count) == got
    assert [Shard(i, count).owns(name) for i in range(count)].count(True) == 1


def test_shard_from_text_and_environment() -> None:
    assert parse_shard(" 1/3 ") == Shard(1, 3) and str(Shard(1, 3)) == "1/3"
    for bad in ("3/3", "1", "a/2", "-1/2", "0/0"):
        with pytest.raises(CommandError):
            parse_shard(bad)
    assert shard_from_env({}) is None
    assert shard_from_env({"AIOFINS_SHARD": "2/5"}) == Shard(2, 5)
    statefulset = {"AIOFINS_SHARDS": "4", "HOSTNAME": "aiofins-gateway-3"}
    assert shard_from_env(statefulset) == Shard(3, 4)
    with pytest.raises(CommandError, match="no -<ordinal> suffix"):
        shard_from_env({"AIOFINS_SHARDS": "4", "HOSTNAME": "gateway"})
    with pytest.raises(CommandError, match="0 <= I < N"):
        shard_from_env({"AIOFINS_SHARDS": "4", "HOSTNAME": "gw-4"})
