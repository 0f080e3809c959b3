"""The gateway's Prometheus metrics (prometheus_client), read from its live counters.

A collector reads the counters when ``/metrics`` is scraped, so a scan costs nothing extra;
only the scan-to-publish latency and the event loop's lag are histograms fed as they happen
(a bucket count bumped, no lock and no call into prometheus_client). Every gateway has
its own registry (two gateways in one process do not mix their numbers). Names start with
``aiofins_gateway_``; the library's own metrics (:class:`aiofins.metrics.FinsMetrics`: the
pool's endpoints, sessions and request latencies, the poller's groups) are served next to
them.

A scrape of a gateway of 1,000 PLCs is ~44,000 lines (3 MB). It must not hold the event loop
that runs the scans: :meth:`GatewayMetrics.scrape` renders it one metric family at a time and
lets the loop run between families, and the text is written by :func:`exposition`, which
gives prometheus_client's own text format byte for byte at a fraction of its cost (the label
strings are rendered once and kept). Scrapes that arrive while one is being rendered get
that one's text.
"""

from __future__ import annotations

from bisect import bisect_left
from collections.abc import Callable, Iterable, Iterator
from typing import TYPE_CHECKING

import anyio
from prometheus_client import CollectorRegistry, generate_latest
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, HistogramMetricFamily
from prometheus_client.openmetrics.exposition import escape_label_name, escape_metric_name
from prometheus_client.registry import Collector
from prometheus_client.utils import floatToGoString

from .mqtt import LinkState
from .plcs import PlcState

if TYPE_CHECKING:
    from prometheus_client.metrics_core import Metric

    from .daemon import Gateway, Route

CONTENT_TYPE = "text/plain; version=0.0.4; charset=utf-8"
#: Scan-to-publish latency buckets (seconds).
LATENCY_BUCKETS = (
    0.001,
    0.0025,
    0.005,
    0.01,
    0.025,
    0.05,
    0.1,
    0.25,
    0.5,
    1.0,
    2.5,
    5.0,
    10.0,
    30.0,
)


class LatencyHistogram:
    """Counts of observations per bucket (upper bounds ``LATENCY_BUCKETS``, then +Inf)."""

    __slots__ = ("counts", "sum")

    def __init__(self) -> None:
        self.counts = [0] * (len(LATENCY_BUCKETS) + 1)
        self.sum = 0.0

    def observe(self, seconds: float) -> None:
        self.counts[bisect_left(LATENCY_BUCKETS, seconds)] += 1
        self.sum += seconds

    def metric(self, name: str, documentation: str) -> HistogramMetricFamily:
        buckets: list[tuple[str, float]] = []
        total = 0
        for bound, count in zip((*map(repr, LATENCY_BUCKETS), "+Inf"), self.counts, strict=True):
            total += count
            buckets.append((bound, total))
        return HistogramMetricFamily(name, documentation, buckets=buckets, sum_value=self.sum)


#: Sample lines rendered between two turns of the event loop (at most one metric family
#: more: a family is rendered whole).
LINES_PER_STEP = 500
#: Label strings kept (a gateway's label sets are bounded by its PLCs and the library's
#: ``max_endpoints``; past this the cache starts over).
LABEL_CACHE_SIZE = 200_000
_HISTOGRAM_PARTS = ("_created", "_gsum", "_gcount")
#: prometheus_client's float format (untyped there).
_go_float: Callable[[float], str] = floatToGoString


