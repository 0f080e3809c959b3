"""``aiofins simulate --plant``: the newcomer's check — serve examples/plant.toml and read the
PLC two networks away with one ``aiofins read`` command, both as real processes."""

from __future__ import annotations

import re
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from aiofins.protocol.errors import CommandError
from aiofins.simulator.plantfile import load_plant, plant_from

EXAMPLE = Path(__file__).parents[2] / "examples" / "plant.toml"
TIMEOUT = 20


def aiofins(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "aiofins.cli", *args],
        capture_output=True,
        text=True,
        timeout=TIMEOUT,
    )


def test_read_a_plc_two_networks_away(tmp_path: Path) -> None:
    plant = tmp_path / "plant.toml"  # the example on a free port instead of 9600
    plant.write_text(EXAMPLE.read_text().replace('"127.0.0.10:9600"', '"127.0.0.10:0"'))
    proc = subprocess.Popen(
        [sys.executable, "-m", "aiofins.cli", "simulate", "--plant", str(plant)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None
        port = None
        lines = []
        while port is None:
            line = proc.stdout.readline()
            if not line:
                pytest.fail(f"simulator exited: {proc.communicate(timeout=TIMEOUT)}")
            lines.append(line)
            match = re.match(r"listening on udp://127\.0\.0\.10:(\d+) \(PLC line", line)
            port = int(match.group(1)) if match else None
        assert lines[:3] == [
            "PLC line: network 1 node 10, network 2 node 1\n",
            "PLC cell: network 2 node 2, network 3 node 3\n",
            "PLC press: network 3 node 5\n",
        ]
        url = f"udp://127.0.0.10:{port}?source_network=1&routes=2:controller_link,3:sysmac_link"
        read = aiofins("read", url, "D0", "2", "--dest", "3.5.0", "--json")
        assert read.returncode == 0, read.stderr
        assert '"values": [1234, 5678]' in read.stdout
        wrong = aiofins("read", url, "D0", "--dest", "4.5.0")
        assert wrong.returncode != 0
        assert "relay error at network 1 node 10" in wrong.stderr and "0501" in wrong.stderr
    finally:
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=TIMEOUT)
    assert proc.returncode == 0
    assert "delivered=1" in err and "refused:0501=1" in err and "relayed=4" in err


def test_plant_file_mistakes_are_named(tmp_path: Path) -> None:
    assert [s.name for s in load_plant(str(EXAMPLE)).stations] == ["line", "cell", "press"]
    net = [{"number": 1, "type": "ethernet"}]
    unit = {"address": 16, "network": 1, "node": 1}
    cases: list[tuple[dict[str, Any], str]] = [
        ({"network": net}, "at least one"),
        ({"network": [{"number": 1, "type": "token_ring"}], "plc": []}, "token_ring"),
        ({"network": net, "plc": [{"unit": [unit], "relay": [[2, 1]]}]}, "relay network"),
        ({"network": net, "plc": [{"unit": [unit], "relay": [[2, 3, 5]]}]}, "not in its local"),
        ({"network": net, "plc": [{"unit": [{**unit, "node": 0}]}]}, "1..254"),
        ({"network": net, "plc": [{"unit": [unit], "colour": 1}]}, "unknown key"),
        ({"network": net, "plc": [{"unit": [{**unit, "conversion": "x"}]}]}, "dynamic"),
    ]
    for data, words in cases:
        with pytest.raises(CommandError, match=words):
            plant_from(data)
    bad = tmp_path / "bad.toml"
    bad.write_text("[[network]\n")
    result = aiofins("simulate", "--plant", str(bad))
    assert result.returncode == 2 and "bad.toml" in result.stderr
