"""One connection to the MQTT broker: a paho-mqtt client run by the asyncio event loop.

paho-mqtt documents an API for running its client in someone else's event loop: the socket
callbacks ``on_socket_open``/``on_socket_close``/``on_socket_register_write``/
``on_socket_unregister_write`` say when to watch its socket, and ``loop_read()``,
``loop_write()`` and ``loop_misc()`` do the work when it is readable, writable, and once a
second. :class:`MqttConnection` is that glue, on nothing else of paho's (no private names):

* The blocking ``connect()`` (the TCP and TLS handshakes) runs in a worker thread, before the
  socket callbacks are set; everything after runs on the event loop's thread.
* Output is written at once: paho asks to be watched for writing when it queues a packet,
  and the connection writes then and there (``loop_write()``), so a QoS 0 ``publish()`` is
  on the wire when it returns, with no task switch, future or callback per message. What the
  socket does not take is written when it becomes writable.
* QoS 1 and 2 publishes and subscriptions are awaited (:meth:`MqttConnection.publish`,
  :meth:`MqttConnection.subscribe`); paho's ``on_publish`` is not used (paho would call it for
  every QoS 0 message too): an awaited message's ``MQTTMessageInfo.is_published()`` is looked
  at after each read.
* Received messages wait in :class:`Inbox`, bounded in messages and bytes; what does not fit
  is dropped, counted and logged (never silently).
"""

from __future__ import annotations

import asyncio
import logging
import ssl
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, TypeVar

import anyio

# paho is imported with this module, not when a connection is made: a gateway that has
# used up its descriptors (an HTTP flood under a low limit) could not open paho's files to
# import them then, and the error ended the daemon (tests/gateway/test_bounds.py).
import paho.mqtt.client as paho_mqtt
from paho.mqtt.enums import CallbackAPIVersion
from paho.mqtt.packettypes import PacketTypes
from paho.mqtt.properties import Properties
from paho.mqtt.reasoncodes import ReasonCode
from paho.mqtt.subscribeoptions import SubscribeOptions

log = logging.getLogger("aiofins.gateway")
T = TypeVar("T")

#: Received messages waiting for the gateway, at most (more are dropped, counted, logged).
MAX_INCOMING = 10_000
#: Payload bytes of the received messages waiting for the gateway, at most (16 MiB).
MAX_INCOMING_BYTES = 16 * 1024 * 1024
#: Seconds between two log lines about dropped received messages (the first is at once).
DROPS_LOGGED_EVERY = 10.0


class ConnectionLost(Exception):
    """The connection to the broker failed or broke; the message says why."""


@dataclass(frozen=True)
class Received:
    """A message from the broker."""

    topic: str
    payload: bytes
    retain: bool
    #: The MQTT 5 message expiry interval left, in seconds (None: none given).
    expiry: float | None
    #: When it was read, on the event loop's clock.
    at: float


@dataclass(eq=False)
class Inbox:
    """Received messages waiting for the gateway: at most ``limit`` of them and ``max_bytes``
    payload bytes; a message that does not fit is dropped (counted, logged)."""

    limit: int = MAX_INCOMING
    max_bytes: int = MAX_INCOMING_BYTES
    messages: deque[Received] = field(default_factory=deque)
    #: Payload bytes waiting.
    size: int = 0
    #: Messages dropped because the inbox was full, and their payload bytes.
    dropped: int = 0
    dropped_bytes: int = 0
    _logged_at: float = -1e9
    _unlogged: int = 0
    _waiting: anyio.Event | None = None

    def put(self, message: Received) -> bool:
        """Keep ``message`` for :meth:`get`, or drop it (False) if it does not fit."""
        size = len(message.payload)
        if len(self.messages) >= self.limit or self.size + size > self.max_bytes:
            self._drop(message, size)
            return False
        self.messages.append(message)
        self.size += size
        if self._waiting is not None:
            self._waiting.set()
        return True

    def _drop(self, message: Received, size: int) -> None:
        self.dropped += 1
        self.dropped_bytes += size
        self._unlogged += 1
        if message.at - self._logged_at >= DROPS_LOGGED_EVERY:
            log.warning(
                "received MQTT messages dropped: %d (the last on %s, %d bytes): %d messages of "
                "%d bytes wait for the gateway already (at most %d messages, %d bytes); "
                "%d dropped since the start",
                self._unlogged,
                message.topic[:200],
                size,
                len(self.messages),
                self.size,
                self.limit,
                self.max_bytes,
                self.dropped,
            )
            self._logged_at = message.at
            self._unlogged = 0

    async def get(self) -> Received:
        while not self.messages:
            waiting = self._waiting = anyio.Event()
            await waiting.wait()
            self._waiting = None
        message = self.messages.popleft()
        self.size -= len(message.payload)
        return message


