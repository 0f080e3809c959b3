"""The gateway: PLCs polled by a :class:`~aiofins.Poller`, scans published to MQTT.

::

    config = load_config("gateway.toml")
    async with Gateway(config, shard=Shard(0, 2)) as gateway:
        await gateway.wait_closed()        # until gateway.close() (the CLI: SIGINT/SIGTERM)

The gateway sits above the library: one :class:`~aiofins.Pool` and one Poller hold a scan
group per (PLC, group) pair of its shard; each snapshot becomes a JSON message in that pair's
outbox (:mod:`.mqtt`), so no scan ever waits for the broker. Runs on asyncio (the MQTT client is
asyncio only; uvloop works).
"""

from __future__ import annotations

import json
import logging
import os
import time
from collections.abc import Callable, Coroutine
from contextlib import AsyncExitStack
from dataclasses import dataclass, field
from types import TracebackType
from typing import Any

import anyio
from anyio.abc import TaskGroup

from ..metrics import FinsMetrics
from ..poller import Poller, ScanGroup
from ..pool import Pool
from .config import GatewayConfig, GroupConfig, PlcConfig, render
from .http import HttpServer
from .metrics import CONTENT_TYPE, GatewayMetrics
from .mqtt import DuplicateClient, LinkState, MqttLink, Outbox
from .payload import ScanEncoder, SetPayloadError, parse_set, request_id_of, status_message
from .plcs import PlcState, PlcStatus
from .sharding import Shard
from .writes import (
    REPLY_BUFFER,
    RETAINED_MEMORY,
    ReplyPool,
    SetRequest,
    Writer,
    encode_reply,
    new_reply,
    reply_topic,
    write_value,
)

log = logging.getLogger("aiofins.gateway")

#: Set requests carried out at once (the rest wait their turn).
MAX_CONCURRENT_WRITES = 16
#: Seconds between two probes of the event loop's lag.
LAG_PROBE_INTERVAL = 0.25
#: Refused set requests logged one by one per second, at most (the rest are summed up).
REFUSALS_LOGGED = 20


@dataclass(eq=False)
class Route:
    """One scan group of one PLC and where its snapshots go."""

    name: str
    plc: str
    url: str
    group: GroupConfig
    topic: str
    outbox: Outbox
    status: PlcStatus = field(repr=False)
    #: The poller's scan group, from the route's first scan on (see ``Gateway._start_groups``).
    scan_group: ScanGroup | None = None
    #: Whether a scan of the route has ended (succeeded or failed).
    scanned: bool = field(default=False, repr=False)
    encoder: ScanEncoder = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.encoder = ScanEncoder(self.plc, self.group.name)

    @property
    def scans(self) -> int:
        return 0 if self.scan_group is None else self.scan_group.scans

    @property
    def errors(self) -> int:
        return 0 if self.scan_group is None else self.scan_group.errors

    @property
    def missed(self) -> int:
        return 0 if self.scan_group is None else self.scan_group.missed


