"""Source nodes per UDP peer: claimed, held, given back, cooling; the pool's and the
sessions' extra SID spaces take theirs from one registry."""

from __future__ import annotations

import pytest

from aiofins.protocol.errors import CommandError
from aiofins.protocol.header import FinsAddress
from aiofins.session.nodes import SourceNodes

PEER = "udp://127.0.0.1:9600"


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_claims_go_254_down_skipping_held_and_avoided_nodes() -> None:
    nodes = SourceNodes()
    nodes.hold(PEER, 254)
    assert nodes.claim(PEER, avoid={253, 1}) == 252
    assert nodes.claim(PEER) == 253
    assert nodes.in_use(PEER) == {252, 253, 254}
    assert nodes.in_use("udp://127.0.0.2:9600") == frozenset()  # per peer
    assert nodes.claim("udp://127.0.0.2:9600") == 254


def test_a_node_held_twice_is_free_once_both_gave_it_back() -> None:
    nodes = SourceNodes()
    nodes.hold(PEER, 7)
    nodes.hold(PEER, 7)
    nodes.release(PEER, 7)
    assert 7 in nodes.in_use(PEER)
    nodes.release(PEER, 7)
    nodes.release(PEER, 7)  # one release too many: nothing
    assert nodes.in_use(PEER) == frozenset()


def test_a_node_given_back_cools_before_it_is_claimed_again() -> None:
    clock = Clock()
    nodes = SourceNodes(clock)
    assert nodes.claim(PEER) == 254
    nodes.release(PEER, 254, cool_until=clock.now + 2)
    assert nodes.claim(PEER) == 253  # a late reply to 254's last socket may still come
    clock.now += 2
    assert nodes.in_use(PEER) == {253}
    assert nodes.claim(PEER) == 254
    nodes.release(PEER, 254, cool_until=clock.now + 5)
    nodes.hold(PEER, 254)  # held on purpose (a session told to use it): no longer cooling
    nodes.release(PEER, 254)
    assert nodes.in_use(PEER) == {253}


def test_all_254_taken() -> None:
    nodes = SourceNodes()
    assert [nodes.claim(PEER) for _ in range(254)] == list(range(254, 0, -1))
    assert nodes.claim(PEER) is None


def test_a_sessions_source_keeps_its_default_unless_in_use_and_a_named_one_is_refused() -> None:
    nodes = SourceNodes()
    default = FinsAddress(1, 254, 0)
    assert nodes.source_for(PEER, default, named=False, where="a") == default  # now held
    # in use, or a node addressed there: the next free one, network and unit kept
    assert nodes.source_for(PEER, default, named=False, avoid={253}, where="b") == FinsAddress(
        1, 252, 0
    )
    assert nodes.in_use(PEER) == {252, 254}
    with pytest.raises(CommandError, match=r"^c: source node 254 is used by another session to"):
        nodes.source_for(PEER, default, named=True, where="c")
    assert nodes.in_use(PEER) == {252, 254}  # a refusal holds nothing
    named = FinsAddress(0, 7, 0)
    assert nodes.source_for(PEER, named, named=True, avoid={7}, where="d") == named  # kept
    for node in range(1, 255):
        nodes.hold(PEER, node)
    with pytest.raises(CommandError, match="no free FINS source node"):
        nodes.source_for(PEER, default, named=False, where="e")
