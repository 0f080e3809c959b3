"""The examples run: the polling daemon (always) and the FastAPI app (when FastAPI is here)."""

from __future__ import annotations

import importlib.util
import json
import signal
import socket
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[2]


def test_polling_daemon_prints_changes_of_two_plcs() -> None:
    result = subprocess.run(
        [sys.executable, str(ROOT / "examples" / "polling_daemon.py"), "--duration=1.0"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    seen = f"stdout:\n{result.stdout}\nstderr:\n{result.stderr}"
    assert result.returncode == 0, seen
    lines = [json.loads(line) for line in result.stdout.splitlines()]
    assert {line["plc"] for line in lines} == {"plc0", "plc1"}, seen
    assert lines[0]["changed"]["temperature"] == [0.0, "good"], seen


def fastapi_client() -> Any:
    """A FastAPI test client of examples/fastapi_app.py (skips without FastAPI)."""
    pytest.importorskip("fastapi", reason="FastAPI is optional (pip install fastapi httpx2)")
    if importlib.util.find_spec("httpx2") is None:
        pytest.importorskip("httpx", reason="the FastAPI test client needs httpx2 (or httpx)")
    from fastapi.testclient import TestClient

    sys.path.insert(0, str(ROOT))
    try:
        from examples.fastapi_app import app
    finally:
        sys.path.remove(str(ROOT))
    return TestClient(app)


def test_fastapi_app_serves_reads_and_writes() -> None:
    with fastapi_client() as http:
        assert http.put("/plc/D100", json=[1, 2, 3]).json() == {"written": 3}
        assert http.get("/plc/D100", params={"count": 3}).json()["values"] == [1, 2, 3]
        assert http.get("/plc/D40000").status_code == 400
        assert http.get("/status").json()["mode"] == "PROGRAM"
        assert http.get("/plc/D100/value", params={"type": "uint32"}).json()["value"] == 0x20001


def test_fastapi_app_exposes_metrics() -> None:
    pytest.importorskip("prometheus_client")
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
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as silent:
        silent.bind(("127.0.0.1", 0))
        monkeypatch.setenv("AIOFINS_PLC", f"udp://127.0.0.1:{silent.getsockname()[1]}?timeout=0.1")
        with fastapi_client() as http:
            reply = http.get("/status")
            assert reply.status_code == 504 and "no response to command 0601" in reply.text


def test_fastapi_app_serves_configured_plcs_only(monkeypatch: pytest.MonkeyPatch) -> None:
    """A host named by the request must be in the configuration: the documented pattern
    built URLs from request paths, and any caller could make the server open sockets."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as silent:
        silent.bind(("127.0.0.2", 0))
        other = f"udp://127.0.0.2:{silent.getsockname()[1]}?timeout=0.1"
        monkeypatch.setenv("AIOFINS_PLCS", other)
        with fastapi_client() as http:
            assert http.get("/plc/D0", params={"plc": "127.0.0.1"}).json()["values"] == [0]
            refused = http.get("/plc/D0", params={"plc": "10.1.2.3"})
            assert refused.status_code == 404
            assert refused.json() == {"detail": "PLC '10.1.2.3' is not configured"}
            assert http.put("/plc/D0", params={"plc": "127.0.0.9"}, json=[1]).status_code == 404
            assert http.get("/status", params={"plc": "127.0.0.2"}).status_code == 504
            stats = http.get("/stats").json()
            assert len(stats) == 2 and not any("10.1.2.3" in key for key in stats)


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_polling_daemon_stops_cleanly_on_a_signal(signum: signal.Signals) -> None:
    """As systemd, Docker or Ctrl-C stop it: exit code 0, no traceback."""
    proc = subprocess.Popen(
        [sys.executable, str(ROOT / "examples" / "polling_daemon.py")],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None
        first = json.loads(proc.stdout.readline())  # polling has started
        assert first["plc"] in ("plc0", "plc1")
        proc.send_signal(signum)
        _, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
        proc.wait()
    assert proc.returncode == 0, err
    assert f"stopping on {signum.name}" in err and "Traceback" not in err, err