class Gateway:
    """Polls the PLCs of its shard and publishes their scans; see the module docstring."""

    def __init__(
        self,
        config: GatewayConfig,
        *,
        shard: Shard | None = None,
    ) -> None:
        self.config = config
        self.shard = shard or Shard(0, 1)
        sharded = self.shard.count > 1
        #: This gateway's name: the configured one, with ``-<index>`` when sharded.
        self.name = f"{config.name}-{self.shard.index}" if sharded else config.name
        self.plcs: tuple[PlcConfig, ...] = tuple(p for p in config.plcs if self.shard.owns(p.name))
        mqtt = config.mqtt
        #: The library's own metrics (sessions, pool, poller), served on /metrics too.
        self.library_metrics = FinsMetrics(registry=None)
        options = dict(config.connect)
        # A session per PLC, kept: with the pool's default bound (256 sessions) a gateway of
        # more PLCs evicted one and opened another on nearly every scan.
        options.setdefault("max_sessions", max(256, len(self.plcs) + 16))
        self.pool = Pool(hooks=self.library_metrics.hooks, **options)
        self.poller = Poller(self.pool, buffer=max(64, sum(len(p.groups) for p in self.plcs)))
        self.plc_status: dict[str, PlcStatus] = {p.name: PlcStatus(p.name) for p in self.plcs}
        self.routes: dict[str, Route] = {}
        #: Set requests by outcome (see :data:`~aiofins.gateway.writes.OUTCOMES`).
        self.write_counts: dict[str, int] = {}
        self._set_routes: dict[str, Route] = {}  # "{topic}/set/" -> route
        #: The reply outbox of each writable tag's set topic ("{topic}/set/{tag}").
        self._reply_boxes: dict[str, Outbox] = {}
        #: Reply outboxes for set topics of no writable tag (bounded, reused).
        self.reply_pool = ReplyPool()
        #: Each PLC's write queue.
        self.writers: dict[str, Writer] = {}
        #: Retained set messages already answered: (topic, payload) -> None, oldest first.
        self._retained_seen: dict[tuple[str, bytes], None] = {}
        self._refusal_window = -1e9
        self._refusals_logged = self._refusals_unlogged = 0
        #: Why the gateway stopped on its own (a duplicate shard), or None.
        self.fatal: DuplicateClient | None = None
        self.library_metrics.watch_pool(self.pool)
        self.library_metrics.watch_poller(self.poller)
        self.metrics = GatewayMetrics(self)
        self.link = MqttLink(
            mqtt,
            client_id=(
                f"aiofins-gateway-{self.name}"
                if mqtt.client_id is None
                else f"{mqtt.client_id}-{self.shard.index}"
                if sharded
                else mqtt.client_id
            ),
            status_topic=render(mqtt.gateway_topic, gateway=self.name),
            on_message=self._on_message,
            on_connected=self._on_connected,
            on_published=self._on_published,
            max_packet=max(4 * config.max_payload, 256 * 1024),
            owner=f"gateway {self.name} (shard {self.shard})",
        )
        for plc in self.plcs:
            for group_name in plc.groups:
                group = config.groups[group_name]
                topic = render(group.topic, gateway=self.name, plc=plc.name, group=group_name)
                route = Route(
                    f"{plc.name}/{group_name}",
                    plc.name,
                    plc.url,
                    group,
                    topic,
                    self.link.outbox(topic, qos=group.qos, retain=group.retain, limit=group.buffer),
                    self.plc_status[plc.name],
                )
                self.routes[route.name] = route
                if group.writable:
                    self._set_routes[f"{topic}/set/"] = route
                    self.link.subscriptions.append(f"{topic}/set/+")
                    for tag in sorted(group.writable):
                        set_topic = f"{topic}/set/{tag}"
                        self._reply_boxes[set_topic] = self.link.outbox(
                            reply_topic(set_topic), qos=1, retain=False, limit=REPLY_BUFFER
                        )
            self.writers[plc.name] = Writer(
                plc.name, config.write_queue, self._start_writer, self._write
            )
        self.http: HttpServer | None = None
        if config.http.enabled:
            self.http = HttpServer(
                config.http.host,
                config.http.port,
                {"/healthz": self._healthz, "/readyz": self._readyz, "/metrics": self._metrics},
                max_connections=config.http.max_connections,
                idle_timeout=config.http.idle_timeout,
            )
        self._tg: TaskGroup | None = None
        self._closed = anyio.Event()
        self._unscanned = len(self.routes)
        self._scanned = anyio.Event()
        if not self.routes:
            self._scanned.set()
        self._writes = anyio.CapacityLimiter(MAX_CONCURRENT_WRITES)
        self._consuming = anyio.CancelScope()
        self._stack = AsyncExitStack()

    # -- lifecycle --------------------------------------------------------------------

    async def __aenter__(self) -> Gateway:
        log.info(
            "gateway %s (shard %s): %d of %d PLCs, %d scan groups",
            self.name,
            self.shard,
            len(self.plcs),
            len(self.config.plcs),
            len(self.routes),
        )
        async with AsyncExitStack() as stack:
            await stack.enter_async_context(self.pool)
            await stack.enter_async_context(self.poller)
            tg = self._tg = await stack.enter_async_context(anyio.create_task_group())
            if self.http is not None:
                await tg.start(self.http.serve)
            tg.start_soon(self._run_link)
            tg.start_soon(self._consume)
            tg.start_soon(self._start_groups)
            tg.start_soon(self._probe_loop_lag)
            self._stack = stack.pop_all()
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> bool | None:
        assert self._tg is not None
        self.close()
        self._consuming.cancel()
        with anyio.move_on_after(self.config.mqtt.timeout + 1, shield=True):
            await self.link.done.wait()  # the offline status goes out first
        self._tg.cancel_scope.cancel()
        self._tg = None
        return await self._stack.__aexit__(exc_type, exc, tb)

    def close(self) -> None:
        """Stop (publishes ``offline`` on the gateway's status topic first)."""
        self._closed.set()
        self.link.close()

    async def wait_closed(self) -> None:
        await self._closed.wait()

    async def wait_scanned(self) -> None:
        """Until every (PLC, group) has had its first scan (answered or failed): the
        gateway holds its sessions, routes and buffers from then on. The CLI keeps Python's
        garbage collector off until then and freezes them (``gc.freeze()``), so full
        collections skip them."""
        await self._scanned.wait()

    @property
    def http_port(self) -> int | None:
        return None if self.http is None else self.http.port

    async def _run_link(self) -> None:
        await self.link.run()
        if self.link.fatal is not None:  # a duplicate shard: stop, the CLI exits non-zero
            self.fatal = self.link.fatal
            self._closed.set()

    async def _probe_loop_lag(self) -> None:
        """Every :data:`LAG_PROBE_INTERVAL` s, how late the loop woke this task (the histogram
        ``aiofins_gateway_loop_lag_seconds``): whatever holds the loop delays scans as much."""
        observe = self.metrics.loop_lag.observe
        while True:
            due = anyio.current_time() + LAG_PROBE_INTERVAL
            await anyio.sleep_until(due)
            observe(max(0.0, anyio.current_time() - due))

    # -- scans --------------------------------------------------------------------------

    async def _start_groups(self) -> None:
        """Add the routes' scan groups to the poller, their first scans spread evenly over
        their interval: a thousand PLCs on one interval are not all read (and published) in
        the same instant of every second."""
        by_interval: dict[float, list[Route]] = {}
        for route in self.routes.values():
            by_interval.setdefault(route.group.interval, []).append(route)
        start = anyio.current_time()
        due = [
            (start + route.group.interval * i / len(routes), route)
            for routes in by_interval.values()
            for i, route in enumerate(routes)
        ]
        due.sort(key=lambda item: item[0])
        for at, route in due:
            if at > anyio.current_time():
                await anyio.sleep_until(at)
            group = route.group
            route.scan_group = self.poller.add_group(
                route.name, route.url, group.tags, interval=group.interval, timeout=group.timeout
            )

    async def _consume(self) -> None:
        with self._consuming:
            await self._consume_snapshots()

    async def _consume_snapshots(self) -> None:
        put = self.link.put
        routes = self.routes
        async for snap in self.poller:
            route = routes[snap.group]
            if not route.scanned:
                route.scanned = True
                self._unscanned -= 1
                if not self._unscanned:
                    self._scanned.set()
            if route.status.observe(route.group.name, snap.error) is not None:
                self._announce(route.status)
            if route.group.changes_only:
                changed = snap.changed
                if not changed:
                    continue
                names = [n for n in snap.readings if n in changed]
                put(route.outbox, route.encoder.encode(snap, names), snap.timestamp)
            else:
                put(route.outbox, route.encoder.encode(snap), snap.timestamp)

    def _announce(self, status: PlcStatus, *, changed: bool = True) -> None:
        """Queue the PLC's state on its status topic (retained; the newest replaces any
        still waiting), and log it if it ``changed`` (a state said again after a reconnect
        is not logged: a broker restart logged every PLC "online" again)."""
        topic = render(self.config.mqtt.plc_status_topic, gateway=self.name, plc=status.name)
        extra: dict[str, Any] = {"plc": status.name, "gateway": self.name}
        if status.reason is not None:
            extra["error"] = status.reason
        box = self.link.outbox(topic, qos=1, retain=True, limit=1)
        self.link.put(box, status_message(status.state.value, **extra))
        if not changed:
            return
        log.info(
            "PLC %s is %s%s",
            status.name,
            status.state.value,
            f" ({status.reason})" if status.reason else "",
        )

    def _on_connected(self) -> None:
        """After a (re)connect, a broker that lost its retained messages learns the PLCs'
        states again (those with none waiting already)."""
        topic_of = self.config.mqtt.plc_status_topic
        for status in self.plc_status.values():
            if status.state is PlcState.UNKNOWN:
                continue
            box = self.link.outboxes.get(render(topic_of, gateway=self.name, plc=status.name))
            if box is None or not box.messages:
                self._announce(status, changed=False)

    def _on_published(self, stamp: float) -> None:
        self.metrics.latency.observe(max(0.0, time.time() - stamp))

    # -- writes -------------------------------------------------------------------------

    def _on_message(
        self, topic: str, payload: bytes, retain: bool, expiry: float | None, received: float
    ) -> None:
        """A set request (read from the broker at ``received``, the loop's clock): refused at
        once (answered), or queued for its PLC's writer."""
        prefix, _, tag_name = topic.rpartition("/")
        route = self._set_routes.get(prefix + "/")
        if route is None or self._tg is None:
            return
        now = received
        group = route.group
        what = f"{route.plc}/{group.name}/{tag_name}"
        box = self._reply_boxes.get(topic)
        if box is None:
            box = self.reply_pool.outbox(reply_topic(topic))
        max_payload = self.config.max_payload
        if retain:
            key = (topic, payload)
            if key in self._retained_seen:  # answered when first seen: not again
                log.debug("retained set %s seen again: not written, not answered", what)
                self._count("retained")
                return
            self._retained_seen[key] = None
            if len(self._retained_seen) > RETAINED_MEMORY:
                del self._retained_seen[next(iter(self._retained_seen))]
            error = (
                f"{what}: a retained set message is not written (it would be written again on "
                "every start and reconnect); publish set requests without retain"
            )
            self._refuse("retained", box, tag_name, request_id_of(payload, max_payload), error)
            return
        tag = group.parsed.get(tag_name)
        if tag is None or tag_name not in group.writable:
            why = "no such tag" if tag is None else "not writable (not in the writable list)"
            self._refuse(
                "refused", box, tag_name, request_id_of(payload, max_payload), f"{what}: {why}"
            )
            return
        try:
            value, request_id = parse_set(payload, tag, max_size=max_payload)
        except SetPayloadError as exc:
            self._refuse("invalid", box, tag_name, exc.request_id, str(exc))
            return
        assert box is not None  # a writable tag has its own outbox
        age = group.write_max_age if expiry is None else min(group.write_max_age, expiry)
        request = SetRequest(
            route.plc, route.url, group, tag, value, request_id, now, now + age, box
        )
        writer = self.writers[route.plc]
        if not writer.offer(request):
            self._refuse(
                "busy",
                box,
                tag_name,
                request_id,
                f"{what}: PLC {route.plc} has {writer.limit} set requests waiting "
                "(write_queue): refused, not queued",
            )

    def _count(self, outcome: str) -> None:
        self.write_counts[outcome] = self.write_counts.get(outcome, 0) + 1

    def _refuse(
        self, outcome: str, box: Outbox | None, tag: str, request_id: str | None, error: str
    ) -> None:
        self._count(outcome)
        self._log_refusal(outcome, error)
        if box is not None:
            self.link.put(box, encode_reply(new_reply(tag, request_id, error)))
        else:
            log.warning("reply to %s dropped: every pooled reply outbox is busy", tag)

    def _log_refusal(self, outcome: str, error: str) -> None:
        """A WARNING per refusal, at most :data:`REFUSALS_LOGGED` a second: a flood of bad
        requests is summed up in one line a second instead of flooding the log."""
        now = anyio.current_time()
        if now - self._refusal_window >= 1.0:
            if self._refusals_unlogged:
                log.warning(
                    "%d more set requests refused and not logged one by one (a flood?)",
                    self._refusals_unlogged,
                )
            self._refusal_window = now
            self._refusals_logged = self._refusals_unlogged = 0
        if self._refusals_logged < REFUSALS_LOGGED:
            self._refusals_logged += 1
            log.warning("set refused (%s): %s", outcome, error)
        else:
            self._refusals_unlogged += 1

    def _start_writer(self, run: Callable[[], Coroutine[Any, Any, None]]) -> None:
        assert self._tg is not None
        self._tg.start_soon(run)

    async def _write(self, request: SetRequest) -> None:
        """Write one queued request unless it is past its deadline; answer it either way."""
        what = f"{request.plc}/{request.group.name}/{request.tag.name}"
        async with self._writes:
            now = anyio.current_time()
            if now > request.deadline:
                self._refuse(
                    "expired",
                    request.reply_box,
                    request.tag.name,
                    request.request_id,
                    f"{what}: expired: {now - request.received:.3f} s after it was received "
                    f"(at most {request.deadline - request.received:.3f} s), not written",
                )
                return
            outcome, reply = await write_value(self.pool, request, now - request.received)
        self._count(outcome)
        self.link.put(request.reply_box, encode_reply(reply))

    # -- HTTP ---------------------------------------------------------------------------

    async def _healthz(self) -> tuple[int, str, bytes]:
        return 200, "application/json", json.dumps(self.health()).encode()

    async def _readyz(self) -> tuple[int, str, bytes]:
        ready = self.link.state is LinkState.CONNECTED
        return (200 if ready else 503), "application/json", json.dumps(self.health()).encode()

    async def _metrics(self) -> tuple[int, str, bytes]:
        return 200, CONTENT_TYPE, await self.metrics.scrape()

    def health(self) -> dict[str, Any]:
        states = [s.state for s in self.plc_status.values()]
        return {
            "gateway": self.name,
            "shard": str(self.shard),
            "pid": os.getpid(),
            "mqtt": self.link.state.value,
            "plcs": {state.value: states.count(state) for state in PlcState},
            "queued_messages": self.link.queued_messages,
            "queued_writes": sum(len(w.queue) for w in self.writers.values()),
            "dropped_messages": self.link.dropped,
        }
