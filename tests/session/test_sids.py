"""SidSpace: the SIDs and requests in flight of one transport, without a session."""

from __future__ import annotations

from time import monotonic

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aiofins.protocol.header import FinsAddress
from aiofins.session.matching import LATE_REPLY_GRACE
from aiofins.session.response import SessionStats
from aiofins.session.sids import HOLD_WINDOW, MAX_LINGER, SidSpace
from aiofins.session.slots import DestState, Pending, SlotQueue

PLC = FinsAddress(0, 1, 0)
OTHER = FinsAddress(0, 2, 0)


def dest(address: FinsAddress = PLC) -> DestState:
    return DestState(address, b"", SlotQueue(5))


def record(key: int) -> Pending:
    """A request of 0101 under ``key``, not sent."""
    p = Pending()
    p.blank(key, 0x01, 0x01)
    return p


def in_flight(space: SidSpace, key: int) -> Pending:
    p = record(key)
    p.sent_at = monotonic()
    space.pending[key] = p
    return p


def test_sids_go_round_robin_and_skip_those_in_flight_quarantined_or_lingering() -> None:
    space, state = SidSpace(), dest()
    now = monotonic()
    assert [space.take(state, now) for _ in range(3)] == [0x10000, 0x10001, 0x10002]
    in_flight(space, 0x10003)
    space.quarantine[0x10004] = now + 10
    space.lingering[0x10005] = now + 10
    assert space.take(state, now) == 0x10006
    state.cursor = 0xFF
    assert space.take(state, now) == 0x100FF
    assert space.take(state, now) == 0x10000  # wraps after 255


def test_a_quarantine_or_linger_that_is_over_frees_its_sid() -> None:
    space, state = SidSpace(), dest()
    past = monotonic() - 1
    space.quarantine[0x10000] = past
    space.lingering[0x10001] = past
    in_flight(space, 0x10002)
    state.cursor = 0x02  # in flight: allocate() scans on and frees the ended ones
    assert space.take(state, monotonic()) == 0x10003
    state.cursor = 0x00
    assert space.allocate(state) == 0x10000
    assert space.allocate(state) == 0x10001
    assert space.quarantine == {} and space.lingering == {}


def test_no_sid_when_all_256_are_taken_and_how_long_until_one_is_free() -> None:
    space, state = SidSpace(), dest()
    now = monotonic()
    for sid in range(255):
        space.quarantine[0x10000 | sid] = now + 60
    space.lingering[0x100FF] = now + 0.005
    assert space.take(state, now) is None
    # (now + 0.005 - now is not 0.005 exactly for every value of the clock)
    assert 0.001 <= space.free_in(state, now) == pytest.approx(0.005)
    space.forget()  # a fresh connection: nothing late can reach it
    assert space.take(state, monotonic()) is not None


def test_routed_sids_stay_unique_across_destinations() -> None:
    space, first, second = SidSpace(), dest(PLC), dest(OTHER)
    space.routed = True
    now = monotonic()
    key = space.take(first, now)
    assert key == 0x10000
    in_flight(space, key)  # SID 0 to node 1
    assert space.take(second, now) == 0x20001  # SID 0 is in flight to node 1


def test_abandon_quarantines_and_drain_empties_the_table() -> None:
    space = SidSpace()
    p = in_flight(space, 0x10007)
    space.abandon(p, monotonic() + 15)
    assert p.done and p.abandoned and 0x10007 not in space.pending
    assert space.quarantine[0x10007] > monotonic() + 14
    q = in_flight(space, 0x10008)
    assert space.drain() == [q] and space.pending == {}


def given_up(space: SidSpace, key: int, sent: float, at: float, once: bool = True) -> None:
    """A request of 0101 under ``key``, sent at ``sent`` (``once``: not sent again), given
    up on at ``at`` (``space``'s clock must read ``at``): quarantined for 15 s."""
    p = record(key)
    p.sent_at = sent
    p.rtt = dest() if once else None
    space.pending[key] = p
    space.abandon(p, at + 15)


def reply(key: int, command: int = 0x0101) -> bytes:
    """A reply under ``key``'s SID to ``command``, end code 0000."""
    return bytes((0xC0, 0, 2, 0, 254, 0, 0, 1, 0, key & 0xFF, command >> 8, command & 0xFF, 0, 0))


