"""The Prometheus collector: a real ``prometheus_client`` registry scraped as text after
loopback runs against the simulator (faults injected)."""

from __future__ import annotations

import pytest
from prometheus_client import CollectorRegistry, generate_latest
from prometheus_client.parser import text_string_to_metric_families

import aiofins
from aiofins.hooks import ResponseReceived
from aiofins.metrics import FinsMetrics, command_family
from aiofins.poller import Poller
from aiofins.protocol.header import FinsAddress
from aiofins.simulator.faults import Delay, FaultPlan, FaultRule
from aiofins.simulator.plc import VirtualPLC
from aiofins.simulator.runner import run_simulator

from .virtual_time import on_virtual_time

PLC = FinsAddress(0, 1, 0)


def scrape(registry: CollectorRegistry) -> dict[tuple[str, tuple[tuple[str, str], ...]], float]:
    """Every sample of the registry's text exposition: (name, sorted labels) -> value."""
    text = generate_latest(registry).decode()
    return {
        (sample.name, tuple(sorted(sample.labels.items()))): sample.value
        for family in text_string_to_metric_families(text)
        for sample in family.samples
    }


def test_command_families_are_named_after_the_mrc() -> None:
    assert command_family(0x0101) == "memory"
    assert command_family(0x0601) == "status"
    assert command_family(0x2801) == "gateway"
    assert command_family(0x4201) == "other"


def test_endpoint_labels_are_bounded() -> None:
    registry = CollectorRegistry()
    metrics = FinsMetrics(registry=registry, max_endpoints=2)
    for n in range(5):
        for code in (0x0101, 0x0102, 0x0601):
            metrics.observe(ResponseReceived(f"udp://10.0.0.{n}:9600", PLC, 1, code, 0, 0.003, 1))
    samples = scrape(registry)
    counts = {
        labels: value
        for (name, labels), value in samples.items()
        if name == "aiofins_request_duration_seconds_count"
    }
    assert counts == {
        (("endpoint", "udp://10.0.0.0:9600"), ("family", "memory")): 2.0,
        (("endpoint", "udp://10.0.0.0:9600"), ("family", "status")): 1.0,
        (("endpoint", "udp://10.0.0.1:9600"), ("family", "memory")): 2.0,
        (("endpoint", "udp://10.0.0.1:9600"), ("family", "status")): 1.0,
        (("endpoint", "other"), ("family", "memory")): 6.0,
        (("endpoint", "other"), ("family", "status")): 3.0,
    }
    le = (("endpoint", "other"), ("family", "status"), ("le", "0.005"))
    assert samples["aiofins_request_duration_seconds_bucket", le] == 3.0
    le = (("endpoint", "other"), ("family", "status"), ("le", "0.002"))
    assert samples["aiofins_request_duration_seconds_bucket", le] == 0.0


@on_virtual_time
async def test_pool_poller_and_latency_scraped_as_text() -> None:
    """On virtual time (asyncio, trio; uvloop's clock cannot be virtual): the 0.2 s timeout
    ends only the read the PLC ignores, never a loaded machine's slow answer; every answer
    takes 10 ms of the PLC's (a latency to measure)."""
    registry = CollectorRegistry()
    metrics = FinsMetrics(registry=registry)
    async with run_simulator(VirtualPLC(), udp=("127.0.0.1", 0), faults=FaultPlan(seed=5)) as sim:
        endpoint = f"udp://127.0.0.1:{sim.udp_port}"
        url = f"{endpoint}?dest=0.1.0"
        async with (
            aiofins.Pool(hooks=metrics.hooks, timeout=0.2, retries=1) as pool,
            Poller(pool) as poller,
        ):
            metrics.watch_pool(pool)
            metrics.watch_poller(poller)
            sim.plan.rule = FaultRule(delay=Delay(0.01, 0.01))
            async with pool.client(url) as plc:
                for _ in range(3):
                    await plc.read("D0", 4)
                await plc.cpu_unit_status_read()
                sim.plan.rule = FaultRule(drop_request=1.0)
                with pytest.raises(aiofins.FinsTimeout):
                    await plc.read("D0", 1)
                sim.plan.rule = FaultRule(delay=Delay(0.01, 0.01))
            poller.add_group("g", url, {"t": "D0"}, interval=0.05)
            snapshots = aiter(poller)
            await anext(snapshots)
            await anext(snapshots)
            samples = scrape(registry)
            last_scan = poller.groups["g"].last_duration
            ((key, stats),) = pool.stats().items()
    memory = (("endpoint", endpoint), ("family", "memory"))
    status = (("endpoint", endpoint), ("family", "status"))
    reads = samples["aiofins_request_duration_seconds_count", memory]
    assert reads >= 5  # three reads and two scans, at least (a health check may add one)
    assert samples["aiofins_request_duration_seconds_count", status] >= 1
    assert 0 < samples["aiofins_request_duration_seconds_sum", memory] < reads
    assert samples["aiofins_request_duration_seconds_bucket", (*memory, ("le", "+Inf"))] == reads
    pool_labels = (("endpoint", key),)
    completed = samples["aiofins_pool_completed_total", pool_labels]
    assert completed == reads + samples["aiofins_request_duration_seconds_count", status]
    assert samples["aiofins_pool_timeouts_total", pool_labels] == stats.timeouts >= 1
    assert samples["aiofins_pool_retries_total", pool_labels] == stats.retries >= 1
    assert samples["aiofins_pool_sessions", pool_labels] == stats.sessions == 1
    group = (("endpoint", url), ("group", "g"))
    assert samples["aiofins_poller_scans_total", group] >= 2
    assert samples["aiofins_poller_scan_errors_total", group] == 0
    assert samples["aiofins_poller_missed_scans_total", group] == 0
    assert samples["aiofins_poller_last_scan_seconds", group] == last_scan


@pytest.mark.anyio
async def test_a_client_from_connect_is_watched(anyio_backend: object) -> None:
    registry = CollectorRegistry()
    metrics = FinsMetrics(registry=registry, namespace="plant")
    async with run_simulator(VirtualPLC(), udp=("127.0.0.1", 0)) as sim:
        endpoint = f"udp://127.0.0.1:{sim.udp_port}"
        async with aiofins.connect(endpoint, dest="0.1.0", hooks=metrics.hooks) as plc:
            metrics.watch_client(plc)
            await plc.write("D10", [1, 2])
            await plc.read("D10", 2)
            samples = scrape(registry)
            metrics.forget(plc)
        assert not any(name.startswith("plant_session") for name, _ in scrape(registry))
    labels = (("endpoint", endpoint),)
    assert samples["plant_session_completed_total", labels] == 2
    assert samples["plant_session_timeouts_total", labels] == 0
    assert samples["plant_session_in_flight", labels] == 0
    memory = (("endpoint", endpoint), ("family", "memory"))
    assert samples["plant_request_duration_seconds_count", memory] == 2
