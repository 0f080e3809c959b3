"""examples/polling_daemon.py: polls the PLCs it is given (``PLC_URL`` by default), prints
their changes as JSON lines and stops cleanly on SIGINT/SIGTERM."""

from __future__ import annotations

import json
import signal
import subprocess
import sys

import pytest

from aiofins.simulator import Mode, VirtualPLC
from tests.simulated import ROOT, run_python, simulated_plc

DAEMON = str(ROOT / "examples" / "polling_daemon.py")


def test_polling_daemon_prints_changes_of_two_plcs() -> None:
    with simulated_plc() as first, simulated_plc(VirtualPLC(mode=Mode.RUN)) as second:
        second.call(second.plc.write_value, "D100", 71.25, "float32")
        result = run_python([DAEMON, first.url, second.url, "--duration", "1"], first.env())
    seen = f"stdout:\n{result.stdout}\nstderr:\n{result.stderr}"
    assert result.returncode == 0, seen
    lines = [json.loads(line) for line in result.stdout.splitlines()]
    first_scans = {line["plc"]: line for line in reversed(lines)}
    assert set(first_scans) == {"plc0", "plc1"}, seen
    assert first_scans["plc0"]["changed"]["temperature"] == [0.0, "good"], seen
    assert first_scans["plc1"]["changed"]["temperature"] == [71.25, "good"], seen


def test_polling_daemon_polls_plc_url_without_arguments() -> None:
    with simulated_plc() as sim:
        result = run_python([DAEMON, "--duration", "0.5"], sim.env())
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout.splitlines()[0])["plc"] == "plc0"


def test_polling_daemon_prints_its_help() -> None:
    result = run_python([DAEMON, "--help"], {"PATH": "/usr/bin:/bin"})
    assert result.returncode == 0 and not result.stderr, result.stderr
    assert result.stdout.startswith("usage: polling_daemon.py [-h]")
    assert "--interval" in result.stdout and "$PLC_URL" in result.stdout


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_polling_daemon_stops_cleanly_on_a_signal(signum: signal.Signals) -> None:
    """As systemd, Docker or Ctrl-C stop it: exit code 0, no traceback."""
    with simulated_plc() as sim:
        proc = subprocess.Popen(
            [sys.executable, DAEMON],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=sim.env(),
        )
        try:
            assert proc.stdout is not None
            first = json.loads(proc.stdout.readline())  # polling has started
            assert first["plc"] == "plc0"
            proc.send_signal(signum)
            _, err = proc.communicate(timeout=60)
        finally:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, err
    assert f"stopping on {signum.name}" in err and "Traceback" not in err, err
