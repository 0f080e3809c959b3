"""examples/fastapi_app.py: served by uvicorn as its docstring says, and through FastAPI's
test client (the app's real lifespan and pool), against a virtual PLC at ``PLC_URL``."""

from __future__ import annotations

import json
import re
import socket
import subprocess
import sys
import urllib.error
import urllib.request
from collections.abc import Iterator
from typing import Any

import pytest

from aiofins.simulator import Mode, VirtualPLC
from tests.simulated import ROOT, RunningPLC, simulated_plc

pytest.importorskip("fastapi", reason="FastAPI is optional (pip install fastapi)")
pytest.importorskip("prometheus_client", reason="the app exports metrics (prometheus_client)")


@pytest.fixture
def sim(monkeypatch: pytest.MonkeyPatch) -> Iterator[RunningPLC]:
    """A virtual PLC at ``PLC_URL``."""
    with simulated_plc() as running:
        monkeypatch.setenv("PLC_URL", running.url)
        monkeypatch.delenv("PLC_URLS", raising=False)
        yield running


def fastapi_client() -> Any:
    """FastAPI's test client of the app: it runs the app's lifespan on a loop of its own."""
    from fastapi.testclient import TestClient

    sys.path.insert(0, str(ROOT))
    try:
        from examples.fastapi_app import app
    finally:
        sys.path.remove(str(ROOT))
    return TestClient(app)


def test_fastapi_app_serves_reads_and_writes(sim: RunningPLC) -> None:
    with fastapi_client() as http:
        assert http.put("/plc/D100", json=[1, 2, 3]).json() == {"written": 3}
        assert sim.call(sim.plc.read, "D100", 3) == [1, 2, 3]
        assert http.get("/plc/D100", params={"count": 3}).json()["values"] == [1, 2, 3]
        assert http.get("/plc/D40000").status_code == 400
        assert http.put("/plc/A0", json=[1]).status_code == 409  # A0 is read-only
        assert http.get("/status").json()["mode"] == "PROGRAM"
        assert http.get("/plc/D100/value", params={"type": "uint32"}).json()["value"] == 0x20001


def test_fastapi_app_exposes_metrics(sim: RunningPLC) -> None:
    with fastapi_client() as http:
        http.put("/plc/D100", json=[7])
        http.get("/plc/D100")
        reply = http.get("/metrics")
        assert reply.status_code == 200 and reply.headers["content-type"].startswith("text/plain")
        lines = reply.text.splitlines()
        endpoint = next(
            line.split('endpoint="')[1].split('"')[0]
            for line in lines
            if line.startswith("aiofins_pool_completed_total{")
        )
        assert f'aiofins_pool_completed_total{{endpoint="{endpoint}"}} 2.0' in lines
        memory = f'endpoint="{endpoint.split("?")[0]}",family="memory"'
        assert f"aiofins_request_duration_seconds_count{{{memory}}} 2.0" in lines


def test_fastapi_app_answers_504_when_the_plc_is_silent(monkeypatch: pytest.MonkeyPatch) -> None:
    """/status went through the pool without the app's error mapping: a 500 and a traceback."""
    with simulated_plc() as silent:
        silent.go_silent()
        monkeypatch.setenv("PLC_URL", f"{silent.url}?timeout=0.1")
        with fastapi_client() as http:
            reply = http.get("/status")
            assert reply.status_code == 504 and "no response to command 0601" in reply.text


def test_fastapi_app_serves_configured_plcs_only(
    sim: RunningPLC, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A host named by the request must be in the configuration: the documented pattern
    built URLs from request paths, and any caller could make the server open sockets."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as silent:
        silent.bind(("127.0.0.2", 0))
        other = f"udp://127.0.0.2:{silent.getsockname()[1]}?timeout=0.1"
        monkeypatch.setenv("PLC_URLS", other)
        with fastapi_client() as http:
            assert http.get("/plc/D0", params={"plc": "127.0.0.1"}).json()["values"] == [0]
            refused = http.get("/plc/D0", params={"plc": "10.1.2.3"})
            assert refused.status_code == 404
            assert refused.json() == {"detail": "PLC '10.1.2.3' is not configured"}
            assert http.put("/plc/D0", params={"plc": "127.0.0.9"}, json=[1]).status_code == 404
            assert http.get("/status", params={"plc": "127.0.0.2"}).status_code == 504
            stats = http.get("/stats").json()
            assert len(stats) == 2 and not any("10.1.2.3" in key for key in stats)


def _get(url: str) -> tuple[int, Any]:
    try:
        with urllib.request.urlopen(url) as reply:
            return reply.status, json.loads(reply.read())
    except urllib.error.HTTPError as error:
        return error.code, json.loads(error.read())


def test_uvicorn_serves_the_app_as_its_docstring_says() -> None:
    """``PLC_URL=... uvicorn examples.fastapi_app:app`` from the repository's root: a real
    server, a real PLC client, HTTP over a socket."""
    pytest.importorskip("uvicorn", reason="uvicorn serves the app (pip install uvicorn)")
    with simulated_plc(VirtualPLC(mode=Mode.RUN)) as sim:
        sim.call(sim.plc.write_value, "D200", 21.5, "float32")
        server = subprocess.Popen(
            [sys.executable, "-m", "uvicorn", "examples.fastapi_app:app", "--port", "0"],
            stderr=subprocess.PIPE,
            text=True,
            env=sim.env(),
            cwd=ROOT,
        )
        try:
            assert server.stderr is not None
            lines = []
            for line in server.stderr:  # uvicorn says where it listens once it does
                lines.append(line)
                match = re.search(r"Uvicorn running on (http://\S+)", line)
                if match:
                    base = match.group(1)
                    break
            else:
                raise AssertionError("".join(lines))
            assert _get(f"{base}/plc/D200/value?type=float32") == (
                200,
                {"address": "D200", "value": 21.5},
            )
            assert _get(f"{base}/status")[1]["mode"] == "RUN"
            status, body = _get(f"{base}/plc/Q0")
            assert status == 400 and "Q0" in body["detail"]
        finally:
            server.terminate()
            server.wait(timeout=60)