class Exposition:
    """Prometheus text format (``generate_latest``'s, byte for byte) of metric families,
    with the label strings of every sample kept once rendered."""

    def __init__(self) -> None:
        self._labels: dict[tuple[tuple[str, str], ...], str] = {}

    def family(self, metric: Metric) -> str:
        """The text of one metric family, as prometheus_client's ``generate_latest``."""
        mtype = metric.type
        if mtype not in ("counter", "gauge", "histogram"):  # not the gateway's: as is
            return generate_latest(_One(metric)).decode()
        name = metric.name + "_total" if mtype == "counter" else metric.name
        doc = metric.documentation.replace("\\", r"\\").replace("\n", r"\n")
        escaped = escape_metric_name(name)
        out = [f"# HELP {escaped} {doc}\n# TYPE {escaped} {mtype}\n"]
        special = {metric.name + part: part for part in _HISTOGRAM_PARTS}
        later: dict[str, list[str]] = {}
        names: dict[str, str] = {}
        cache = self._labels
        for sample in metric.samples:
            sname = names.get(sample.name)
            if sname is None:
                sname = names[sample.name] = escape_metric_name(sample.name)
            value = sample.value
            if value.__class__ is int and -1_000_000 < value < 1_000_000:
                text = f"{value}.0"  # what floatToGoString gives, sooner
            else:
                text = _go_float(value)
            if sample.timestamp is not None:
                text += f" {int(float(sample.timestamp) * 1000):d}"
            labels = sample.labels
            if labels:
                key = tuple(labels.items())
                labelstr = cache.get(key)
                if labelstr is None:
                    if len(cache) >= LABEL_CACHE_SIZE:
                        cache.clear()
                    labelstr = cache[key] = _labelstr(labels)
                line = f"{sname}{labelstr} {text}\n"
            else:
                line = f"{sname} {text}\n"
            part = special.get(sample.name)
            if part is None:
                out.append(line)
            else:
                later.setdefault(part, []).append(line)
        for part, lines in sorted(later.items()):
            extra = escape_metric_name(metric.name + part)
            out.append(f"# HELP {extra} {doc}\n# TYPE {extra} gauge\n")
            out.extend(lines)
        return "".join(out)

    def families(self, metrics: Iterable[Metric]) -> Iterator[tuple[str, int]]:
        """Each family's text and its number of samples."""
        for metric in metrics:
            try:
                yield self.family(metric), len(metric.samples)
            except Exception as exc:  # as generate_latest: which family failed
                exc.args = (*(exc.args or ("",)), metric)
                raise


def _labelstr(labels: dict[str, str]) -> str:
    pairs = ",".join(
        f'{escape_label_name(k)}="{_escape_value(v)}"' for k, v in sorted(labels.items())
    )
    return f"{{{pairs}}}"


def _escape_value(value: str) -> str:
    return value.replace("\\", r"\\").replace("\n", r"\n").replace('"', r"\"")


class _One(Collector):
    def __init__(self, metric: Metric) -> None:
        self.metric = metric

    def collect(self) -> Iterator[Metric]:
        yield self.metric


def exposition(collector: Collector | CollectorRegistry) -> bytes:
    """Prometheus text format of everything ``collector`` collects: what
    ``prometheus_client.generate_latest`` gives, byte for byte, in a fraction of its time."""
    return "".join(text for text, _ in Exposition().families(collector.collect())).encode()


class GatewayMetrics:
    """A registry with the gateway's metrics; :meth:`scrape` is the ``/metrics`` body."""

    def __init__(self, gateway: Gateway) -> None:
        self.registry = CollectorRegistry(auto_describe=False)
        self.latency = LatencyHistogram()
        #: How late the event loop ran the gateway's lag probe (see ``Gateway``).
        self.loop_lag = LatencyHistogram()
        self.registry.register(_Collector(gateway, self.latency, self.loop_lag))
        self.registry.register(gateway.library_metrics)
        self._exposition = Exposition()
        self._rendering: anyio.Event | None = None
        self._shared: bytes | None = None

    def render(self) -> bytes:
        """The metrics now, in one go (holds the loop for the whole render)."""
        return "".join(t for t, _ in self._exposition.families(self.registry.collect())).encode()

    async def scrape(self) -> bytes:
        """The metrics now, rendered a family at a time with the event loop's other work in
        between (at most :data:`LINES_PER_STEP` lines, or one family, per turn). Called
        while a render is under way, it waits for that one and answers its text."""
        rendering = self._rendering
        if rendering is not None:
            await rendering.wait()
            if self._shared is None:
                raise RuntimeError("the /metrics render this scrape waited for failed")
            return self._shared
        done = self._rendering = anyio.Event()
        self._shared = None
        try:
            parts: list[str] = []
            lines = 0
            for text, samples in self._exposition.families(self.registry.collect()):
                parts.append(text)
                lines += samples
                if lines >= LINES_PER_STEP:
                    lines = 0
                    await anyio.lowlevel.checkpoint()
            self._shared = "".join(parts).encode()
        finally:
            self._rendering = None
            done.set()
        return self._shared


#: The per (PLC, group) families: name, help, type, value.
_PER_ROUTE: tuple[
    tuple[str, str, type[CounterMetricFamily | GaugeMetricFamily], Callable[[Route], float]], ...
] = (
    ("aiofins_gateway_scans", "Scans run", CounterMetricFamily, lambda r: r.scans),
    ("aiofins_gateway_scan_errors", "Scans that failed", CounterMetricFamily, lambda r: r.errors),
    (
        "aiofins_gateway_missed_scans",
        "Scan times skipped (overrun or backpressure)",
        CounterMetricFamily,
        lambda r: r.missed,
    ),
    (
        "aiofins_gateway_published_messages",
        "Scan messages the broker took",
        CounterMetricFamily,
        lambda r: r.outbox.published,
    ),
    (
        "aiofins_gateway_dropped_messages",
        "Scan messages dropped from a full outbox (broker away)",
        CounterMetricFamily,
        lambda r: r.outbox.dropped,
    ),
    (
        "aiofins_gateway_queued_messages",
        "Scan messages waiting for the broker",
        GaugeMetricFamily,
        lambda r: len(r.outbox.messages),
    ),
)


