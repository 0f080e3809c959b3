"""The gateway's Prometheus metrics (prometheus_client), read from its live counters.

A collector reads the counters when ``/metrics`` is scraped, so a scan costs nothing extra;
only the scan-to-publish latency is a histogram fed per published message (a bucket count
bumped, no lock and no call into prometheus_client). Every gateway has
its own registry (two gateways in one process do not mix their numbers). Names start with
``aiofins_gateway_``; the library's own metrics (:class:`aiofins.metrics.FinsMetrics`: the
pool's endpoints, sessions and request latencies, the poller's groups) are served next to
them.
"""

from __future__ import annotations

from bisect import bisect_left
from collections.abc import Iterator
from typing import TYPE_CHECKING

from prometheus_client import CollectorRegistry, generate_latest
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, HistogramMetricFamily
from prometheus_client.registry import Collector

from .mqtt import LinkState
from .plcs import PlcState

if TYPE_CHECKING:
    from prometheus_client.metrics_core import Metric

    from .daemon import Gateway

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


class GatewayMetrics:
    """A registry with the gateway's metrics; :meth:`render` is the ``/metrics`` body."""

    def __init__(self, gateway: Gateway) -> None:
        self.registry = CollectorRegistry(auto_describe=False)
        self.latency = LatencyHistogram()
        self.registry.register(_Collector(gateway, self.latency))
        self.registry.register(gateway.library_metrics)

    def render(self) -> bytes:
        return generate_latest(self.registry)


class _Collector(Collector):
    def __init__(self, gateway: Gateway, latency: LatencyHistogram) -> None:
        self.gateway = gateway
        self.latency = latency

    def collect(self) -> Iterator[Metric]:
        gw = self.gateway
        labels = ["plc", "group"]
        scans = CounterMetricFamily("aiofins_gateway_scans", "Scans run", labels=labels)
        errors = CounterMetricFamily(
            "aiofins_gateway_scan_errors", "Scans that failed", labels=labels
        )
        missed = CounterMetricFamily(
            "aiofins_gateway_missed_scans",
            "Scan times skipped (overrun or backpressure)",
            labels=labels,
        )
        published = CounterMetricFamily(
            "aiofins_gateway_published_messages", "Scan messages the broker took", labels=labels
        )
        dropped = CounterMetricFamily(
            "aiofins_gateway_dropped_messages",
            "Scan messages dropped from a full outbox (broker away)",
            labels=labels,
        )
        queued = GaugeMetricFamily(
            "aiofins_gateway_queued_messages", "Scan messages waiting for the broker", labels=labels
        )
        for route in gw.routes.values():
            key = [route.plc, route.group.name]
            scans.add_metric(key, route.scans)
            errors.add_metric(key, route.errors)
            missed.add_metric(key, route.missed)
            published.add_metric(key, route.outbox.published)
            dropped.add_metric(key, route.outbox.dropped)
            queued.add_metric(key, len(route.outbox.messages))
        yield from (scans, errors, missed, published, dropped, queued)

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
