"""The gateway's link to the MQTT broker: outboxes, publishers, reconnects.

Scans never wait for the broker: :meth:`MqttLink.put` appends a message to its topic's
:class:`Outbox` (bounded: when full, the oldest message is dropped and counted) and returns.
While the link is :attr:`LinkState.CONNECTED`, outboxes are sent in turn, one message each, so
every topic keeps its order and no topic starves the others:

* QoS 0 messages are handed to the connection (:class:`~.mqttclient.MqttConnection`, a
  paho-mqtt client on the event loop) as they come, with no task switch or future per
  message: a message put into an empty outbox is written to the socket at once, a backlog
  (after a reconnect) goes through one pump task. A message handed over but not yet written
  when the link breaks goes back to the front of its outbox.
* QoS 1 and 2 messages go through a few publisher tasks that await the broker's
  acknowledgement; a message leaves its outbox only once acknowledged.

So a publish cut off by a lost link is sent again after the reconnect (at least once). A lost
or refused connection is tried again after a jittered, doubling backoff. Received messages
wait in one :class:`~.mqttclient.Inbox` (bounded; drops counted and logged) for one task that
hands them to ``on_message``, whatever connection they came on.

The gateway's own status topic carries ``online`` (published on every connect, retained) and
``offline`` (the MQTT will, published by the broker if the gateway vanishes, and by the
gateway itself when it stops).
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import random
import secrets
import socket
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from enum import Enum
from typing import TYPE_CHECKING

import anyio
import anyio.lowlevel
from anyio.streams.memory import MemoryObjectReceiveStream, MemoryObjectSendStream

from .config import MqttConfig
from .mqttclient import ConnectionLost, ConnectSettings, Inbox, MqttConnection
from .payload import status_message

if TYPE_CHECKING:
    import paho.mqtt.client as paho_mqtt

log = logging.getLogger("aiofins.gateway")

#: QoS 0 messages handed to the MQTT client and not yet known to be written to its socket,
#: at most (a slow broker makes the rest wait in their outboxes, bounded and counted).
MAX_HANDED = 1024
#: QoS 0 messages the pump hands over before it lets the event loop write them.
PUMP_BATCH = 256
#: Received messages handed to ``on_message`` before the receiver lets other tasks run.
RECEIVE_BATCH = 64
#: Takeovers of the client id within :data:`TAKEOVER_WINDOW` seconds that stop the gateway
#: (another gateway runs with the same shard: flapping helps no one).
TAKEOVER_LIMIT = 3
TAKEOVER_WINDOW = 60.0

#: ``on_message(topic, payload, retain, expiry, received)``: ``expiry`` is the MQTT 5 message
#: expiry interval left (seconds), or None; ``received`` when it was read (the loop's clock).
OnMessage = Callable[[str, bytes, bool, "float | None", float], None]


class DuplicateClient(Exception):
    """Another client keeps taking this gateway's MQTT client id (a second gateway running
    as the same shard); the message names the id and the shard."""


class LinkState(Enum):
    """The broker connection's lifecycle (transitions in :meth:`MqttLink._enter`)."""

    #: Making a connection (the first, or the next after a backoff).
    CONNECTING = "connecting"
    #: Connected: outboxes are published, set topics subscribed.
    CONNECTED = "connected"
    #: The connection failed or was lost: waiting for the backoff to pass.
    BACKING_OFF = "backing_off"
    #: Stopped by the gateway: no more attempts.
    CLOSED = "closed"


_TRANSITIONS: dict[LinkState, frozenset[LinkState]] = {
    LinkState.CONNECTING: frozenset({LinkState.CONNECTED, LinkState.BACKING_OFF, LinkState.CLOSED}),
    LinkState.CONNECTED: frozenset({LinkState.BACKING_OFF, LinkState.CLOSED}),
    LinkState.BACKING_OFF: frozenset({LinkState.CONNECTING, LinkState.CLOSED}),
    LinkState.CLOSED: frozenset(),
}