class _Collector(Collector):
    def __init__(
        self, gateway: Gateway, latency: LatencyHistogram, loop_lag: LatencyHistogram
    ) -> None:
        self.gateway = gateway
        self.latency = latency
        self.loop_lag = loop_lag

    def collect(self) -> Iterator[Metric]:
        """The metrics now, one family at a time (see :meth:`GatewayMetrics.scrape`)."""
        gw = self.gateway
        labels = ["plc", "group"]
        routes = list(gw.routes.values())
        for name, doc, family, value in _PER_ROUTE:
            metric = family(name, doc, labels=labels)
            for route in routes:
                metric.add_metric([route.plc, route.group.name], value(route))
            yield metric

        online = GaugeMetricFamily(
            "aiofins_gateway_plc_online", "1 if the PLC is online", labels=["plc"]
        )
        transitions = CounterMetricFamily(
            "aiofins_gateway_plc_transitions", "Online/offline changes", labels=["plc"]
        )
        for status in gw.plc_status.values():
            online.add_metric([status.name], 1.0 if status.state is PlcState.ONLINE else 0.0)
            transitions.add_metric([status.name], status.transitions)
        yield from (online, transitions)

        link = gw.link
        yield GaugeMetricFamily(
            "aiofins_gateway_mqtt_connected",
            "1 while the broker link is connected",
            value=1.0 if link.state is LinkState.CONNECTED else 0.0,
        )
        yield CounterMetricFamily(
            "aiofins_gateway_mqtt_connects", "Broker connections made", value=link.connects
        )
        yield CounterMetricFamily(
            "aiofins_gateway_mqtt_connect_failures",
            "Failed broker connection attempts",
            value=link.connect_failures,
        )
        yield CounterMetricFamily(
            "aiofins_gateway_mqtt_disconnects",
            "Broker connections lost or closed",
            value=link.disconnects,
        )
        yield CounterMetricFamily(
            "aiofins_gateway_mqtt_takeovers",
            "Times another client took the gateway's MQTT client id (a duplicate shard)",
            value=link.takeovers,
        )
        inbox = link.inbox
        yield GaugeMetricFamily(
            "aiofins_gateway_mqtt_received_waiting",
            "Received MQTT messages waiting for the gateway (the inbox)",
            value=len(inbox.messages),
        )
        yield CounterMetricFamily(
            "aiofins_gateway_mqtt_received_dropped",
            "Received MQTT messages dropped: the inbox was full (messages or bytes)",
            value=inbox.dropped,
        )
        yield GaugeMetricFamily(
            "aiofins_gateway_queued_writes",
            "Set requests waiting in the PLCs' write queues",
            value=sum(len(w.queue) for w in gw.writers.values()),
        )
        yield CounterMetricFamily(
            "aiofins_gateway_dropped_replies",
            "Replies to set requests on no writable tag dropped (every pooled outbox busy)",
            value=gw.reply_pool.dropped,
        )
        http = gw.http
        if http is not None:
            yield GaugeMetricFamily(
                "aiofins_gateway_http_connections",
                "HTTP connections being served",
                value=http.connections,
            )
            yield CounterMetricFamily(
                "aiofins_gateway_http_accept_errors",
                "HTTP accepts that failed (too many open files, ...)",
                value=http.accept_errors,
            )
            yield CounterMetricFamily(
                "aiofins_gateway_http_timeouts",
                "HTTP connections closed for taking longer than idle_timeout",
                value=http.timeouts,
            )
        writes = CounterMetricFamily(
            "aiofins_gateway_writes", "Set requests by outcome", labels=["outcome"]
        )
        for outcome, count in sorted(gw.write_counts.items()):
            writes.add_metric([outcome], count)
        yield writes
        yield self.latency.metric(
            "aiofins_gateway_publish_latency_seconds",
            "Time from a scan's timestamp to the broker taking its message (QoS 0: to the "
            "connection taking it)",
        )
        yield self.loop_lag.metric(
            "aiofins_gateway_loop_lag_seconds",
            "How late the event loop ran a timer due every 0.25 s (work that holds the loop "
            "delays scans by as much)",
        )
