"""The gateway's /metrics: prometheus_client's text byte for byte, rendered in steps that let
the event loop run (a 1,000-PLC scrape held the loop for seconds under load and made scans
miss), scrapes during a render sharing it."""

from __future__ import annotations

import math

import anyio
import anyio.lowlevel
import httpx
import pytest
from hypothesis import given
from hypothesis import strategies as st
from prometheus_client import generate_latest
from prometheus_client.core import (
    CounterMetricFamily,
    GaugeMetricFamily,
    HistogramMetricFamily,
    InfoMetricFamily,
    Metric,
    SummaryMetricFamily,
)
from prometheus_client.registry import Collector

from aiofins.gateway import Gateway
from aiofins.gateway import metrics as gateway_metrics
from aiofins.gateway.config import GatewayConfig, parse_config
from aiofins.gateway.http import HttpServer
from aiofins.gateway.metrics import Exposition, exposition

from .conftest import free_port

pytestmark = pytest.mark.anyio


class Families(Collector):
    def __init__(self, metrics: list[Metric]) -> None:
        self.metrics = metrics
        self.collects = 0

    def collect(self) -> list[Metric]:
        self.collects += 1
        return self.metrics


label_text = st.text(st.sampled_from('ab_:/.9 é€\U0001f600\\"\n{}='), max_size=8)
values = (
    st.integers(-(10**20), 10**20)
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.sampled_from([0, 999_999, 1_000_000, -999_999, -1_000_000, 1e6, 1234567.0, 1e22])
)


@st.composite
def families(draw: st.DrawFn) -> Metric:
    kind = draw(st.sampled_from(["counter", "gauge", "histogram", "info", "summary"]))
    name = draw(st.sampled_from(["a", "x_y", "aiofins_gateway_scans", "m:sub", "c_total"]))
    doc = draw(label_text)
    names = draw(st.lists(st.sampled_from(["plc", "group", "endpoint", "z"]), unique=True))
    rows = draw(
        st.lists(
            st.tuples(st.lists(label_text, min_size=len(names), max_size=len(names)), values),
            max_size=5,
        )
    )
    metric: Metric
    if kind == "counter":
        metric = CounterMetricFamily(name, doc, labels=names)
        for labels, value in rows:
            created = draw(st.none() | st.floats(0, 2e9))
            metric.add_metric(labels, value, created=created)
    elif kind == "gauge":
        metric = GaugeMetricFamily(name, doc, labels=names)
        for labels, value in rows:
            metric.add_metric(labels, value, timestamp=draw(st.none() | st.floats(0, 2e9)))
    elif kind == "histogram":
        metric = HistogramMetricFamily(name, doc, labels=names)
        for labels, value in rows:
            counts = draw(st.lists(st.integers(0, 10**7), min_size=1, max_size=4))
            bounds = [
                *map(
                    repr,
                    sorted(
                        draw(
                            st.sets(
                                st.floats(0.001, 1e7),
                                min_size=len(counts) - 1,
                                max_size=len(counts) - 1,
                            )
                        )
                    ),
                ),
                "+Inf",
            ]
            metric.add_metric(labels, list(zip(bounds, counts, strict=True)), value)
    elif kind == "info":
        metric = InfoMetricFamily(name, doc, labels=names)
        for labels, _ in rows:
            metric.add_metric(labels, {"version": draw(label_text)})
    else:
        metric = SummaryMetricFamily(name, doc, labels=names)
        for labels, value in rows:
            metric.add_metric(labels, count_value=draw(st.integers(0, 99)), sum_value=value)
    return metric


@given(st.lists(families(), max_size=4))
def test_the_exposition_is_prometheus_clients_text_byte_for_byte(metrics: list[Metric]) -> None:
    collector = Families(metrics)
    assert exposition(collector) == generate_latest(collector)
    kept = Exposition()  # label strings kept from the first rendering serve the second
    for _ in range(2):
        text = "".join(t for t, _ in kept.families(metrics)).encode()
        assert text == generate_latest(collector)


