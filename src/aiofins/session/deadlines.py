"""The deadlines of the requests in flight, earliest first, cheap to add and to drop.

Most requests of a session share one timeout, so their deadlines come in order: those go to a
FIFO (``append``/``popleft``, O(1), no tuple per request). A deadline earlier than the FIFO's
last one goes to a heap instead. Answered requests stay in place (marked ``done``) until they
reach the front; when a slow request at the front keeps many answered ones behind it, the
session compacts both (O(n), rarely).
"""

from __future__ import annotations

import heapq
import math
from collections import deque

from .slots import Pending


class Deadlines:
    """Requests in flight ordered by ``Pending.deadline``: a FIFO plus a heap for stragglers."""

    __slots__ = ("fifo", "heap", "seq")

    def __init__(self) -> None:
        #: Requests whose deadlines are in order (the session appends here inline).
        self.fifo: deque[Pending] = deque()
        #: ``(deadline, seq, request)`` for requests added out of order.
        self.heap: list[tuple[float, int, Pending]] = []
        self.seq = 0

    def __len__(self) -> int:
        return len(self.fifo) + len(self.heap)

    def add(self, p: Pending) -> None:
        fifo = self.fifo
        if not fifo or p.deadline >= fifo[-1].deadline:
            fifo.append(p)
        else:
            self.seq += 1
            heapq.heappush(self.heap, (p.deadline, self.seq, p))

    def earliest(self) -> float:
        """The earliest deadline (``inf`` if none); answered requests may still count."""
        fifo, heap = self.fifo, self.heap
        at = fifo[0].deadline if fifo else math.inf
        if heap and heap[0][0] < at:
            at = heap[0][0]
        return at

    def live_earliest(self) -> float:
        """The earliest deadline of a request not yet answered (``inf`` if none); answered
        requests at the fronts are dropped on the way."""
        fifo, heap = self.fifo, self.heap
        while fifo and fifo[0].done:
            fifo.popleft()
        while heap and heap[0][2].done:
            heapq.heappop(heap)
        at = fifo[0].deadline if fifo else math.inf
        if heap and heap[0][0] < at:
            at = heap[0][0]
        return at

    def prune(self, live: int) -> None:
        """Drop answered requests from the fronts; compact if they pile up (``live`` in flight)."""
        fifo, heap = self.fifo, self.heap
        while fifo and fifo[0].done:
            fifo.popleft()
        while heap and heap[0][2].done:
            heapq.heappop(heap)
        if len(fifo) + len(heap) > 64 + 4 * live:
            kept = [p for p in fifo if not p.done]
            fifo.clear()
            fifo.extend(kept)
            heap[:] = [entry for entry in heap if not entry[2].done]
            heapq.heapify(heap)

    def due(self, now: float) -> list[Pending]:
        """Remove and return the unanswered requests whose deadline is ``now`` or earlier."""
        out: list[Pending] = []
        fifo, heap = self.fifo, self.heap
        while fifo:
            p = fifo[0]
            if not p.done:
                if p.deadline > now:
                    break
                out.append(p)
            fifo.popleft()
        while heap:
            deadline, _, p = heap[0]
            if not p.done:
                if deadline > now:
                    break
                out.append(p)
            heapq.heappop(heap)
        return out

    def clear(self) -> None:
        self.fifo.clear()
        self.heap.clear()