def test_the_evidence_ends_a_quarantine_no_sooner_than_twice_the_slowest_round_trip() -> None:
    """A late reply before any evidence, with its request's command, shows the link's
    slowest round trip (0.65 s); the destination's answer to a younger request then ends
    the quarantines 0.5 s later, but none sooner than twice that after its request was
    sent (soak seed 50239: a delayed command reaches the PLC after a younger one). A late
    reply after the evidence (a reply under a wrong SID, say, in the term the evidence
    left), or with another command, teaches nothing: it made the term grow twice as long
    each time."""
    now = [10.1]
    space, stats = SidSpace(clock=lambda: now[0]), SessionStats({})
    given_up(space, 0x10001, 10.0, 10.1)
    now[0] = 10.65
    assert space.unmatched(stats, 0x10001, reply(0x10001)) == ("late", 0.0)
    assert space.slowest == pytest.approx(0.65)
    now[0] = 11.05
    given_up(space, 0x10002, 11.0, 11.05)
    given_up(space, 0x10003, 11.0, 11.05, once=False)  # sent again: from its give-up
    now[0] = 11.1
    space.answered_after(0x10004, 11.06, 11.1)  # a younger request answered
    assert space.quarantine[0x10002] == pytest.approx(11.0 + 1.3)
    assert space.quarantine[0x10003] == pytest.approx(11.05 + 1.3)
    assert space.given_up == {}
    now[0] = 12.2
    assert space.unmatched(stats, 0x10002, reply(0x10002)) == ("late", 0.0)
    assert space.quarantine[0x10002] == pytest.approx(12.2 + LATE_REPLY_GRACE)
    assert space.slowest == pytest.approx(0.65)  # after the evidence: taught nothing
    now[0] = 13.05
    given_up(space, 0x10006, 13.0, 13.05)
    given_up(space, 0x10007, 13.0, 13.05, once=False)
    now[0] = 14.0
    assert space.unmatched(stats, 0x10006, reply(0x10006, 0x0102)) == ("late", 0.0)
    assert space.unmatched(stats, 0x10007, reply(0x10007)) == ("late", 0.0)
    assert space.slowest == pytest.approx(0.65)  # another command; sent twice (Karn)
    given_up(space, 0x10008, 13.0, 14.0)
    now[0] = 14.2
    assert space.unmatched(stats, 0x10008, reply(0x10008)) == ("late", 0.0)
    assert space.slowest == pytest.approx(1.2)
    assert (stats.late_replies, stats.duplicates, stats.unsolicited) == (5, 0, 0)


def answered(space: SidSpace, key: int, at: float, reply: bytes = b"reply") -> None:
    """``key``'s request was answered with ``reply`` at ``at`` (negative: after a
    retransmission)."""
    space.recent[key] = at
    space.answers[key] = reply


def test_unmatched_replies_are_counted_and_a_duplicate_teaches_the_linger() -> None:
    space, stats = SidSpace(min_linger=0.01), SessionStats({})
    space.quarantine[0x10001] = monotonic() + 15
    assert space.unmatched(stats, 0x10001, b"late") == ("late", 0.0)
    assert space.quarantine[0x10001] <= monotonic() + LATE_REPLY_GRACE  # its reply has come
    answered(space, 0x10002, monotonic() - 0.1)  # 0.1 s ago: the network duplicated it
    kind, lateness = space.unmatched(stats, 0x10002, b"reply")
    assert kind == "duplicate" and 0.1 <= lateness < 1
    assert 0.2 <= space.linger <= MAX_LINGER
    answered(space, 0x10003, -(monotonic() - 0.2))  # answered after a retransmission
    assert space.unmatched(stats, 0x10003, b"reply") == ("duplicate", 0.0)
    assert space.linger_resent >= 0.4
    assert space.unmatched(stats, 0x10009, b"reply") == ("unsolicited", 0.0)
    assert (stats.late_replies, stats.duplicates, stats.unsolicited) == (1, 2, 1)


def test_a_reply_under_an_answered_sid_is_a_duplicate_only_if_a_copy_of_its_reply() -> None:
    """Anything else under an answered SID (a reply with a wrong SID) is unsolicited and
    teaches no linger: taken for a duplicate seconds late, it made every SID linger
    seconds (issue #22, the soak's "no free SID" long after the faults)."""
    now = [100.0]
    space, stats = SidSpace(clock=lambda: now[0]), SessionStats({})
    answered(space, 0x10001, 98.0, b"D100 holds 1")
    answered(space, 0x10002, -98.0, b"D100 holds 1")  # (after a retransmission)
    assert space.unmatched(stats, 0x10001, b"D200 holds 2") == ("unsolicited", 0.0)
    assert space.unmatched(stats, 0x10002, b"D200 holds 2") == ("unsolicited", 0.0)
    assert (space.linger, space.linger_resent, space.lingering) == (0.0, 0.0, {})
    assert space.unmatched(stats, 0x10001, b"D100 holds 1") == ("duplicate", 2.0)
    assert space.linger == 4.0  # twice its lateness
    assert (stats.duplicates, stats.unsolicited) == (1, 2)