@dataclass(frozen=True)
class ConnectSettings:
    """What :class:`MqttConnection` connects with."""

    host: str
    port: int
    client_id: str
    protocol: str = "5"
    keepalive: int = 60
    #: Seconds for the TCP/TLS handshake and for the broker's CONNACK, SUBACK, PUBACK.
    timeout: float = 10.0
    username: str | None = None
    password: str | None = None
    tls: bool = False
    ca_file: str | None = None
    cert_file: str | None = None
    key_file: str | None = None
    #: (topic, payload, qos, retain) the broker publishes if the connection is lost.
    will: tuple[str, bytes, int, bool] | None = None
    #: MQTT 5: the largest packet the broker may send us (CONNECT's Maximum Packet Size).
    max_packet: int | None = None


class MqttConnection:
    """A paho-mqtt client on the running asyncio loop, for one connection (make a new one to
    connect again). :meth:`connect`, then :meth:`publish`/:meth:`publish_now`/
    :meth:`subscribe`, :meth:`disconnect` (or :meth:`abort`) when done. Received messages go
    to ``inbox``; ``on_lost(why)`` is called once if the connection breaks after connecting.
    """

    def __init__(
        self,
        settings: ConnectSettings,
        inbox: Inbox,
        *,
        on_lost: Callable[[str], None] | None = None,
    ) -> None:
        self.settings = settings
        self.inbox = inbox
        self.on_lost = on_lost
        self.v5 = settings.protocol == "5"
        client = paho_mqtt.Client(
            CallbackAPIVersion.VERSION2,
            client_id=settings.client_id,
            protocol=paho_mqtt.MQTTv5 if self.v5 else paho_mqtt.MQTTv311,
            clean_session=None if self.v5 else True,
            reconnect_on_failure=False,
        )
        logger = logging.getLogger("aiofins.gateway.mqtt")
        if logger.isEnabledFor(logging.DEBUG):  # paho logs a line per packet: only then
            client.enable_logger(logger)
        client.connect_timeout = settings.timeout
        if settings.username is not None:
            client.username_pw_set(settings.username, settings.password)
        if settings.tls:
            client.tls_set(
                ca_certs=settings.ca_file,
                certfile=settings.cert_file,
                keyfile=settings.key_file,
                cert_reqs=ssl.CERT_REQUIRED,
            )
        if settings.will is not None:
            topic, payload, qos, retain = settings.will
            client.will_set(topic, payload, qos, retain)
        client.on_connect = self._on_connect
        client.on_disconnect = self._on_disconnect
        client.on_message = self._on_message
        client.on_subscribe = self._on_subscribe
        self.client = client
        self._loop: asyncio.AbstractEventLoop | None = None
        self._sock: Any = None
        self._writer = False
        self._connack: asyncio.Future[None] | None = None
        #: mid -> (future of the SUBACK's reason codes).
        self._subacks: dict[int, asyncio.Future[list[ReasonCode]]] = {}
        #: QoS 1/2 publishes awaited: (message info, future).
        self._acks: list[tuple[paho_mqtt.MQTTMessageInfo, asyncio.Future[None]]] = []
        self._misc: asyncio.TimerHandle | None = None
        #: Why the connection ended (None while it is up or being made).
        self.lost: str | None = None
        #: Whether the broker accepted the connection (its CONNACK came).
        self.connected = False
        self._closing = False
        self.closed = anyio.Event()

    # -- connecting -----------------------------------------------------------------------

    async def connect(self) -> None:
        """Connect and wait for the broker's CONNACK (at most ``timeout``), or raise
        :class:`ConnectionLost` saying why not."""
        s = self.settings
        loop = self._loop = asyncio.get_running_loop()
        self._connack = loop.create_future()
        properties = None
        if self.v5 and s.max_packet is not None:
            properties = Properties(PacketTypes.CONNECT)  # type: ignore[no-untyped-call]
            properties.MaximumPacketSize = s.max_packet
        client = self.client
        try:
            # Blocking (name lookup, TCP and TLS handshakes): in a worker thread. With no
            # socket callbacks set yet, paho writes the CONNECT packet there itself.
            await anyio.to_thread.run_sync(
                lambda: client.connect(s.host, s.port, s.keepalive, properties=properties),
                abandon_on_cancel=True,
            )
        except (OSError, ValueError, ssl.SSLError) as exc:
            self._end(f"{type(exc).__name__}: {exc}" if not str(exc) else str(exc))
            raise ConnectionLost(self.lost or str(exc)) from None
        sock = self._sock = client.socket()
        if sock is None:  # pragma: no cover - paho closed it already
            self._end("the connection was closed at once")
            raise ConnectionLost(self.lost)
        client.on_socket_close = self._on_socket_close
        client.on_socket_register_write = self._on_register_write
        client.on_socket_unregister_write = self._on_unregister_write
        loop.add_reader(sock, self._readable)
        if client.want_write():  # the CONNECT not written whole in the thread
            self._write()
            if client.want_write():
                self._watch_writes()
        self._misc = loop.call_later(1.0, self._tick)
        try:
            with anyio.fail_after(s.timeout):
                await self._connack
        except TimeoutError:
            self.abort(f"no CONNACK within {s.timeout:g} s")
            raise ConnectionLost(self.lost) from None
        finally:
            if self.lost is not None:
                self.abort(self.lost)

    def _on_connect(
        self,
        client: paho_mqtt.Client,
        userdata: Any,
        flags: Any,
        reason: ReasonCode,
        properties: Any,
    ) -> None:
        future = self._connack
        if future is None or future.done():
            return
        if reason.is_failure:
            self._end(f"the broker refused the connection: {reason}")
        else:
            self.connected = True
            future.set_result(None)

    # -- the socket, driven by the loop ---------------------------------------------------

    def _readable(self) -> None:
        client = self.client
        try:
            rc = client.loop_read()
            sock = self._sock
            # TLS: records already decrypted wait in the SSL object, not in the socket, and
            # the loop would not say it is readable again: read them now.
            while not rc and isinstance(sock, ssl.SSLSocket) and sock.pending():
                rc = client.loop_read()
        except Exception as exc:  # nothing the broker sends raises out of the loop's callback
            log.exception("reading from the MQTT broker failed")
            self.abort(f"reading failed: {type(exc).__name__}: {exc}")
            return
        if rc:
            self._end(f"connection lost: {_error(rc)}")
        self._check_acks()

    def _on_register_write(self, client: paho_mqtt.Client, userdata: Any, sock: Any) -> None:
        """paho has output: write it now (a QoS 0 publish is sent before ``publish()``
        returns); what the socket does not take yet, when it becomes writable."""
        if self._writer:
            return
        self._write()
        if client.want_write() and self.lost is None:
            self._watch_writes()

    def _write(self) -> None:
        rc = self.client.loop_write()
        if rc:
            self._end(f"connection lost: {_error(rc)}")

    def _watch_writes(self) -> None:
        if not self._writer and self._loop is not None and self._sock is not None:
            self._writer = True
            self._loop.add_writer(self._sock, self._write)

    def _on_unregister_write(self, client: paho_mqtt.Client, userdata: Any, sock: Any) -> None:
        if self._writer:
            self._writer = False
            if self._loop is not None:
                self._loop.remove_writer(sock)

    def _on_socket_close(self, client: paho_mqtt.Client, userdata: Any, sock: Any) -> None:
        self._unwatch(sock)

    def _unwatch(self, sock: Any) -> None:
        loop = self._loop
        if loop is not None and sock is not None:
            loop.remove_reader(sock)
            if self._writer:
                loop.remove_writer(sock)
        self._writer = False
        self._sock = None

    def _tick(self) -> None:
        """Once a second: paho's keepalive (PINGREQ, and the end of a silent connection)."""
        if self.lost is not None or self._loop is None:
            return
        rc = self.client.loop_misc()
        if rc:
            self._end(f"connection lost: {_error(rc)}")
            return
        self._misc = self._loop.call_later(1.0, self._tick)

    def _on_disconnect(
        self,
        client: paho_mqtt.Client,
        userdata: Any,
        flags: Any,
        reason: ReasonCode,
        properties: Any,
    ) -> None:
        self._end(f"disconnected: {reason}")

    def _end(self, why: str) -> None:
        """The one place the connection ends: wake everything that waits on it."""
        if self.lost is not None:
            return
        self.lost = why
        if self._misc is not None:
            self._misc.cancel()
        error = ConnectionLost(why)
        for future in (self._connack, *self._subacks.values(), *(f for _, f in self._acks)):
            if future is not None and not future.done():
                future.set_exception(error)
                future.exception()  # retrieved: no "never retrieved" warning if unawaited
        self._subacks.clear()
        self._acks.clear()
        self.closed.set()
        if self.on_lost is not None and self.connected and not self._closing:
            self.on_lost(why)

    # -- receiving ------------------------------------------------------------------------

    def _on_message(
        self, client: paho_mqtt.Client, userdata: Any, message: paho_mqtt.MQTTMessage
    ) -> None:
        try:
            topic = message.topic
        except UnicodeDecodeError:  # a broker passes only UTF-8 topics (MQTT 4.7.3)
            topic = "(a topic that is not UTF-8)"
        expiry = None
        if self.v5 and message.properties is not None:
            expiry = getattr(message.properties, "MessageExpiryInterval", None)
        assert self._loop is not None
        payload = message.payload
        self.inbox.put(
            Received(
                topic,
                payload if isinstance(payload, bytes) else bytes(payload),
                bool(message.retain),
                None if expiry is None else float(expiry),
                self._loop.time(),
            )
        )

    # -- publishing and subscribing -------------------------------------------------------

    def publish_now(self, topic: str, payload: bytes, retain: bool) -> paho_mqtt.MQTTMessageInfo:
        """Publish at QoS 0: written to the socket before this returns unless the socket is
        full (then as soon as it takes it). ``info.rc`` is not 0 if the connection is gone;
        ``info.is_published()`` says when it was written."""
        return self.client.publish(topic, payload, 0, retain)

    async def publish(self, topic: str, payload: bytes, qos: int, retain: bool) -> None:
        """Publish and, at QoS 1 or 2, wait for the broker's acknowledgement (at most
        ``timeout``); :class:`ConnectionLost` if the connection is or goes away."""
        if self.lost is not None:
            raise ConnectionLost(self.lost)
        info = self.client.publish(topic, payload, qos, retain)
        if info.rc:
            self._end(f"publish failed: {_error(info.rc)}")
            raise ConnectionLost(self.lost)
        if qos == 0 or info.is_published():
            return
        assert self._loop is not None
        future: asyncio.Future[None] = self._loop.create_future()
        self._acks.append((info, future))
        await self._answer(future, "PUBACK")

    async def _answer(self, future: asyncio.Future[T], what: str) -> T:
        """The broker's answer, or :class:`ConnectionLost` (the connection is closed when
        none comes within ``timeout``: a broker that stopped answering)."""
        try:
            with anyio.fail_after(self.settings.timeout):
                return await future
        except TimeoutError:
            self.abort(f"no {what} within {self.settings.timeout:g} s")
            raise ConnectionLost(self.lost) from None

    def _check_acks(self) -> None:
        acks = self._acks
        if acks and any(info.is_published() for info, _ in acks):
            keep = []
            for info, future in acks:
                if info.is_published():
                    if not future.done():
                        future.set_result(None)
                elif not future.done():
                    keep.append((info, future))
            self._acks = keep

    async def subscribe(self, topic: str, qos: int = 1, retain_as_published: bool = False) -> None:
        """Subscribe and wait for the SUBACK; :class:`ConnectionLost` if refused or lost."""
        if self.lost is not None:
            raise ConnectionLost(self.lost)
        if self.v5:
            options = SubscribeOptions(qos=qos, retainAsPublished=retain_as_published)
            rc, mid = self.client.subscribe(topic, options=options)
        else:
            rc, mid = self.client.subscribe(topic, qos)
        if rc or mid is None:
            self._end(f"subscribe failed: {_error(rc)}")
            raise ConnectionLost(self.lost)
        assert self._loop is not None
        future: asyncio.Future[list[ReasonCode]] = self._loop.create_future()
        self._subacks[mid] = future
        reasons = await self._answer(future, "SUBACK")
        refused = [r for r in reasons if r.is_failure]
        if refused:
            raise ConnectionLost(f"the broker refused the subscription to {topic}: {refused[0]}")

    def _on_subscribe(
        self,
        client: paho_mqtt.Client,
        userdata: Any,
        mid: int,
        reasons: list[ReasonCode],
        properties: Any,
    ) -> None:
        future = self._subacks.pop(mid, None)
        if future is not None and not future.done():
            future.set_result(reasons)

    # -- ending ---------------------------------------------------------------------------

    async def disconnect(self) -> None:
        """Send DISCONNECT (the broker then forgets the will) and close, waiting at most
        ``timeout`` for paho to write it."""
        self._closing = True
        if self.lost is None:
            self.client.disconnect()
            with anyio.move_on_after(self.settings.timeout):
                await self.closed.wait()
        self.abort("disconnected")

    def abort(self, why: str = "closed") -> None:
        """Close at once (the broker publishes the will, if any)."""
        sock = self._sock
        self._unwatch(sock)
        if sock is not None:
            sock.close()
        self._end(why)


def _error(rc: int) -> str:
    return f"{paho_mqtt.error_string(rc)} (error {int(rc)})"
