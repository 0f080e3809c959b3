"""The Poller's scan of a plan of one frame, as a step kept between scans (a module of its
own so that a compiled build compiles it: docs/packaging.md). Used by :mod:`aiofins.poller`
only; it reaches the poller, its group, the lease and the client by attribute."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Any

from .protocol.endcodes import EndCode
from .protocol.frames import END_CODE, MIN_REPLY_SIZE
from .protocol.values import Value
from .session.callback import CallbackPending, PreparedRequest

logger = logging.getLogger("aiofins.poller")

#: A plan of one frame as a scan sends it: its command ``(mrc, src, params)`` and the
#: decoder of its reply frame (``None``: the reply is decoded tag by tag).
OneFrame = tuple[tuple[int, int, bytes], Callable[[bytes], "tuple[Value, ...] | None"] | None]

_NORMAL = EndCode(0)
#: (read only) A good scan's tags that are no value of their type: none.
NO_BAD: dict[str, str] = {}


class FrameScan:
    """A group's scan of a plan of one frame on the callback path (asyncio), kept between
    scans: the group's lease and the client it lends, the plan's command prepared on that
    client's session (:class:`~aiofins.session.callback.PreparedRequest`) and the decoder
    of its reply frame. Each due scan :meth:`start` borrows the client (the pool's fast
    path: the pool sees each scan as a use, idle closing and health checks as before),
    sends from the timer's step, and :meth:`done` ends it in the session's receive
    callback: decode, snapshot, buffer."""

    __slots__ = (
        "client",
        "decode",
        "group",
        "idle",
        "lease",
        "limits",
        "names",
        "poller",
        "prepared",
        "request",
        "scanning",
        "stamp",
        "started",
    )

    def __init__(
        self,
        poller: Any,
        group: Any,
        lease: Any,
        client: Any,
        limits: object,
        one: OneFrame,
        scanning: object,
        idle: object,
    ) -> None:
        #: The Poller, its ScanGroup, the group's pool lease and the client it lends
        #: (typed ``Any``: interpreted classes, reached from here by attribute).
        self.poller = poller
        self.group = group
        self.lease = lease
        self.client = client
        #: The client's limits the plan was checked against.
        self.limits = limits
        command, self.decode = one
        plan = group.plan
        assert plan is not None
        self.names = plan.tag_names
        self.prepared = PreparedRequest(
            client.session, command, self.done, dest=client.dest, timeout=group.timeout
        )
        #: The scan in flight (``None``: none), when it started (loop clock, wall clock).
        self.request: CallbackPending | None = None
        self.started = self.stamp = 0.0
        #: The group's states SCANNING and IDLE (:class:`~aiofins.poller.ScanState`).
        self.scanning = scanning
        self.idle = idle

    def start(self) -> bool:
        """Send the group's due scan now; False (nothing started, the group's task scans
        instead) as :meth:`Poller._scan_soon` says, and the step dropped when the group's
        lease or the client lent is no longer the one it was made for."""
        group = self.group
        lease = self.lease
        if group._lease is not lease:  # (a scan_once beside it holds the lease)
            group._step = None
            return False
        client = lease.borrow_ready()
        if client is not self.client or client.limits is not self.limits:
            lease.release()
            group._step = None
            return False
        self.started = self.poller._now()
        try:
            request = self.prepared.send()
        except Exception:  # a bug, not the PLC: the group's task scans (and says what)
            logger.exception("scan group %s: the scan could not start", group.name)
            request = None
        if request is None:
            lease.release()
            return False
        self.request = request
        self.stamp = time.time()
        group._lease = None  # in use (a scan_once beside this scan takes another)
        group._enter(self.scanning)
        group.scans += 1
        return True

    def done(self, frame: bytes | None, error: BaseException | None) -> None:
        """The scan's reply frame (a normal completion) or its failure, from the session:
        decoded in one call where the plan allows (:meth:`ReadPlan.frame_decoder`), else
        tag by tag (:meth:`Poller._scanned_frame`); its snapshot to the buffer."""
        if self.request is None:  # (given up by the poller's exit)
            return
        self.request = None
        group = self.group
        lease = self.lease
        lease.release()
        if group._lease is None:
            group._lease = lease
        poller = self.poller
        try:
            decode = self.decode
            values = None if frame is None or decode is None else decode(frame)
            if values is None:
                poller._scanned_frame(group, self.client, self.started, self.stamp, frame, error)
                return
            assert frame is not None
            if frame[END_CODE] or frame[END_CODE + 1]:  # (CPU error flags)
                self.client.last_end_code = EndCode(
                    int.from_bytes(frame[END_CODE:MIN_REPLY_SIZE], "big")
                )
            else:
                self.client.last_end_code = _NORMAL
            if group._missed_unlogged or group._failing is not None:  # (to log: the rest)
                snapshot = poller._scanned(
                    group, self.started, self.stamp, values, None, NO_BAD, None
                )
            else:  # the usual scan: _scanned's steps for a good scan with nothing to log
                group.last_duration = poller._now() - self.started
                snapshot = poller._good(group, self.stamp, values, self.names)
            poller._handover(group, snapshot)
        except Exception:  # a bug, not the PLC: logged, and the group scans on
            logger.exception("scan group %s: the scan could not end", group.name)
            group.errors += 1
            if group.state is self.scanning:
                group._enter(self.idle)

    def give_up(self) -> None:
        """The poller exits: the scan in flight, if any, given up (its SID quarantined),
        the lease given back."""
        request = self.request
        if request is not None:
            self.request = None
            request.cancel()
            self.lease.release()
            if self.group._lease is None:
                self.group._lease = self.lease
