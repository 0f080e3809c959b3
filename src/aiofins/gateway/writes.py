"""Writes back from MQTT: ``{topic}/set/{tag}``, for the tags a group marks writable only.

The contract (docs/gateway.md, "Writing back"):

* **Retained** set messages are never written: refused (``"retained"``), logged, answered
  once (the same retained message again after a reconnect is not answered again).
* **Size first:** a payload over ``max_payload`` bytes (64 kB) is refused unread; parsing
  cannot recurse without bound (a payload nesting deeper than ``{"value": ...}`` is refused
  before ``json.loads``).
* **Values:** ``NaN``, ``Infinity`` and numbers outside the tag type's range are refused,
  the message giving the range (:func:`~aiofins.gateway.payload.check_value`).
* **Age:** a request is written only before its deadline: ``write_max_age`` (5 s) from the
  gateway's receipt, on the event loop's clock, or sooner if its MQTT 5 message expiry says
  so; after it, it is refused ``"expired"`` and never written.
* **Queue:** each PLC has one queue of at most ``write_queue`` requests (100), written in
  order one at a time; a request finding it full is refused ``"busy"`` at once, not delayed.
* **Replies:** exactly one per request, on ``{topic}/set/{tag}/reply``, echoing the request's
  ``id`` whenever the payload carried one::

    {"tag": "setpoint", "id": "42", "ok": true, "end_code": "0000", "error": null,
     "waited": 0.0012}

  ``waited`` is the seconds from the gateway's receipt of the request to its write being
  sent (``null`` when nothing was sent: at most ``write_max_age`` otherwise).
  ``end_code`` is the PLC's answer (``"2108"``: cannot write in this mode, ...), ``null``
  when nothing reached the PLC. Replies to tags that are not writable (or do not exist) go
  through a pool of :data:`REPLY_POOL` outboxes reused in turn, so invented tag names cannot
  grow memory.

A failed write is tried again only ``write_retries`` times (0 by default).
"""

from __future__ import annotations

import json
import logging
from collections import OrderedDict, deque
from collections.abc import Awaitable, Callable, Coroutine
from dataclasses import dataclass
from enum import Enum
from typing import TYPE_CHECKING, Any

from ..protocol.errors import EndCodeError, FinsError
from ..protocol.values import Value
from .mqtt import Outbox

if TYPE_CHECKING:
    from ..pool import Pool
    from ..tags import Tag
    from .config import GroupConfig

log = logging.getLogger("aiofins.gateway")

#: Outboxes for replies to set requests on tags that are not writable, at most.
REPLY_POOL = 64
#: Replies waiting per pooled outbox, at most.
POOL_BUFFER = 100
#: Replies waiting per writable tag's reply topic, at most (a reply is a few hundred bytes).
REPLY_BUFFER = 10_000
#: Retained set messages remembered as answered, at most (then forgotten, oldest first).
RETAINED_MEMORY = 1024
#: Outcomes of set requests (the ``outcome`` label of ``aiofins_gateway_writes``).
OUTCOMES = ("written", "failed", "refused", "invalid", "expired", "busy", "retained")


def reply_topic(set_topic: str) -> str:
    return f"{set_topic}/reply"


def new_reply(tag: str, request_id: str | None, error: str | None = None) -> dict[str, Any]:
    """A reply; ``waited`` is the seconds from the gateway's receipt of the request to its
    write being sent (None: nothing was sent)."""
    return {
        "tag": tag,
        "id": request_id,
        "ok": False,
        "end_code": None,
        "error": error,
        "waited": None,
    }


def encode_reply(reply: dict[str, Any]) -> bytes:
    return json.dumps(reply, separators=(",", ":")).encode()


@dataclass(eq=False)
class SetRequest:
    """One set request accepted into a PLC's queue."""

    plc: str
    url: str
    group: GroupConfig
    tag: Tag
    value: Value
    request_id: str | None
    #: Loop time it was received, and the loop time after which it is not written.
    received: float
    deadline: float
    reply_box: Outbox


