"""The gateway's configuration: read whole, every mistake at once with FILE:LINE."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from aiofins.endpoint import OPTIONS, parse_endpoint
from aiofins.gateway import ConfigError, load_config
from aiofins.gateway.config import PLC_OPTIONS, parse_config

ROOT = Path(__file__).resolve().parents[2]

GOOD = """\
[gateway]
name = "plant"

[mqtt]
host = "broker.local"
port = 8883
tls = true
ca_file = "/etc/ssl/ca.pem"

[connect]
timeout = 0.5
retries = 1

[[groups]]
name = "fast"
interval = 0.25
tags = { temp = "D100:float32", sp = "D120:int16" }
writable = ["sp"]
qos = 1

[[groups]]
name = "slow"
interval = 10
changes_only = true
retain = true
tags_file = "tags.csv"

[[plcs]]
name = "press1"
url = "udp://10.0.0.5"
options = { dest = "0.5.0", timeout = 1.5 }

[[plcs]]
name = "press2"
url = "tcp://10.0.0.6:9600"
groups = ["slow"]
"""


def test_a_good_config_reads_whole(tmp_path: Path) -> None:
    (tmp_path / "tags.csv").write_text("name,address,type\nlevel,D200,uint16\nok,CIO 1.00,\n")
    path = tmp_path / "gateway.toml"
    path.write_text(GOOD)
    cfg = load_config(path)
    assert cfg.name == "plant" and cfg.mqtt.tls and cfg.mqtt.port == 8883
    assert dict(cfg.connect) == {"timeout": 0.5, "retries": 1}
    fast, slow = cfg.groups["fast"], cfg.groups["slow"]
    assert fast.interval == 0.25 and fast.writable == frozenset({"sp"}) and fast.qos == 1
    assert dict(slow.tags) == {"level": "D200:uint16", "ok": "CIO 1.00"}
    assert slow.changes_only and slow.retain and slow.interval == 10.0
    p1, p2 = cfg.plcs
    assert p1.groups == ("fast", "slow") and p2.groups == ("slow",)
    assert p1.url == "udp://10.0.0.5?dest=0.5.0&timeout=1.5"


def test_the_example_configs_are_good() -> None:
    cfg = load_config(ROOT / "examples" / "gateway.toml")
    assert [p.name for p in cfg.plcs] == ["press1"]
    assert cfg.groups["line"].writable == frozenset({"Setpoint"})
    compose = load_config(ROOT / "deploy" / "gateway.toml")
    assert len(compose.plcs) == 3 and compose.mqtt.host == "mosquitto"


BAD = """\
[gateway]
name = "has space"
[mqtt]
port = 70000
qos = 1
backoff_min = 2
backoff_max = 1
[connect]
speed = 3
[[groups]]
name = "fast"
interval = -1
tags = { temp = "D100:float33", far = "D40000" }
writable = ["nope"]
qos = 3
topic = "fins/{plant}/{group}"
[[groups]]
name = "fast"
tags = { x = "D0" }
[[groups]]
name = "empty"
[[groups]]
name = "fromfile"
tags_file = "missing.csv"
[[plcs]]
name = "p1"
url = "ftp://10.0.0.5"
groups = ["fast", "nosuch"]
[[plcs]]
name = "p1"
url = "udp://10.0.0.6"
options = { baud = 9 }
[[plcs]]
url = "udp://10.0.0.7"
[extra]
"""


def test_every_mistake_is_reported_at_once_with_its_line() -> None:
    with pytest.raises(ConfigError) as info:
        parse_config(BAD, "bad.toml")
    problems = info.value.problems
    text = "\n".join(problems)

    def line_of(fragment: str) -> int:
        (hit,) = [p for p in problems if fragment in p]
        return int(hit.split(":")[1])

    assert line_of("unknown section 'extra'") == 35
    assert line_of("gateway name 'has space'") == 2
    assert line_of("port must be a port number") == 4
    assert line_of("unknown key 'qos'") == 5
    assert line_of("backoff_max is below backoff_min") == 7
    assert line_of("speed") == 8  # the [connect] header
    assert line_of("interval must be a positive number") == 12
    assert line_of("tag 'temp' (D100:float33)") == 13
    assert line_of("tag 'far' (D40000)") == 13
    assert line_of("writable tag 'nope'") == 14
    assert line_of("qos must be 0, 1 or 2") == 15
    assert line_of("unknown field(s) plant") == 16
    assert line_of("group 'fast' is defined twice") == 18
    assert line_of("group 'empty' has no tags") == 20
    assert line_of("missing.csv") == 24
    assert line_of("ftp") == 27
    assert line_of("no group named 'nosuch'") == 28
    assert line_of("PLC 'p1' is defined twice") == 30
    assert line_of("option 'baud'") == 32
    assert line_of("needs a name and a url") == 33
    assert all(p.startswith("bad.toml:") for p in problems), text


def test_toml_syntax_errors_name_their_line() -> None:
    with pytest.raises(ConfigError) as info:
        parse_config('[gateway]\nname = "x"\n[[plcs]\n', "syntax.toml")
    (problem,) = info.value.problems
    assert problem.startswith("syntax.toml:3: TOML syntax")


def test_two_pairs_on_one_topic_are_refused() -> None:
    text = """
