"""A FastAPI service: read and write PLC memory over HTTP, one aiofins.Pool for all requests.

    pip install fastapi uvicorn prometheus_client
    uvicorn examples.fastapi_app:app                          # the PLC at udp://127.0.0.1
    PLC_URL=udp://192.168.250.1 uvicorn examples.fastapi_app:app --host 0.0.0.0

``PLC_URL`` is the PLC the routes talk to (default ``udp://127.0.0.1``, where
``aiofins simulate`` answers). The PLCs a request may name (``?plc=HOST``) are configured,
never taken from the request: ``PLC_URLS=udp://192.168.250.2,udp://192.168.250.3`` adds them
to ``PLC_URL``, the default. Any other host is refused (404) before the pool opens anything:
a route that built URLs from request input would let any caller make the server open sockets
to hosts of their choosing. FINS errors become HTTP errors: bad input 400, the PLC refusing
(an end code) 409, no answer 504.

    GET  /plc/D100?count=10            -> {"address": "D100", "values": [...]}
    GET  /plc/D100?plc=192.168.250.2   -> the same, from another configured PLC
    GET  /plc/D200/value?type=float32  -> {"address": "D200", "value": 21.5}
    PUT  /plc/D100  [1, 2, 3]          -> {"written": 3}
    GET  /status                       -> mode, error code, message
    GET  /stats                        -> the pool's per-endpoint counters
    GET  /metrics                      -> the same and request latencies, for Prometheus
"""

from __future__ import annotations

import os
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import asdict
from typing import Any

from fastapi import FastAPI, HTTPException, Response
from prometheus_client import CONTENT_TYPE_LATEST, CollectorRegistry, generate_latest

import aiofins
from aiofins.endpoint import parse_endpoint
from aiofins.metrics import FinsMetrics

STATE: dict[str, Any] = {}


@asynccontextmanager
async def lifespan(app: FastAPI) -> AsyncIterator[None]:
    url = os.environ.get("PLC_URL", "udp://127.0.0.1")
    STATE["url"] = url
    extra = [u.strip() for u in os.environ.get("PLC_URLS", "").split(",") if u.strip()]
    # The allowlist: host (or serial device) -> URL, from the configuration only.
    endpoints = {u: parse_endpoint(u) for u in [url, *extra]}
    STATE["plcs"] = {e.host or e.device: u for u, e in endpoints.items()}
    # Metrics: the pool's counters at each scrape, latencies from its hooks. A registry
    # of the app's own (prometheus_client.REGISTRY also works, once per process).
    metrics = FinsMetrics(registry=None)
    STATE["registry"] = CollectorRegistry()
    STATE["registry"].register(metrics)
    async with aiofins.Pool(timeout=1.0, hooks=metrics.hooks) as pool:
        STATE["pool"] = pool
        metrics.watch_pool(pool)
        yield


app = FastAPI(lifespan=lifespan)


def _http_error(exc: aiofins.FinsError) -> HTTPException:
    if isinstance(exc, (aiofins.AddressError, aiofins.CommandError)):
        return HTTPException(400, str(exc))
    if isinstance(exc, aiofins.EndCodeError):
        return HTTPException(409, str(exc))
    return HTTPException(504, str(exc))


def _url(host: str | None) -> str:
    """The configured URL of ``host`` (the default PLC without one); 404 for any other."""
    if host is None:
        return str(STATE["url"])
    url = STATE["plcs"].get(host)
    if url is None:
        raise HTTPException(404, f"PLC {host!r} is not configured")
    return str(url)


@asynccontextmanager
async def _plc(host: str | None = None) -> AsyncIterator[aiofins.Client]:
    """The client of a configured PLC, lent by the pool; FINS errors leave the block as
    HTTP errors."""
    url = _url(host)
    try:
        async with STATE["pool"].client(url) as plc:
            yield plc
    except aiofins.FinsError as exc:
        raise _http_error(exc) from exc


@app.get("/plc/{address}")
async def read(address: str, count: int = 1, plc: str | None = None) -> dict[str, Any]:
    async with _plc(plc) as client:
        return {"address": address, "values": await client.read(address, count)}


@app.get("/plc/{address}/value")
async def read_value(address: str, type: str = "uint16", plc: str | None = None) -> dict[str, Any]:
    async with _plc(plc) as client:
        return {"address": address, "value": await client.read_value(address, type)}


@app.put("/plc/{address}")
async def write(address: str, values: list[int], plc: str | None = None) -> dict[str, Any]:
    async with _plc(plc) as client:
        await client.write(address, values)
        return {"written": len(values)}


@app.get("/status")
async def status(plc: str | None = None) -> dict[str, Any]:
    async with _plc(plc) as client:
        s = await client.cpu_unit_status_read()
        return {"mode": s.mode.name, "error_code": s.error_code, "message": s.error_message}


@app.get("/stats")
async def stats() -> dict[str, Any]:
    return {key: asdict(value) for key, value in STATE["pool"].stats().items()}


@app.get("/metrics")
async def metrics() -> Response:
    return Response(generate_latest(STATE["registry"]), media_type=CONTENT_TYPE_LATEST)
