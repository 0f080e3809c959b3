"""Which FINS source nodes (SA1) are in use towards each UDP peer of this process.

An Ethernet unit replies to the last UDP port it saw for a source node, so every socket
talking to one peer needs a node of its own: two sockets sharing SA1 steal each other's
replies. A :class:`~aiofins.pool.Pool` gives each of its sessions to one peer its own node,
and a session gives each extra SID space (another socket, see docs/session.md) its own
node; both take them from :data:`SOURCE_NODES`, so neither collides with the other.

A node given back stays out of use for a while (``cool_until``): a late reply to its last
socket's requests would otherwise go to the next socket using it, which would then no longer
be a fresh SID space.
"""

from __future__ import annotations

import threading
from collections import Counter
from collections.abc import Callable, Iterable
from time import monotonic

from ..protocol.errors import CommandError
from ..protocol.header import FinsAddress


class SourceNodes:
    """Source nodes held per peer (``udp://address:port``), counted: a node held twice (two
    sessions told to use it) is free again only once both gave it back. Safe to share
    between threads (each ``aiofins.sync`` client runs its own event loop)."""

    def __init__(self, clock: Callable[[], float] = monotonic) -> None:
        self._held: dict[str, Counter[int]] = {}
        #: peer -> node -> until when a node given back stays out of use, on which clock
        #: (the releasing session's: sessions of one process may run on different clocks).
        self._cooling: dict[str, dict[int, tuple[float, Callable[[], float]]]] = {}
        self._clock = clock
        self._lock = threading.Lock()

    def in_use(self, peer: str) -> frozenset[int]:
        """The nodes held towards ``peer``, or given back and still cooling."""
        with self._lock:
            return self._in_use(peer)

    def _in_use(self, peer: str) -> frozenset[int]:
        held = self._held.get(peer)
        cooling = self._cooling.get(peer)
        if cooling:
            for node in [n for n, (until, clock) in cooling.items() if _over(until, clock)]:
                del cooling[node]
        return frozenset(held or ()) | frozenset(cooling or ())

    def hold(self, peer: str, node: int) -> None:
        """Count ``node`` as used towards ``peer`` (chosen elsewhere, e.g. the session's own)."""
        with self._lock:
            self._hold(peer, node)

    def _hold(self, peer: str, node: int) -> None:
        self._held.setdefault(peer, Counter())[node] += 1
        cooling = self._cooling.get(peer)
        if cooling:
            cooling.pop(node, None)

    def claim(self, peer: str, avoid: Iterable[int] = ()) -> int | None:
        """A node nobody uses towards ``peer`` (254 down, none of ``avoid``), now held;
        ``None`` if all 254 are taken."""
        with self._lock:
            node = _free(self._in_use(peer).union(avoid))
            if node is not None:
                self._hold(peer, node)
            return node

    def source_for(
        self,
        peer: str,
        source: FinsAddress,
        *,
        named: bool,
        avoid: Iterable[int] = (),
        where: str,
    ) -> FinsAddress:
        """The source address of a new session's socket to ``peer``, its node now held
        (:meth:`release` gives it back).

        ``source`` is the session's default: kept if no socket of the process uses its node
        towards ``peer`` and it is none of ``avoid`` (e.g. nodes of PLCs addressed there),
        else a free node, 254 down. A source the user ``named`` is kept, or refused with
        :class:`CommandError` if its node is in use towards ``peer`` (the PLC would send
        each socket's replies to the other); ``where`` begins the message (the endpoint).
        """
        with self._lock:
            used = self._in_use(peer)
            node = source.node
            if named and node in used:
                raise CommandError(
                    f"{where}: source node {node} is used by another session to {peer} "
                    "in this pool or process; the PLC would send each one's replies to "
                    "the other. Name another src, or leave it out"
                )
            taken = used.union(avoid)
            if not named and node in taken:
                free = _free(taken)
                if free is None:
                    raise CommandError(f"{peer}: no free FINS source node for another session")
                node = free
            self._hold(peer, node)
            return FinsAddress(source.network, node, source.unit)

    def release(
        self,
        peer: str,
        node: int,
        cool_until: float = 0.0,
        clock: Callable[[], float] | None = None,
    ) -> None:
        """Give ``node`` back; it is free again once every holder gave it back and
        ``clock`` (the releasing session's; default: this table's own, monotonic) has
        passed ``cool_until``."""
        with self._lock:
            self._release(peer, node, cool_until, clock or self._clock)

    def _release(self, peer: str, node: int, cool_until: float, clock: Callable[[], float]) -> None:
        held = self._held.get(peer)
        if held is None or not held[node]:
            return
        held[node] -= 1
        if held[node]:
            return
        del held[node]
        if not held:
            del self._held[peer]
        if cool_until > clock():
            self._cooling.setdefault(peer, {})[node] = (cool_until, clock)


def _over(until: float, clock: Callable[[], float]) -> bool:
    """Whether ``clock`` has passed ``until``; a clock that cannot be read any more (trio's
    outside its run: the session that released the node is long gone) has."""
    try:
        return until <= clock()
    except RuntimeError:
        return True


def _free(taken: frozenset[int]) -> int | None:
    """The highest node (254 down) not in ``taken``; ``None`` if all are."""
    return next((n for n in range(254, 0, -1) if n not in taken), None)


#: The source nodes of every session and pool of this process.
SOURCE_NODES = SourceNodes()