[[groups]]
name = "a"
topic = "fins/{plc}"
tags = { x = "D0" }
[[groups]]
name = "b"
topic = "fins/{plc}"
tags = { y = "D1" }
[[plcs]]
name = "p"
url = "udp://127.0.0.1"
"""
    with pytest.raises(ConfigError, match="publishes on 'fins/p', the topic of PLC 'p' group 'a'"):
        parse_config(text)
    with pytest.raises(ConfigError, match="status"):
        parse_config(text.replace('topic = "fins/{plc}"\n', 'topic = "fins/{plc}/status"\n', 1))


EXAMPLE = str(ROOT / "examples" / "gateway.toml")


def test_the_cli_checks_a_config_and_reports_mistakes(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text(BAD)
    result = subprocess.run(
        [sys.executable, "-m", "aiofins.cli", "gateway", str(bad)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 2 and result.stdout == ""
    lines = result.stderr.splitlines()
    assert len(lines) == 20 and all(line.startswith(f"{bad}:") for line in lines)
    good = subprocess.run(
        [sys.executable, "-m", "aiofins.cli", "gateway", "--check", "--shard", "1/2", EXAMPLE],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert good.returncode == 0, good.stderr
    assert "OK" in good.stdout and "2 groups" in good.stdout
    bad_shard = subprocess.run(
        [sys.executable, "-m", "aiofins.cli", "gateway", "--shard", "2/2", EXAMPLE],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert bad_shard.returncode == 2 and "0 <= I < N" in bad_shard.stderr


def test_mqtt_limits_are_checked_before_anything_connects(tmp_path: Path) -> None:
    """``keepalive = 70000`` and a 70,000-character client id passed ``--check`` and killed
    the daemon at its first connect; topics the broker would refuse are caught too."""
    text = f"""\
[mqtt]
keepalive = 70000
client_id = "{"c" * 70000}"
gateway_topic = "$SYS/{{gateway}}"
plc_status_topic = "fins/{{plc}}/st\\u0000"

[[groups]]
name = "g"
tags = {{ x = "D0" }}
topic = "{"t" * 70000}/{{plc}}"