@dataclass(eq=False)
class Outbox:
    """Messages for one topic waiting for the broker, at most ``limit`` (oldest dropped)."""

    topic: str
    qos: int
    retain: bool
    limit: int
    #: (payload, Unix time the message's data was read).
    messages: deque[tuple[bytes, float]] = field(default_factory=deque)
    #: Messages the broker took (QoS 0: handed to the connection; one not written when it
    #: breaks goes back into ``messages`` and is not counted).
    published: int = 0
    #: Messages dropped from a full outbox (the oldest first).
    dropped: int = 0
    #: Whether the outbox waits in the pump's (QoS 0) or the publishers' (QoS 1/2) queue.
    queued: bool = False
    #: The QoS 1/2 message being published (the head), which a full outbox does not drop.
    sending: tuple[bytes, float] | None = None


class MqttLink:
    """One broker connection for a gateway; :meth:`run` it in a task, :meth:`close` to stop."""

    def __init__(
        self,
        config: MqttConfig,
        *,
        client_id: str,
        status_topic: str,
        subscriptions: Sequence[str] = (),
        on_message: OnMessage | None = None,
        on_connected: Callable[[], None] | None = None,
        on_published: Callable[[float], None] | None = None,
        max_packet: int | None = None,
        owner: str = "",
    ) -> None:
        self.config = config
        #: The largest MQTT packet the broker may send us (MQTT 5; None: no limit).
        self.max_packet = max_packet
        #: Who runs this link, for messages ("gateway plant-1 (shard 1/3)").
        self.owner = owner or f"client {client_id}"
        self.client_id = client_id
        self.status_topic = status_topic
        self.subscriptions = list(subscriptions)
        self.on_message = on_message
        self.on_connected = on_connected
        self.on_published = on_published
        self.state = LinkState.CONNECTING
        self.outboxes: dict[str, Outbox] = {}
        self.connects = 0
        self.connect_failures = 0
        self.disconnects = 0
        #: This process's instance on the status topic: host, pid and a random part.
        self.instance = f"{socket.gethostname()}:{os.getpid()}:{secrets.token_hex(4)}"
        #: Times another instance of us (same status topic) went online while we were.
        self.takeovers = 0
        self._takeover_times: deque[float] = deque(maxlen=TAKEOVER_LIMIT)
        #: Why the link gave up for good (a duplicate client id), or None.
        self.fatal: DuplicateClient | None = None
        #: Set when the link is :attr:`LinkState.CONNECTED` (cleared when it is not).
        self.connected = anyio.Event()
        self._closing = anyio.Event()
        #: Set once :meth:`run` has ended (after :meth:`close`).
        self.done = anyio.Event()
        #: Received messages waiting for ``on_message`` (bounded; drops counted, logged).
        self.inbox = Inbox()
        #: QoS 1/2 outboxes with messages, for the publisher tasks.
        send, receive = anyio.create_memory_object_stream[Outbox](float("inf"))
        self._ready: MemoryObjectSendStream[Outbox] = send
        self._ready_out: MemoryObjectReceiveStream[Outbox] = receive
        #: QoS 0 outboxes with messages, for the pump.
        self._ready0: deque[Outbox] = deque()
        self._pump_idle: anyio.Event | None = None
        #: The connection while connected (QoS 0 goes straight to it), or None.
        self._conn: MqttConnection | None = None
        #: QoS 0 messages handed to the connection, oldest first, until known written.
        self._handed: deque[tuple[Outbox, tuple[bytes, float], paho_mqtt.MQTTMessageInfo]] = deque()
        self._lost: Callable[[str], None] | None = None

    # -- state ------------------------------------------------------------------------

    def _enter(self, state: LinkState, why: str = "") -> None:
        """The one place the link changes state."""
        if state is self.state:
            return
        if state not in _TRANSITIONS[self.state]:
            raise RuntimeError(f"MQTT link cannot go from {self.state.name} to {state.name}")
        log.info("MQTT link %s -> %s%s", self.state.name, state.name, f": {why}" if why else "")
        self.state = state
        if state is LinkState.CONNECTED:
            self.connected.set()
        elif self.connected.is_set():
            self.connected = anyio.Event()

    # -- outboxes ---------------------------------------------------------------------

    def outbox(self, topic: str, *, qos: int = 0, retain: bool = False, limit: int = 100) -> Outbox:
        box = self.outboxes.get(topic)
        if box is None:
            box = self.outboxes[topic] = Outbox(topic, qos, retain, limit)
        return box

    def put(self, box: Outbox, payload: bytes, stamp: float | None = None) -> None:
        """Queue a message (never waits; a full outbox drops its oldest, counted)."""
        entry = (payload, time.time() if stamp is None else stamp)
        messages = box.messages
        if box.qos == 0:
            conn = self._conn
            if conn is not None and not messages and self._hand(conn, box, entry):
                return
        if len(messages) >= box.limit:
            if box.sending is None or messages[0] is not box.sending:
                messages.popleft()
                box.dropped += 1
            elif len(messages) > 1:  # the head may reach the broker: drop the next oldest
                del messages[1]
                box.dropped += 1
        messages.append(entry)
        if not box.queued:
            self._queue(box)

    def _queue(self, box: Outbox) -> None:
        box.queued = True
        if box.qos:
            self._ready.send_nowait(box)
        else:
            self._ready0.append(box)
            if self._pump_idle is not None:
                self._pump_idle.set()

    def _hand(self, conn: MqttConnection, box: Outbox, entry: tuple[bytes, float]) -> bool:
        """Hand a QoS 0 message to the connection (written at once unless the socket is
        full); False if too many are unwritten or the link is lost (the message stays with
        the caller)."""
        handed = self._handed
        while handed and handed[0][2].is_published():
            handed.popleft()
        if len(handed) >= MAX_HANDED:
            return False
        info = conn.publish_now(box.topic, entry[0], box.retain)
        if info.rc:  # not MQTT_ERR_SUCCESS: no connection
            self._conn = None
            if self._lost is not None:
                self._lost(f"publish failed: error {info.rc}")
            return False
        handed.append((box, entry, info))
        box.published += 1
        if self.on_published is not None:
            self.on_published(entry[1])
        return True

    def _take_back(self) -> None:
        """After the link broke: QoS 0 messages handed to the connection but never written go
        back to the front of their outboxes (or, where the outbox is full by now, count as
        dropped)."""
        self._conn = None
        handed = self._handed
        while handed:
            box, entry, info = handed.pop()  # newest first: each goes in front of the next
            if info.is_published():
                continue
            box.published -= 1
            if len(box.messages) >= box.limit:
                box.dropped += 1  # the oldest of a full outbox
            else:
                box.messages.appendleft(entry)
            if not box.queued:
                self._queue(box)

    @property
    def dropped(self) -> int:
        return sum(box.dropped for box in self.outboxes.values())

    @property
    def queued_messages(self) -> int:
        return sum(len(box.messages) for box in self.outboxes.values())

    # -- running ----------------------------------------------------------------------

    async def run(self) -> None:
        """Connect, publish, reconnect after a backoff, until :meth:`close`."""
        try:
            async with anyio.create_task_group() as tg:
                tg.start_soon(self._receive)
                await self._run()
                tg.cancel_scope.cancel()
        finally:
            self.done.set()

    async def _run(self) -> None:
        backoff = self.config.backoff_min
        while not self._closing.is_set():
            self._enter(LinkState.CONNECTING)
            conn = MqttConnection(self._settings(), self.inbox)
            try:
                try:
                    await conn.connect()
                except ConnectionLost as exc:
                    self.connect_failures += 1
                    why = f"cannot connect to {self.config.host}:{self.config.port}: {exc}"
                else:
                    self.connects += 1
                    backoff = self.config.backoff_min
                    try:
                        why = await self._serve(conn)
                    finally:
                        with anyio.CancelScope(shield=True):
                            await conn.disconnect()
                    self.disconnects += 1
            finally:
                self._take_back()  # (the connection is closed: what it wrote is known)
            if self._closing.is_set():
                break
            delay = random.uniform(backoff / 2, backoff)  # jitter: shards do not reconnect in step
            backoff = min(self.config.backoff_max, backoff * 2)
            self._enter(LinkState.BACKING_OFF, f"{why}; next attempt in {delay:.2f} s")
            with anyio.move_on_after(delay):
                await self._closing.wait()
        self._enter(LinkState.CLOSED)

    def _status_seen(self, payload: bytes) -> None:
        """A message on our own status topic from another instance: its "online" live, or
        its retained will found on (re)connecting, means a second gateway with our name and
        shard took the connection from us (or we from it). One such event is a restart (the
        old process's will); :data:`TAKEOVER_LIMIT` of them in :data:`TAKEOVER_WINDOW` are
        two processes taking turns."""
        try:
            status = json.loads(payload)
        except ValueError:
            return
        other = status.get("instance") if isinstance(status, dict) else None
        if other is None or other == self.instance:
            return
        if status.get("state") == "offline" and status.get("stopped") is True:
            return  # a predecessor that stopped cleanly (a restart), not a takeover
        self._taken_over(str(other))

    def _taken_over(self, other: str) -> None:
        """Another instance of us took the connection: an error each time, and after
        :data:`TAKEOVER_LIMIT` within :data:`TAKEOVER_WINDOW` the link of the instance whose
        name sorts first stops for good (:attr:`fatal`); the other goes on."""
        self.takeovers += 1
        now = anyio.current_time()
        self._takeover_times.append(now)
        log.error(
            "MQTT client id %r was taken over by another client, instance %s (%d times so "
            "far): is another %s running?",
            self.client_id,
            _cut(other),
            self.takeovers,
            self.owner,
        )
        times = self._takeover_times
        # Of two instances, the one with the lower instance name gives up: one stays.
        if (
            len(times) == TAKEOVER_LIMIT
            and now - times[0] <= TAKEOVER_WINDOW
            and (self.instance < other)
        ):
            self.fatal = DuplicateClient(
                f"another client took MQTT client id {self.client_id!r} {TAKEOVER_LIMIT} times "
                f"within {TAKEOVER_WINDOW:.0f} s: a second {self.owner} is running "
                f"(instance {_cut(other)}); stop one of them (each shard runs once)"
            )
            log.error("%s", self.fatal)
            self._closing.set()

    def _settings(self) -> ConnectSettings:
        c = self.config
        return ConnectSettings(
            c.host,
            c.port,
            self.client_id,
            protocol=c.protocol,
            keepalive=c.keepalive,
            timeout=c.timeout,
            username=os.environ.get(c.username_env) or None,
            password=os.environ.get(c.password_env) or None,
            tls=c.tls,
            ca_file=c.ca_file,
            cert_file=c.cert_file,
            key_file=c.key_file,
            will=(
                self.status_topic,
                status_message("offline", instance=self.instance),
                1,
                True,
            ),
            max_packet=self.max_packet,
        )

    async def _serve(self, conn: MqttConnection) -> str:
        """Publish until the link breaks or the gateway closes; why it ended."""
        ended = ["closed"]

        async with anyio.create_task_group() as tg:

            def lost(why: str) -> None:
                self._conn = self._lost = None  # nothing more is handed to this connection
                if ended == ["closed"]:
                    ended[0] = why
                tg.cancel_scope.cancel()

            try:
                # Our own status topic first: its retained message, if another instance's
                # "online", is a second gateway with our name and shard.
                await conn.subscribe(self.status_topic, qos=1)
                await conn.publish(
                    self.status_topic,
                    status_message("online", instance=self.instance),
                    qos=1,
                    retain=True,
                )
                for topic in self.subscriptions:
                    # MQTT 5: a live retained message keeps its flag (retain-as-published);
                    # 3.1.1 clears it on live messages: only replays show as retained.
                    await conn.subscribe(topic, qos=1, retain_as_published=True)
            except ConnectionLost as exc:
                return f"lost during setup: {exc}"
            conn.on_lost = self._lost = lost
            self._conn = conn
            self._enter(LinkState.CONNECTED, f"{self.config.host}:{self.config.port}")
            if self.on_connected is not None:
                self.on_connected()
            tg.start_soon(self._pump)
            for _ in range(self.config.publishers):
                tg.start_soon(self._publish, conn, self._ready_out.clone(), lost)
            await self._closing.wait()
            self._conn = None
            with anyio.move_on_after(self.config.timeout, shield=True):
                with contextlib.suppress(ConnectionLost):
                    await conn.publish(
                        self.status_topic,
                        status_message("offline", instance=self.instance, stopped=True),
                        qos=1,
                        retain=True,
                    )
            conn.on_lost = self._lost = None
            tg.cancel_scope.cancel()
        conn.on_lost = None
        return ended[0]

    async def _receive(self) -> None:
        """Hand received messages to ``on_message``, oldest first, for as long as the link
        runs (messages read before a connection broke are handled after it too)."""
        inbox = self.inbox
        status_topic = self.status_topic
        handed = 0
        while True:
            message = await inbox.get()
            handed += 1
            if handed % RECEIVE_BATCH == 0:
                await anyio.lowlevel.checkpoint()  # get() does not wait while messages wait
            if message.topic == status_topic:
                self._status_seen(message.payload)
                continue
            on_message = self.on_message
            if on_message is None:
                continue
            try:
                on_message(
                    message.topic, message.payload, message.retain, message.expiry, message.at
                )
            except Exception:  # nothing a peer sends raises out of the receiver
                log.exception("a message on %s could not be handled", message.topic[:200])

    async def _pump(self) -> None:
        """Send the QoS 0 outboxes' backlogs, one message per outbox in turn."""
        ready = self._ready0
        while True:
            sent = 0
            while ready:
                box = ready.popleft()
                box.queued = False
                if not box.messages:
                    continue
                entry = box.messages.popleft()
                conn = self._conn
                if conn is None or not self._hand(conn, box, entry):
                    box.messages.appendleft(entry)
                    self._queue(box)
                    if self._conn is None:
                        return  # lost
                    await anyio.sleep(0.005)  # too many unwritten: let the socket drain
                    continue
                if box.messages:
                    self._queue(box)
                sent += 1
                if sent % PUMP_BATCH == 0:
                    await anyio.sleep(0)  # let the event loop run
            idle = self._pump_idle = anyio.Event()
            await idle.wait()
            self._pump_idle = None

    async def _publish(
        self,
        conn: MqttConnection,
        ready: MemoryObjectReceiveStream[Outbox],
        lost: Callable[[str], None],
    ) -> None:
        on_published = self.on_published
        async with ready:
            async for box in ready:
                box.queued = False
                if box.sending is not None:  # another publisher sends its head: that one
                    continue  # queues the outbox again when done (sending it twice did not)
                try:
                    if not box.messages:
                        continue
                    entry = box.sending = box.messages[0]
                    try:
                        await conn.publish(box.topic, entry[0], box.qos, box.retain)
                    except ConnectionLost as exc:
                        lost(f"publish failed: {exc}")
                        return
                    finally:
                        box.sending = None
                    if box.messages and box.messages[0] is entry:  # put() kept it
                        box.messages.popleft()
                    box.published += 1
                    if on_published is not None:
                        on_published(entry[1])
                finally:  # one message per turn: the outbox goes to the back of the queue
                    if box.messages and not box.queued:
                        self._queue(box)

    def close(self) -> None:
        """Stop: publish ``offline`` if connected, disconnect, make no more attempts."""
        self._closing.set()


def _cut(text: str, limit: int = 100) -> str:
    return text if len(text) <= limit else f"{text[:limit]}..."
