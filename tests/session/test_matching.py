"""Replies without the exact key of a request: relay errors (bit 15), matched by SID and
command code alone, and never to a request they were not for."""

from __future__ import annotations

from aiofins.protocol.frames import pack_head
from aiofins.session.matching import match_relay_error
from aiofins.session.slots import Pending


def key(network: int, node: int, sid: int) -> int:
    """A request's key: its destination's ``DNA DA1 DA2`` and its SID."""
    return (network << 24) | (node << 16) | sid


def relay_error(sid: int, mrc: int = 0x01, src: int = 0x01) -> bytes:
    """A 0205 relay error from the relay 1.9.0 (its own address, not the destination's),
    with its trailer: forwarding failed at network 1, node 9."""
    head = pack_head(bytes((0xC0, 0, 2, 0, 254, 0, 1, 9, 0)), sid, mrc, src)
    return head + b"\x82\x05\x01\x09"


def pending(*keys: int, mrc: int = 0x01, src: int = 0x01) -> dict[int, Pending]:
    return {k: _record(k, mrc, src) for k in keys}


def _record(k: int, mrc: int, src: int) -> Pending:
    p = Pending()
    p.blank(k, mrc, src)
    return p


def test_a_relay_error_reaches_the_one_request_with_its_sid_and_command() -> None:
    table = pending(key(3, 6, 7), key(2, 5, 8))
    assert match_relay_error(table, relay_error(7)) is table[key(3, 6, 7)]
    assert match_relay_error(table, relay_error(8)) is table[key(2, 5, 8)]
    assert match_relay_error(table, relay_error(9)) is None
    assert match_relay_error(table, relay_error(7, 0x01, 0x02)) is None  # another command


def test_a_relay_error_that_fits_several_requests_reaches_none() -> None:
    """Several requests in flight under one SID and command code (to different
    destinations through one relay): nothing in the error says which it is for. It was
    given to the one whose destination network is the relay's (1), a guess, and wrong when
    the error was for the request to network 3. The session never has one SID in flight to
    two destinations (the relay-error rule); this guard holds should it ever."""
    for keys in (
        (key(1, 5, 7), key(3, 6, 7)),  # one on the relay's network, one behind it
        (key(2, 5, 7), key(3, 6, 7), key(4, 7, 7)),
    ):
        table = pending(*keys, key(3, 6, 8))
        assert match_relay_error(table, relay_error(7)) is None
        assert match_relay_error(table, relay_error(8)) is table[key(3, 6, 8)]