[[plcs]]
name = "p1"
url = "udp://10.0.0.5"
"""
    path = tmp_path / "limits.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_config(path)
    problems = info.value.problems

    def line_of(fragment: str) -> int:
        (hit,) = [p for p in problems if fragment in p]
        return int(hit.split(":")[1])

    assert line_of("keepalive must be 1..65535 seconds") == 2
    assert line_of("client_id has 70000 bytes, at most 65535") == 3
    assert line_of("gateway_topic must not be empty, start with '$'") == 4
    assert line_of("plc_status_topic must not be empty, start with '$' or contain NUL") == 5
    assert line_of("PLC 'p1' group 'g''s topic has 70003 bytes") == 13
    result = subprocess.run(
        [sys.executable, "-m", "aiofins.cli", "gateway", "--check", str(path)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert len(result.stderr.splitlines()) == len(problems)
    assert len(result.stderr) < 2000  # the 70,000-character values are not echoed whole
    assert all(line.startswith(f"{path}:") for line in result.stderr.splitlines())


def test_a_malformed_tag_file_is_reported_by_check_with_its_lines(tmp_path: Path) -> None:
    (tmp_path / "tags.csv").write_text(
        "Name,Data Type,Address / Value,Rack Location,Usage,Comment\n"
        'sp,INT,D100,,Work,"first line\nsecond line, with a comma"\n'
        f"big,STRING[{'9' * 5000}],D200,,,\n"
        f'huge,INT,D1,,,"{"x" * 200_000}"\n'
        "ok,REAL,D300,,,\n"
    )
    path = tmp_path / "gw.toml"
    path.write_text(
        '[[groups]]\nname = "g"\ntags_file = "tags.csv"\n'
        '[[plcs]]\nname = "p1"\nurl = "udp://10.0.0.5"\n'
    )
    result = subprocess.run(
        [sys.executable, "-m", "aiofins.cli", "gateway", "--check", str(path)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 2 and "Traceback" not in result.stderr, result.stderr
    lines = result.stderr.splitlines()
    csv = tmp_path / "tags.csv"
    assert len(lines) == 2, lines
    assert lines[0].startswith(f"{path}:3: {csv}:4: a cell of 5008 characters")
    assert lines[1].startswith(f"{path}:3: {csv}:5: a cell longer than csv's limit")


def test_per_plc_options_are_the_url_options_of_the_one_table() -> None:
    """A PLC's ``options`` take every URL option of ``aiofins.endpoint.OPTIONS`` (the
    breaker's and the reconnection's too), in TOML's own types, checked by that table."""
    text = """
[[groups]]
name = "g"
tags = { x = "D0" }
[[plcs]]
name = "p1"
url = "udp://10.0.0.5"
[plcs.options]
breaker_threshold = 2
breaker_cooldown = [0.1, 5]
reconnect_backoff = "0.5,30"
read_only = true
[[plcs]]
name = "p2"
url = "tcp://10.0.0.6"
options = { breaker_cooldown = [5, 1] }
[[plcs]]
name = "p3"
url = "serial:///dev/ttyUSB0"
options = { breaker_threshold = -1, baudrate = 19200 }
[[plcs]]
name = "p4"
url = "udp://10.0.0.7?breaker_threshold=1"
options = { breaker_threshold = 3 }
"""
    assert {"breaker_threshold", "breaker_cooldown", "reconnect_backoff"} <= PLC_OPTIONS
    assert {name for name, option in OPTIONS.items() if option.schemes} == PLC_OPTIONS
    with pytest.raises(ConfigError) as info:
        parse_config(text, "plcs.toml")
    problems = info.value.problems
    assert len(problems) == 3, problems  # p3: serial and its options parse
    assert problems[0].startswith("plcs.toml:16: breaker_cooldown must be MIN,MAX seconds")
    assert problems[1].startswith("plcs.toml:20: breaker_threshold must be a whole number")
    assert problems[2].startswith("plcs.toml:23: ") and "given twice" in problems[2]
    good = parse_config(text.split('[[plcs]]\nname = "p2"')[0], "plcs.toml")
    (p1,) = good.plcs
    endpoint = parse_endpoint(p1.url)
    assert endpoint.option("breaker_threshold") == "2"
    assert endpoint.option("breaker_cooldown") == "0.1,5.0"
    assert endpoint.option("reconnect_backoff") == "0.5,30.0"
    assert endpoint.option("read_only") == "True"