class WriterState(Enum):
    """A PLC's write queue (transitions in :meth:`Writer._enter`)."""

    #: No request waiting, no task.
    IDLE = "idle"
    #: A task writes the waiting requests in order until none is left.
    WRITING = "writing"


class Writer:
    """One PLC's set requests: at most ``limit`` waiting, written in order by one task."""

    def __init__(
        self,
        plc: str,
        limit: int,
        start: Callable[[Callable[[], Coroutine[Any, Any, None]]], None],
        write: Callable[[SetRequest], Awaitable[None]],
    ) -> None:
        self.plc = plc
        self.limit = limit
        self.state = WriterState.IDLE
        self.queue: deque[SetRequest] = deque()
        self._start = start
        self._write = write

    def _enter(self, state: WriterState) -> None:
        """The one place the writer changes state."""
        self.state = state
        if state is WriterState.WRITING:
            self._start(self._run)

    def offer(self, request: SetRequest) -> bool:
        """Queue ``request``; False (nothing queued) if the queue is full."""
        if len(self.queue) >= self.limit:
            return False
        self.queue.append(request)
        if self.state is WriterState.IDLE:
            self._enter(WriterState.WRITING)
        return True

    async def _run(self) -> None:
        try:
            while self.queue:
                await self._write(self.queue.popleft())
        finally:
            self._enter(WriterState.IDLE)


class ReplyPool:
    """At most :data:`REPLY_POOL` outboxes for replies on topics of no writable tag: a topic
    seen again reuses its outbox; a new one takes over the least recently used idle one."""

    def __init__(self, size: int = REPLY_POOL, buffer: int = POOL_BUFFER) -> None:
        self.size = size
        self.buffer = buffer
        self._boxes: OrderedDict[str, Outbox] = OrderedDict()
        #: Replies not sent because every pooled outbox was busy (broker away).
        self.dropped = 0

    def __len__(self) -> int:
        return len(self._boxes)

    def outbox(self, topic: str) -> Outbox | None:
        box = self._boxes.get(topic)
        if box is not None:
            self._boxes.move_to_end(topic)
            return box
        if len(self._boxes) < self.size:
            box = self._boxes[topic] = Outbox(topic, 1, False, self.buffer)
            return box
        for old, candidate in self._boxes.items():
            if not candidate.messages and not candidate.queued and candidate.sending is None:
                del self._boxes[old]
                candidate.topic = topic
                self._boxes[topic] = candidate
                return candidate
        self.dropped += 1
        return None

    @property
    def queued_messages(self) -> int:
        return sum(len(box.messages) for box in self._boxes.values())


async def write_value(pool: Pool, request: SetRequest, waited: float) -> tuple[str, dict[str, Any]]:
    """Write one accepted request to its PLC, ``waited`` seconds after its receipt;
    (outcome, reply). Outcomes: ``written``, ``failed``. Never raises for what a peer
    sends."""
    tag, group = request.tag, request.group
    reply = new_reply(tag.name, request.request_id)
    reply["waited"] = round(waited, 6)
    what = f"{request.plc}/{group.name}/{tag.name}"
    value = request.value
    try:
        async with pool.client(request.url, timeout=group.timeout) as client:
            if tag.vtype.kind == "bit":
                await client.write(
                    tag.address,
                    [int(bool(value))],
                    timeout=group.timeout,
                    retries=group.write_retries,
                )
            else:
                await client.write_value(
                    tag.address,
                    value,
                    tag.vtype,
                    timeout=group.timeout,
                    retries=group.write_retries,
                )
    except EndCodeError as exc:
        reply["end_code"] = f"{exc.end_code.code:04X}"
        reply["error"] = str(exc)
        log.warning("set %s = %r failed: %s", what, value, exc)
        return "failed", reply
    except FinsError as exc:
        reply["error"] = f"{type(exc).__name__}: {exc}"
        log.warning("set %s = %r failed: %s", what, value, reply["error"])
        return "failed", reply
    reply["ok"] = True
    reply["end_code"] = "0000"
    log.info("set %s = %r (%s)", what, value, tag.text)
    return "written", reply