def gateway_config(plcs: int) -> GatewayConfig:
    table = "".join(
        f'[[plcs]]\nname = "p{i}"\nurl = "udp://127.0.0.1:{9600 + i}"\n' for i in range(plcs)
    )
    return parse_config(
        f"""
[gateway]
name = "m"
[mqtt]
port = {free_port()}
[http]
enabled = false
[[groups]]
name = "g"
tags = {{ x = "D0" }}
[[groups]]
name = "h"
tags = {{ y = "D1:float32" }}
{table}""",
        "m.toml",
    )


@pytest.fixture
def anyio_backend() -> str:
    return "asyncio"  # the gateway runs on asyncio


async def test_the_gateways_metrics_are_prometheus_clients_text() -> None:
    gateway = Gateway(gateway_config(3))
    gateway.metrics.latency.observe(0.003)
    gateway.write_counts["written"] = 2
    expected = generate_latest(gateway.metrics.registry)
    assert gateway.metrics.render() == expected
    assert await gateway.metrics.scrape() == expected
    assert b'aiofins_gateway_scans_total{group="h",plc="p2"} 0.0\n' in expected
    assert b"aiofins_gateway_loop_lag_seconds_count 0.0\n" in expected


async def test_a_scrape_lets_the_loop_run_between_metric_families(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    gateway = Gateway(gateway_config(4))
    families = [m for m in gateway.metrics.registry.collect() if m.samples]
    monkeypatch.setattr(gateway_metrics, "LINES_PER_STEP", 8)
    big = sum(1 for m in families if len(m.samples) >= 8)  # 8 routes: a step each
    turns = 0
    done = False

    async def other_work() -> None:
        nonlocal turns
        while not done:
            turns += 1
            await anyio.lowlevel.checkpoint()

    async with anyio.create_task_group() as tg:
        tg.start_soon(other_work)
        await anyio.lowlevel.checkpoint()
        before = turns
        body = await gateway.metrics.scrape()
        during = turns - before
        done = True
    assert body == generate_latest(gateway.metrics.registry)
    assert big >= 8 and during >= big  # the loop ran between the families


async def test_scrapes_during_a_render_get_its_text(monkeypatch: pytest.MonkeyPatch) -> None:
    gateway = Gateway(gateway_config(2))
    counting = Families([GaugeMetricFamily("extra", "one more", value=1.0)])
    gateway.metrics.registry.register(counting)
    monkeypatch.setattr(gateway_metrics, "LINES_PER_STEP", 1)
    bodies: list[bytes] = []

    async def scrape() -> None:
        bodies.append(await gateway.metrics.scrape())

    async with anyio.create_task_group() as tg:
        for _ in range(3):
            tg.start_soon(scrape)
    assert counting.collects == 1  # one render for the three
    assert len(bodies) == 3 and bodies[0] is bodies[1] is bodies[2]
    assert bodies[0] == generate_latest(gateway.metrics.registry)
    assert counting.collects == 2
    await scrape()  # the next scrape renders anew
    assert counting.collects == 3 and bodies[3] == bodies[0]


async def test_the_time_to_make_an_answer_is_not_the_clients_idle_timeout() -> None:
    deadlines: list[float] = []

    async def slow() -> tuple[int, str, bytes]:
        deadlines.append(anyio.current_effective_deadline())
        return 200, "text/plain", b"made\n"

    server = HttpServer("127.0.0.1", 0, {"/slow": slow}, idle_timeout=5.0)
    async with anyio.create_task_group() as tg:
        await tg.start(server.serve)
        async with httpx.AsyncClient() as client:
            answer = await client.get(f"http://127.0.0.1:{server.port}/slow")
        tg.cancel_scope.cancel()
    assert answer.status_code == 200 and answer.text == "made\n"
    assert deadlines == [math.inf]  # no idle_timeout around the handler
