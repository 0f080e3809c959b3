"""OpenTelemetry spans per request, read from the SDK's in-memory exporter after loopback
runs against the simulator (drops and error end codes injected)."""

from __future__ import annotations

from collections.abc import Iterator

import anyio
import pytest
from opentelemetry.sdk.trace import ReadableSpan, TracerProvider
from opentelemetry.sdk.trace.export import SimpleSpanProcessor
from opentelemetry.sdk.trace.export.in_memory_span_exporter import InMemorySpanExporter
from opentelemetry.trace import SpanKind, StatusCode

import aiofins
from aiofins.simulator.faults import FaultPlan, FaultRule
from aiofins.simulator.plc import VirtualPLC
from aiofins.simulator.runner import run_simulator
from aiofins.tracing import FinsTracing

pytestmark = pytest.mark.anyio


@pytest.fixture
def exporter() -> Iterator[InMemorySpanExporter]:
    exporter = InMemorySpanExporter()
    yield exporter
    exporter.clear()


def provider_for(exporter: InMemorySpanExporter) -> TracerProvider:
    provider = TracerProvider()
    provider.add_span_processor(SimpleSpanProcessor(exporter))
    return provider


def fins(span: ReadableSpan) -> dict[str, object]:
    return {k: v for k, v in (span.attributes or {}).items() if k.startswith("fins.")}


async def test_a_span_per_request_with_fins_attributes(exporter: InMemorySpanExporter) -> None:
    provider = provider_for(exporter)
    tracing = FinsTracing(provider)
    tracer = provider.get_tracer("app")
    async with run_simulator(VirtualPLC(), udp=("127.0.0.1", 0), faults=FaultPlan(seed=2)) as sim:
        endpoint = f"udp://127.0.0.1:{sim.udp_port}"
        async with aiofins.connect(
            endpoint, dest="0.1.0", hooks=tracing.hooks, timeout=0.3, retries=1
        ) as plc:
            with tracer.start_as_current_span("poll once") as parent:
                assert await plc.read("D0", 2) == [0, 0]
            sim.plan.rule = FaultRule(end_code=0x1103)
            with pytest.raises(aiofins.FinsError):
                await plc.read("D0", 1)
            sim.plan.rule = FaultRule(drop_request=1.0)
            with pytest.raises(aiofins.FinsTimeout):
                await plc.read("D0", 1)
    spans = [s for s in exporter.get_finished_spans() if s.name.startswith("FINS")]
    read, refused, lost = spans
    assert read.name == "FINS 0101 memory" and read.kind is SpanKind.CLIENT
    assert read.parent is not None
    assert read.parent.span_id == parent.get_span_context().span_id
    attributes = read.attributes or {}
    sid, retries = attributes["fins.sid"], attributes["fins.retries"]
    assert retries in (0, 1)  # 1 if the machine is so loaded that the reply was late
    assert fins(read) == {
        "fins.endpoint": endpoint,
        "fins.dest": "0.1.0",
        "fins.command_code": "0101",
        "fins.command_family": "memory",
        "fins.sid": sid,
        "fins.retries": retries,
        "fins.end_code": "0000",
    }
    assert read.status.status_code is StatusCode.UNSET
    assert fins(refused)["fins.end_code"] == "1103"
    assert refused.status.status_code is StatusCode.ERROR
    assert refused.status.description == "end code 1103"
    assert fins(lost)["fins.retries"] == 1 and "fins.end_code" not in fins(lost)
    assert lost.status.status_code is StatusCode.ERROR
    assert lost.status.description == "no reply after 2 transmissions"
    (event,) = lost.events
    assert event.name == "retransmission" and (event.attributes or {})["fins.attempt"] == 2
    assert read.end_time is not None and read.start_time is not None
    assert read.end_time > read.start_time


async def test_a_cancelled_request_s_span_ends_when_its_sid_is_reused(
    exporter: InMemorySpanExporter,
) -> None:
    tracing = FinsTracing(provider_for(exporter))
    async with (
        run_simulator(VirtualPLC(), udp=("127.0.0.1", 0), faults=FaultPlan(seed=2)) as sim,
        aiofins.connect(
            f"udp://127.0.0.1:{sim.udp_port}", dest="0.1.0", hooks=tracing.hooks, timeout=5
        ) as plc,
    ):
        # The cancelled request's SID is not quarantined at all: it comes round again after
        # the 255 others, however fast the reads go (a quarantine of 0.05 s made the count
        # depend on the machine's speed: 767 spans on a quiet one, issue #22).
        plc.session.min_quarantine, plc.session.quarantine_factor = 0.0, 0.0
        sim.plan.rule = FaultRule(drop_request=1.0)
        with anyio.move_on_after(0.05):
            await plc.read("D0", 1)
        sim.plan.rule = FaultRule()
        assert not exporter.get_finished_spans() and len(tracing._open) == 1
        # Until the SID comes round again: the 256th read after it takes it.
        reads = 0
        while tracing._open:
            await plc.read("D0", 1)
            reads += 1
        assert reads == 256
    spans = exporter.get_finished_spans()
    cancelled = [s for s in spans if fins(s).get("fins.cancelled")]
    assert len(cancelled) == 1 and "fins.end_code" not in fins(cancelled[0])
    assert len(spans) == 1 + 256  # a span per read, all ended