def test_a_copy_of_a_reply_its_sid_carried_many_uses_earlier_is_a_duplicate() -> None:
    """Issue #22, defect 5 (soak seed 1400620): on a link that has shown duplicates, its
    linger calmed to the floor, an outage left 54 SIDs free, and SID 123 carried 14 reads
    in the 65 ms before a copy of its first reply came; the last 8 replies of each SID were
    kept, so the copy was unknown and answered a read of other words. The space's recent
    replies are kept whatever SID they came under: a copy of one within the hold window
    is a duplicate however often its SID came round since (and teaches the linger)."""
    now = [100.0]
    space, stats = SidSpace(clock=lambda: now[0]), SessionStats({})
    space.calm(now[0])  # (a link that has shown duplicates, calmed: the linger's floor)
    key = 0x0001007B  # (0.1.0, SID 123: a reply's SNA SA1 SA2 SID)
    head = bytes.fromhex("c0000200c8000001007b01010000")  # a 0101 reply under SID 123
    replies = [head + (0x06FA + i).to_bytes(2, "big") for i in range(14)]
    for i, reply in enumerate(replies):
        now[0] = 100.0 + 0.0045 * i
        space.remember(key, reply, now[0], b"read %d" % i)
    now[0] = 100.065
    kind, lateness = space.unmatched(stats, key, replies[0])
    assert kind == "duplicate" and lateness == pytest.approx(0.065)
    assert space.copied(replies[0], now[0]) == (100.0, b"read 0")
    assert space.linger == pytest.approx(0.13)
    now[0] = 100.0 + HOLD_WINDOW  # (the hold window has passed: the copy is unknown)
    assert space.copied(replies[0], now[0]) is None
    assert space.copied(head + b"\x00\x00", now[0]) is None  # (bytes never heard)
    assert (stats.duplicates, stats.unsolicited) == (1, 0)


def test_a_later_duplicate_extends_the_linger_of_the_sids_answered_before_it() -> None:
    """Issue #22, defect 5: the linger grows when a duplicate comes later than it, but the
    SIDs answered just before under the old linger were free again at once, and one
    reused took a later duplicate of its old reply for the new request's (another read's
    words). They now linger the new linger from when they were answered."""
    now = [100.0]
    space, stats = SidSpace(min_linger=0.0, clock=lambda: now[0]), SessionStats({})
    answered(space, 0x10001, 99.7)  # the duplicate's reply, answered 0.3 s ago
    answered(space, 0x10002, 99.9)  # answered 0.1 s ago, free under the old linger (0)
    answered(space, 0x10003, 99.0)  # answered 1 s ago: past any linger learnt here
    answered(space, 0x10004, 99.95)  # answered, and its SID carries a new request already
    space.pending[0x10004] = record(0x10004)
    kind, lateness = space.unmatched(stats, 0x10001, b"reply")
    assert kind == "duplicate" and lateness == pytest.approx(0.3)
    assert space.linger == pytest.approx(0.6)
    assert space.lingering == {
        0x10001: pytest.approx(100.3),
        0x10002: pytest.approx(100.5),
    }


def test_a_longer_round_trip_extends_the_quarantines_the_evidence_ended() -> None:
    """The evidence ended three quarantines (the link had shown 0.3 s): 0.5 s after it, or
    twice 0.3 s after the request's send. A late reply within 0.5 s of the evidence shows
    a round trip of 0.4 s (soak seed 53003: a delay episode began before the evidence):
    the quarantines last again until twice that after their requests' sends, but not the
    SID reused meanwhile, nor past the full term. A late reply later than 0.5 s after the
    evidence (in the term it left: a reply under a wrong SID, say) teaches nothing."""
    now = [0.3]
    space, stats = SidSpace(clock=lambda: now[0]), SessionStats({})
    space.slowest = 0.3
    now[0] = 2.05
    given_up(space, 0x10001, 2.0, 2.05)
    now[0] = 2.1
    given_up(space, 0x10002, 2.05, 2.1)
    given_up(space, 0x10003, 2.05, 2.1)
    space.quarantine[0x10003] = 2.8  # (a full term of 0.7 s)
    given_up(space, 0x10004, 2.0, 2.1)
    space.answered_after(0x10005, 2.1, 2.1)
    assert space.quarantine == pytest.approx(
        {k: 2.65 for k in (0x10002, 0x10003)} | {0x10001: 2.6, 0x10004: 2.6}
    )
    now[0] = 2.4
    assert space.is_free(0x10004, 2.7, frozenset())  # (checked at 2.7: reused)
    space.pending[0x10004] = record(0x10004)
    assert space.unmatched(stats, 0x10001, reply(0x10001)) == ("late", 0.0)
    assert space.slowest == pytest.approx(0.4)
    assert space.quarantine == pytest.approx(
        {0x10001: 2.4 + LATE_REPLY_GRACE, 0x10002: 2.05 + 0.8, 0x10003: 2.8}
    )
    now[0] = 2.65
    assert space.unmatched(stats, 0x10002, reply(0x10002)) == ("late", 0.0)
    assert space.slowest == pytest.approx(0.4)  # 0.55 s after the evidence: nothing
    assert 0x10004 not in space.ended and space.ended.keys() == {0x10003}
    assert (stats.late_replies, stats.duplicates, stats.unsolicited) == (2, 0, 0)


