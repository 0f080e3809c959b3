"""A FastAPI backend sharing one aiofins.Pool across requests.

    pip install fastapi uvicorn
    AIOFINS_PLC=udp://192.168.250.1 uvicorn examples.fastapi_app:app

Without ``AIOFINS_PLC`` the app starts an embedded virtual PLC in its lifespan.

    GET  /plc/D100?count=10            -> {"address": "D100", "values": [...]}
    GET  /plc/D200/value?type=float32  -> {"address": "D200", "value": 21.5}
    PUT  /plc/D100  [1, 2, 3]          -> {"written": 3}
    GET  /status                       -> mode, error code, message
    GET  /stats                        -> the pool's per-endpoint counters
"""

from __future__ import annotations

import os
from collections.abc import AsyncIterator
from contextlib import AsyncExitStack, asynccontextmanager
from dataclasses import asdict
from typing import Any

from fastapi import FastAPI, HTTPException

import aiofins
from aiofins.simulator import VirtualPLC, run_simulator

STATE: dict[str, Any] = {}


@asynccontextmanager
async def lifespan(app: FastAPI) -> AsyncIterator[None]:
    async with AsyncExitStack() as stack:
        url = os.environ.get("AIOFINS_PLC")
        if not url:
            sim = await stack.enter_async_context(run_simulator(VirtualPLC(), udp=("127.0.0.1", 0)))
            url = f"udp://127.0.0.1:{sim.udp_port}"
        STATE["url"] = url
        STATE["pool"] = await stack.enter_async_context(aiofins.Pool(timeout=1.0))
        yield


app = FastAPI(lifespan=lifespan)


def _http_error(exc: aiofins.FinsError) -> HTTPException:
    if isinstance(exc, (aiofins.AddressError, aiofins.CommandError)):
        return HTTPException(400, str(exc))
    if isinstance(exc, aiofins.EndCodeError):
        return HTTPException(409, str(exc))
    return HTTPException(504, str(exc))


@asynccontextmanager
async def _plc() -> AsyncIterator[aiofins.Client]:
    """The PLC's client, lent by the pool; FINS errors leave the block as HTTP errors."""
    try:
        async with STATE["pool"].client(STATE["url"]) as plc:
            yield plc
    except aiofins.FinsError as exc:
        raise _http_error(exc) from exc


@app.get("/plc/{address}")
async def read(address: str, count: int = 1) -> dict[str, Any]:
    async with _plc() as plc:
        return {"address": address, "values": await plc.read(address, count)}


@app.get("/plc/{address}/value")
async def read_value(address: str, type: str = "uint16") -> dict[str, Any]:
    async with _plc() as plc:
        return {"address": address, "value": await plc.read_value(address, type)}


@app.put("/plc/{address}")
async def write(address: str, values: list[int]) -> dict[str, Any]:
    async with _plc() as plc:
        await plc.write(address, values)
        return {"written": len(values)}


@app.get("/status")
async def status() -> dict[str, Any]:
    async with _plc() as plc:
        s = await plc.cpu_unit_status_read()
        return {"mode": s.mode.name, "error_code": s.error_code, "message": s.error_message}


@app.get("/stats")
async def stats() -> dict[str, Any]:
    return {key: asdict(value) for key, value in STATE["pool"].stats().items()}
