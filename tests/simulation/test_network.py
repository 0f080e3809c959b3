"""The network's ground truth for a wrong answer (tests/simulation/network.py): a late
original reply is the exposed kind only when its round trip was longer than twice any the
link had shown when its SID was reused."""

from __future__ import annotations

import random

import pytest

from aiofins.memnet import Packet
from aiofins.simulator import EthernetUnit

from .loop import VirtualTimeLoop
from .network import Network
from .plant import Unit

CLIENT = ("10.8.0.1", 9600)
WORDS = bytes.fromhex("02ae02cc")


@pytest.mark.parametrize(("shown", "cause"), [(0.4, "late"), (0.2, "slow")])
def test_a_late_reply_is_exposed_only_beyond_twice_the_round_trips_shown(
    shown: float, cause: str
) -> None:
    """An earlier read's reply showed a round trip of ``shown`` (plus the network's few
    ms); a read under SID 7 is sent at 1.0 s, reaches the PLC at once, and its reply goes
    at 1.65 s, 0.1 s at most on its way (a delay episode); a read reuses SID 7 at 1.66 s
    and the first read's reply answers it: ``"slow"`` when its round trip (0.65 s and
    more) is more than twice what the link had shown (0.2 s), ``"late"`` when not (0.4 s:
    a quarantine bounded by the round trips shown could have held the SID, a defect)."""
    loop = VirtualTimeLoop()
    try:
        net = Network(loop, random.Random(1), lambda: None)
        unit = Unit(1, {}, EthernetUnit("10.0.0.1"), random.Random(1), loop.time, net)
        net.add_unit(unit)
        number = iter(range(1, 100))
        arrivals: list[float] = []

        def send(at: float, sid: int, to_unit: bool, words: bytes = b"") -> None:
            loop.clock.now = at
            head = bytes((0x80 if to_unit else 0xC0, 0, 2, 0, 1, 0, 0, 8, 0, sid))
            body = bytes.fromhex("0101820000000002" if to_unit else "01010000") + words
            source, dest = (CLIENT, unit.address) if to_unit else (unit.address, CLIENT)
            net._answering = CLIENT  # (what Network._send sets while a unit replies)
            delays = net.fate(Packet("datagram", source, dest, head + body, next(number)))
            arrivals.append(at + delays[0])

        send(0.0, 3, True)
        send(shown, 3, False, bytes(4))
        send(1.0, 7, True)
        unit.faults["delay"] = 0.1
        send(1.65, 7, False, WORDS)
        unit.faults.clear()
        send(1.66, 7, True)
        assert arrivals[3] > arrivals[4]  # (the reply came after the reuse's command went)
        loop.clock.now = 1.8
        assert net.original_answered(WORDS, 1.66, 1.8) == cause
        assert net.copy_answered(WORDS, 1.66, 1.8) == ""
    finally:
        loop.close()


@pytest.mark.parametrize(("again", "cause"), [("820000000002", "poll"), ("820010000002", "copy")])
def test_a_copy_of_a_poll_s_reply_to_the_same_question_asked_again_is_named_so(
    again: str, cause: str
) -> None:
    """A read of D0-D1 under SID 7 at 1.0 s is answered at 1.01 s, and the network copies
    that reply (a copy of another reply reached the socket before: not the link's first).
    The SID carries another read at 1.02 s, before the copy comes, and the copy answers it:
    ``"poll"`` when that read asked D0-D1 again (no client can tell the copy from its own
    reply: exposed), ``"copy"`` when it asked other words (a defect: the duplicate rule
    holds such a copy back)."""
    loop = VirtualTimeLoop()
    try:
        net = Network(loop, random.Random(1), lambda: None)
        unit = Unit(1, {}, EthernetUnit("10.0.0.1"), random.Random(1), loop.time, net)
        net.add_unit(unit)
        unit.faults["dup"] = 1.0
        number = iter(range(1, 100))
        arrivals: list[float] = []

        def send(at: float, sid: int, body: str) -> None:
            loop.clock.now = at
            to_unit = body.startswith("010182")
            head = bytes((0x80 if to_unit else 0xC0, 0, 2, 0, 1, 0, 0, 8, 0, sid))
            source, dest = (CLIENT, unit.address) if to_unit else (unit.address, CLIENT)
            net._answering = CLIENT  # (what Network._send sets while a unit replies)
            frame = head + bytes.fromhex(body)
            delays = net.fate(Packet("datagram", source, dest, frame, next(number)))
            arrivals.append(at + max(delays))  # (a reply's copy: the later)

        send(0.0, 3, "0101820000000002")
        send(0.01, 3, "01010000" + "0000" * 2)
        send(1.0, 7, "0101820000000002")
        send(1.01, 7, "01010000" + WORDS.hex())
        send(1.02, 7, "0101" + again)
        assert arrivals[3] > 1.02  # (the copy came after the SID was reused)
        assert net.copy_answered(WORDS, 1.02, 2.0) == cause
    finally:
        loop.close()