_KEYS = st.sampled_from([0x10000, 0x10001, 0x10002, 0x20000])
_OPERATIONS = st.lists(
    st.one_of(
        st.tuples(st.just("abandon"), _KEYS, st.booleans()),
        st.tuples(st.just("answered_after"), _KEYS, st.floats(0.0, 30.0)),
        st.tuples(st.just("hold"), _KEYS, st.booleans()),
        st.tuples(st.just("hold_first"), _KEYS),
        st.tuples(st.just("unhold"), _KEYS),
        st.tuples(
            st.just("forget"),
        ),
        st.tuples(st.just("tick"), st.floats(0.0, 5.0)),
    ),
    max_size=40,
)


@settings(max_examples=300, deadline=None)
@given(_OPERATIONS)
def test_unsure_is_whether_anything_is_held_or_given_up_after_every_operation(
    operations: list[tuple[object, ...]],
) -> None:
    """SidSpace.unsure, the receive path's one test for a copy held back or SIDs given up
    on, equals that slow condition after every operation that changes either."""
    now = [10.0]
    space = SidSpace(clock=lambda: now[0])
    for op, *args in operations:
        key = args[0] if args else 0
        assert isinstance(key, (int, float))
        if op == "abandon":
            p = in_flight(space, int(key))
            p.sent_at = now[0] - 0.1
            p.rtt = dest() if args[1] else None
            space.abandon(p, now[0] + 15)
        elif op == "answered_after":
            space.answered_after(int(key), now[0] - float(args[1]), now[0])  # type: ignore[arg-type]
        elif op == "hold":
            space.recent[int(key)] = now[0] - 0.5
            space.hold(int(key), now[0], f"{now[0]}".encode(), now[0] - 2.0 if args[1] else None)
        elif op == "hold_first":
            space.hold_first(int(key), f"{now[0]}".encode())  # (bytes held: one per instant)
        elif op == "unhold":
            space.unhold(int(key))
        elif op == "forget":
            space.forget()
        else:
            now[0] += float(key)
        assert space.unsure == bool(space.held or space.given_up), op


def test_only_sid_spaces_change_what_is_held_or_given_up() -> None:
    """:attr:`SidSpace.held` and :attr:`SidSpace.given_up` change only in ``sids.py``
    (where :attr:`SidSpace.unsure` is kept with them): anywhere else in the package
    they are only read."""
    import ast
    from pathlib import Path

    import aiofins.session

    def of_a_space(node: ast.AST) -> bool:  # (a batch's held is its count of slots)
        return (
            isinstance(node, ast.Attribute)
            and node.attr in ("held", "given_up")
            and not (isinstance(node.value, ast.Name) and node.value.id in ("self", "batch"))
        )

    changing = {"pop", "clear", "update", "setdefault", "popitem", "__setitem__", "__delitem__"}
    found = []
    for path in sorted(Path(aiofins.session.__file__).parent.glob("*.py")):
        if path.name == "sids.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.Assign, ast.AugAssign, ast.AnnAssign, ast.Delete)):
                targets = (
                    node.targets if isinstance(node, (ast.Assign, ast.Delete)) else [node.target]
                )
                for t in targets:
                    if of_a_space(t.value if isinstance(t, ast.Subscript) else t):
                        found.append(f"{path.name}:{node.lineno}")
            elif (
                isinstance(node, ast.Call)
                and isinstance(node.func, ast.Attribute)
                and node.func.attr in changing
                and of_a_space(node.func.value)
            ):
                found.append(f"{path.name}:{node.lineno}")
    assert found == []
