"""Prometheus metrics for pools, sessions and pollers (the ``aiofins[prometheus]`` extra).

:class:`FinsMetrics` is a ``prometheus_client`` collector. At each scrape it reads the
counters aiofins keeps anyway (:meth:`Pool.stats() <aiofins.Pool.stats>`, a client's
``session.stats``, a poller's scan groups): nothing is counted twice and nothing runs per
request for them. The one thing it records as requests happen is the round-trip histogram,
fed by its :attr:`~FinsMetrics.hooks` (give them to ``Pool``/``connect``). Labels are bounded:
``endpoint`` (at most ``max_endpoints`` of them; later ones are summed under ``other``) and
``family``, the command family named after the MRC (``memory``, ``status``, ...).

::

    metrics = FinsMetrics()                      # registered in prometheus_client.REGISTRY
    async with aiofins.Pool(hooks=metrics.hooks) as pool:
        metrics.watch_pool(pool)
        ...                                      # prometheus_client.generate_latest() scrapes
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import fields
from typing import TYPE_CHECKING

from prometheus_client import REGISTRY, CollectorRegistry, Histogram
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.registry import Collector

from .hooks import OTHER_FAMILY, EventHooks, ResponseReceived, command_family
from .pool import EndpointStats
from .session.response import SESSION_COUNTERS

if TYPE_CHECKING:
    from .client import Client
    from .poller import Poller
    from .pool import Pool

__all__ = ["DEFAULT_BUCKETS", "FinsMetrics", "command_family"]

#: Histogram buckets in seconds: a CPU unit answers in 1-50 ms, a busy or routed one slower.
DEFAULT_BUCKETS = (0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0)

#: The label value of endpoints past ``max_endpoints``.
OTHER = OTHER_FAMILY

#: EndpointStats fields exported as gauges (they describe the sessions open now).
_POOL_GAUGES = {
    "sessions": "Sessions open to the endpoint",
    "in_use": "Sessions lent to borrowers now",
    "in_flight": "Requests awaiting a reply",
    "backoff": "Seconds drawn as backoff after the endpoint's last failure",
}


class FinsMetrics(Collector):
    """A Prometheus collector of aiofins' counters and request latencies.

    ``registry`` is where it registers (default: ``prometheus_client.REGISTRY``; ``None``:
    nowhere, register it yourself). ``namespace`` prefixes every metric name.

    A scrape reads the watched pools' and pollers' state: scrape from the event loop's
    thread (an async web route, as in the FastAPI recipe), not from the thread of
    ``prometheus_client.start_http_server``, while they run.
    """

    def __init__(
        self,
        *,
        registry: CollectorRegistry | None = REGISTRY,
        namespace: str = "aiofins",
        buckets: Sequence[float] = DEFAULT_BUCKETS,
        max_endpoints: int = 256,
    ) -> None:
        self.namespace = namespace
        self.max_endpoints = max_endpoints
        self._pools: list[Pool] = []
        self._clients: list[Client] = []
        self._pollers: list[Poller] = []
        self._endpoints: set[str] = set()
        self._children: dict[tuple[str, int], Histogram] = {}
        self._latency = Histogram(
            f"{namespace}_request_duration_seconds",
            "Seconds from a request's first transmission to its reply",
            ("endpoint", "family"),
            registry=None,
            buckets=tuple(buckets),
        )
        #: Give these to ``Pool(hooks=...)`` or ``connect(..., hooks=...)``: they feed the
        #: latency histogram.
        self.hooks = EventHooks(response_received=[self.observe])
        if registry is not None:
            registry.register(self)

    def watch_pool(self, pool: Pool) -> None:
        """Export ``pool.stats()`` at each scrape, per endpoint."""
        self._pools.append(pool)

    def watch_client(self, client: Client) -> None:
        """Export the counters of one client's session (a client from ``connect()``)."""
        self._clients.append(client)

    def watch_poller(self, poller: Poller) -> None:
        """Export the counters of every scan group of ``poller``."""
        self._pollers.append(poller)

    def forget(self, watched: Pool | Client | Poller) -> None:
        """Stop exporting something watched (e.g. once it is closed)."""
        for watching in (self._pools, self._clients, self._pollers):
            if watched in watching:
                watching.remove(watched)  # type: ignore[arg-type]

    def _endpoint(self, endpoint: str) -> str:
        """``endpoint`` as a label value: the first ``max_endpoints`` seen, then ``other``."""
        if endpoint in self._endpoints:
            return endpoint
        if len(self._endpoints) < self.max_endpoints:
            self._endpoints.add(endpoint)
            return endpoint
        return OTHER

    def observe(self, event: ResponseReceived) -> None:
        """Record one reply's round trip (the ``response_received`` hook)."""
        key = (self._endpoint(event.endpoint), event.command_code >> 8)
        child = self._children.get(key)
        if child is None:
            child = self._children[key] = self._latency.labels(
                key[0], command_family(event.command_code)
            )
        child.observe(event.elapsed)

    def describe(self) -> Iterable[Metric]:
        """Nothing: the metrics are collected at each scrape (labels vary)."""
        return ()

    def collect(self) -> Iterable[Metric]:
        """The metrics now (called by the registry at each scrape)."""
        yield from self._latency.collect()
        yield from self._collect_pools()
        yield from self._collect_clients()
        yield from self._collect_pollers()

    def _name(self, name: str) -> str:
        return f"{self.namespace}_{name}"

    def _collect_pools(self) -> Iterator[Metric]:
        """The pools' counters, then gauges, per endpoint: one family at a time (a scrape
        rendered in steps, as the gateway's, holds the loop for one family, not all)."""
        if not self._pools:
            return
        stats = [(key, s) for pool in list(self._pools) for key, s in pool.stats().items()]
        names = [f.name for f in fields(EndpointStats) if not f.name.startswith("latency")]
        for name in names:
            if name not in _POOL_GAUGES:
                counter = CounterMetricFamily(
                    self._name(f"pool_{name}"),
                    f"Pool counter {name} per endpoint (see EndpointStats)",
                    labels=("endpoint",),
                )
                for key, each in stats:
                    counter.add_metric((key,), getattr(each, name))
                yield counter
        for name in names:
            if name in _POOL_GAUGES:
                gauge = GaugeMetricFamily(
                    self._name(f"pool_{name}"), _POOL_GAUGES[name], labels=("endpoint",)
                )
                for key, each in stats:
                    gauge.add_metric((key,), getattr(each, name))
                yield gauge

    def _collect_clients(self) -> Iterator[Metric]:
        if not self._clients:
            return
        counters = {
            name: CounterMetricFamily(
                self._name(f"session_{name}"),
                f"Session counter {name} (see SessionStats)",
                labels=("endpoint",),
            )
            for name in SESSION_COUNTERS
        }
        in_flight = GaugeMetricFamily(
            self._name("session_in_flight"), "Requests awaiting a reply", labels=("endpoint",)
        )
        for client in self._clients:
            session = client.session
            where = session.transport.description
            for name, family in counters.items():
                family.add_metric((where,), getattr(session.stats, name))
            in_flight.add_metric((where,), session.stats.in_flight)
        yield from counters.values()
        yield in_flight

    def _collect_pollers(self) -> Iterator[Metric]:
        if not self._pollers:
            return
        labels = ("group", "endpoint")
        groups = [group for poller in list(self._pollers) for group in poller.groups.values()]
        families: list[tuple[str, str, type[CounterMetricFamily | GaugeMetricFamily], str]] = [
            ("poller_scans", "Scans run", CounterMetricFamily, "scans"),
            ("poller_scan_errors", "Scans that failed", CounterMetricFamily, "errors"),
            (
                "poller_missed_scans",
                "Scan times skipped (late scans)",
                CounterMetricFamily,
                "missed",
            ),
            (
                "poller_last_scan_seconds",
                "Seconds the last scan took",
                GaugeMetricFamily,
                "last_duration",
            ),
        ]
        for name, doc, family, attribute in families:  # one family at a time
            metric = family(self._name(name), doc, labels=labels)
            for group in groups:
                metric.add_metric((group.name, group.url), getattr(group, attribute))
            yield metric
