"""The command line against a simulator started with ``aiofins simulate`` (a real process)."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import anyio
import pytest

from aiofins.cli import main
from aiofins.cli.demo import demo


def simulate(*options: str) -> subprocess.Popen[str]:
    """``aiofins simulate`` on free loopback ports, in its own process."""
    return subprocess.Popen(
        [sys.executable, "-m", "aiofins.cli", "simulate", "--udp", "127.0.0.1:0", *options],
        stdout=subprocess.PIPE,
        text=True,
    )


def udp_url_of(proc: subprocess.Popen[str]) -> str:
    assert proc.stdout is not None
    for line in proc.stdout:
        if line.startswith("listening on udp://"):
            return line.split()[-1]
    raise AssertionError("simulator did not report its UDP address")


@contextmanager
def simulator_url(*options: str) -> Iterator[str]:
    """The UDP URL of an ``aiofins simulate`` process, stopped on leaving."""
    proc = simulate(*options)
    try:
        yield udp_url_of(proc)
    finally:
        proc.terminate()
        proc.wait(timeout=10)


@pytest.fixture(scope="module")
def sim_url() -> Iterator[str]:
    with simulator_url("--tcp", "127.0.0.1:0", "--mode", "program") as url:
        yield url


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_write_then_read_json(sim_url: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert run(capsys, "write", sim_url, "D10", "1", "0x10", "65535")[0] == 0
    code, out, _ = run(capsys, "read", sim_url, "D10", "3", "--json")
    assert code == 0
    assert json.loads(out) == {"address": "D10", "type": "raw", "values": [1, 16, 65535]}


def test_typed_read_and_write(sim_url: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert run(capsys, "write", sim_url, "D20", "-1.25", "--type", "float32")[0] == 0
    code, out, _ = run(capsys, "read", sim_url, "D20", "--type", "float32", "--json")
    assert code == 0 and json.loads(out)["values"] == [-1.25]
    code, out, _ = run(capsys, "read", sim_url, "D20", "2", "--json")
    assert code == 0
    assert json.loads(out)["values"] == [0x0000, 0xBFA0]


def test_status_info_clock_ping(sim_url: str, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(capsys, "status", sim_url, "--json")
    status = json.loads(out)
    assert code == 0 and status["mode"] == "PROGRAM"
    # The status byte decoded: program stopped, not on standby (bits 3-6 masked).
    assert status["running"] is False and status["standby"] is False
    assert status["status"] & 0x01 == 0 and status["status"] & 0x78 == 0
    code, out, _ = run(capsys, "info", sim_url, "--json")
    info = json.loads(out)
    assert code == 0 and info["model_data"]["model"] == "CJ2M-CPU33"
    assert info["model_data"]["area_data"]["dm_words"] == 32768
    assert info["configuration"]["cpu_bus_units"] == [0] * 16
    assert "reserved" not in info["configuration"]
    code, out, _ = run(capsys, "info", sim_url)
    assert code == 0 and "model_data.model: CJ2M-CPU33" in out.splitlines()
    assert "model_data.area_data.dm_words: 32768" in out.splitlines()
    code, out, _ = run(capsys, "clock", sim_url, "--json")
    assert code == 0 and json.loads(out)["time"][:2] == "20"
    code, out, _ = run(capsys, "ping", sim_url, "--count", "2", "--json")
    assert code == 0 and json.loads(out)["count"] == 2


def test_errors_go_to_stderr_with_nonzero_exit(
    sim_url: str, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, err = run(capsys, "write", sim_url, "A0", "1")
    assert code != 0 and out == ""
    assert "2101" in err
    code, out, err = run(capsys, "read", sim_url, "D40000")
    assert code != 0 and "D" in err and out == ""
    code, out, err = run(capsys, "read", "udp://127.0.0.1:1", "D0", "--timeout", "0.2")
    assert code != 0 and out == ""


def test_poll_prints_scans(sim_url: str, capsys: pytest.CaptureFixture[str]) -> None:
    run(capsys, "write", sim_url, "D50", "42")
    code, out, _ = run(
        capsys, "poll", sim_url, "x=D50", "CIO 0.01", "--interval", "0.05", "--count", "2", "--json"
    )
    lines = [json.loads(line) for line in out.splitlines()]
    assert code == 0 and len(lines) == 2
    assert lines[0]["tags"]["x"] == {
        "value": 42,
        "quality": "good",
        "timestamp": lines[0]["tags"]["x"]["timestamp"],
    }
    assert lines[0]["tags"]["CIO 0.01"]["value"] is False


def test_demo_shows_good_values(tmp_path: object) -> None:
    import io

    out = io.StringIO()
    shown = anyio.run(demo, 1.2, 0.2, out)
    text = out.getvalue()
    assert shown >= 2
    assert "temperature" in text and "LOT-0042" in text
    assert "error" not in text and "stale" not in text


def test_backup_restore_and_files(
    sim_url: str, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    image = tmp_path / "program.bin"
    assert run(capsys, "backup", sim_url, str(image))[0] == 0
    assert image.stat().st_size > 0 and image.stat().st_size % 4 == 0
    code, out, err = run(capsys, "restore", sim_url, str(image), "--stop")
    assert code == 0 and "restored" in out, err
    params = tmp_path / "params.json"
    assert run(capsys, "backup", sim_url, str(params), "--what", "parameters")[0] == 0
    assert set(json.loads(params.read_text())) == {"8010", "8012", "8013", "8002"}
    assert run(capsys, "restore", sim_url, str(params), "--what", "parameters")[0] == 0

    local = tmp_path / "notes.txt"
    local.write_bytes(b"line\n" * 1000)
    assert run(capsys, "files", sim_url, "put", "NOTES.TXT", str(local))[0] == 0
    code, out, _ = run(capsys, "files", sim_url, "list", "--json")
    sizes = {e["name"]: e["size"] for e in json.loads(out)}
    assert code == 0 and sizes["NOTES.TXT"] == 5000
    back = tmp_path / "back.txt"
    assert run(capsys, "files", sim_url, "get", "NOTES.TXT", str(back))[0] == 0
    assert back.read_bytes() == local.read_bytes()
    assert run(capsys, "files", sim_url, "delete", "NOTES.TXT") == (0, "NOTES.TXT: deleted\n", "")
    code, out, _ = run(capsys, "files", sim_url, "list", "--json")
    assert "NOTES.TXT" not in out
    code, out, err = run(capsys, "files", sim_url, "delete", "NOTES.TXT", "--json")
    assert (code, out) == (1, "") and err == "aiofins: NOTES.TXT: no such file, nothing deleted\n"


@pytest.mark.parametrize(
    ("flags", "said"), [("40", "a non-fatal"), ("C0", "a fatal and a non-fatal")]
)
def test_cpu_error_flags_succeed_with_a_warning_on_stderr(
    flags: str, said: str, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    with simulator_url("--flags", flags) as url:
        code, out, err = run(capsys, "read", url, "D0", "2", "--json")
        assert code == 0 and json.loads(out)["values"] == [0, 0]  # stdout: the JSON, unchanged
        warning = f"warning: the PLC reports {said} CPU error (end code 00{flags})"
        assert warning in err
        # poll (once, however many scans), files and backup warn too
        code, out, err = run(capsys, "poll", url, "x=D0", "--interval", "0.02", "--count", "2")
        assert code == 0 and len(out.splitlines()) == 2 and err.count(warning) == 1, err
        code, _, err = run(capsys, "files", url, "list")
        assert code == 0 and warning in err
        code, _, err = run(capsys, "backup", url, str(tmp_path / "p.bin"))
        assert code == 0 and warning in err


def test_ping_count_must_be_positive(sim_url: str, capsys: pytest.CaptureFixture[str]) -> None:
    for count in ("0", "-1"):
        code, out, err = run(capsys, "ping", sim_url, "--count", count)
        assert (code, out) == (1, "") and f"CommandError: --count {count}: give the" in err


def test_no_warning_without_flags(sim_url: str, capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run(capsys, "read", sim_url, "D0")
    assert code == 0 and err == ""


def test_values_that_do_not_parse_are_errors_not_tracebacks(
    sim_url: str, capsys: pytest.CaptureFixture[str]
) -> None:
    for argv, said in (
        (("D30", "12a", "--type", "bcd16"), "value '12a' is not an integer"),
        (("D30", "abc"), "value 'abc' is no word (a whole number 0..65535"),
        (("D30", "1,5", "--type", "float32"), "value '1,5' is not a number"),
    ):
        code, out, err = run(capsys, "write", sim_url, *argv)
        assert code == 1 and out == "" and f"CommandError: {said}" in err
    code, _, _ = run(capsys, "write", sim_url, "D40", "--type", "float64", "--", "-1e10")
    assert code == 0
    code, out, _ = run(capsys, "read", sim_url, "D40", "--type", "float64", "--json")
    assert json.loads(out)["values"] == [-1e10]


def test_restore_with_a_bad_file_does_not_stop_the_plc(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The file is read and checked before --stop sends anything."""
    proc = simulate()  # RUN mode
    try:
        url = udp_url_of(proc)
        for content, what in (
            ("{bad", "parameters"),
            ('{"8010": [1, 2]}', "parameters"),
            ("123", "program"),  # 3 bytes: not a multiple of 4
            ("", "program"),  # empty
            ('{"8010": [1, 2, 3, 4]}  ', "program"),  # 24 bytes, but a parameter backup
        ):
            path = tmp_path / f"backup.{what}"
            path.write_text(content)
            code, out, err = run(capsys, "restore", url, str(path), "--what", what, "--stop")
            assert code == 1 and out == "" and "CommandError" in err, err
        code, out, _ = run(capsys, "status", url, "--json")
        assert json.loads(out)["mode"] == "RUN"
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def test_poll_refuses_bad_tags_and_intervals_before_polling(
    sim_url: str, capsys: pytest.CaptureFixture[str]
) -> None:
    for argv, said in (
        (("x=Q0",), "AddressError: 'Q0': unknown area 'Q'"),
        (("x=D0:float99",), "CommandError: unknown value type 'float99'"),
        (("=D0",), "CommandError: tag '=D0' is not ADDRESS[:TYPE] or NAME=ADDRESS[:TYPE]"),
        (("x=D0", "--interval", "0"), "CommandError: interval must be a positive number"),
        (("a=D0", "a=D1"), "CommandError: tag name 'a' is given twice"),
        (("x=D0", "--count", "-1"), "CommandError: --count -1: give a number of scans"),
    ):
        code, out, err = run(capsys, "poll", sim_url, "--count", "1", *argv)
        assert code == 1 and out == "" and said in err, err
    code, out, err = run(capsys, "read", "udp://[::1", "D0")
    assert code == 1 and "CommandError: 'udp://[::1': Invalid IPv6 URL" in err


def test_poll_text_lines_say_why_a_scan_failed(capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as silent:  # a PLC that never answers
        silent.bind(("127.0.0.1", 0))
        url = f"udp://127.0.0.1:{silent.getsockname()[1]}"
        # 1 s: time for the socket to open first, even on a loaded machine (with 0.05 s the
        # line said "no connection within 0.05 s" instead)
        code, out, _ = run(capsys, "poll", url, "x=D0", "--timeout", "1", "--count", "1")
    assert code == 0
    assert out.startswith("#1 x=None(error)  (FinsTimeout: no response to command 0101"), out


def test_simulate_startup_errors_are_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    """Port in use, unknown host, no such device, bad unit: a line on stderr, no traceback."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as busy:
        busy.bind(("127.0.0.1", 0))
        port = busy.getsockname()[1]
        code, _, err = run(capsys, "simulate", "--udp", f"127.0.0.1:{port}")
    assert code == 1 and "Traceback" not in err
    assert err.splitlines()[0] == (
        f"aiofins simulate: [Errno 98] cannot serve FINS/UDP on 127.0.0.1:{port}: "
        "Address already in use"
    )
    code, _, err = run(capsys, "simulate", "--serial", "/nonexistent/tty")
    assert code == 1 and "could not open port /nonexistent/tty" in err
    with pytest.raises(SystemExit) as info:  # refused by argparse, as every bad option
        run(capsys, "simulate", "--serial", "/dev/null", "--serial-unit", "40")
    err = capsys.readouterr().err
    assert info.value.code == 2 and "Traceback" not in err
    assert err.splitlines()[-1].endswith("argument --serial-unit: 40 out of range 0..31")


def test_errors_inside_task_groups_are_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run(capsys, "demo", "--interval", "0")
    assert code == 1
    assert err == "aiofins: CommandError: interval must be a positive number of seconds, got 0.0\n"


def test_poll_changes_only_counts_scans_not_printed_lines(
    sim_url: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """Unchanged scans print nothing, but --count N still stops after N scans."""
    run(capsys, "write", sim_url, "D60", "7", "8")
    argv = ["poll", sim_url, "a=D60", "b=D61", "--interval", "0.02", "--count", "4"]
    done = subprocess.run(  # in a process: it used to wait for a change forever
        [sys.executable, "-m", "aiofins.cli", *argv, "--changes-only", "--json"],
        capture_output=True,
        text=True,
        timeout=20,
        check=False,
    )
    lines = [json.loads(line) for line in done.stdout.splitlines()]
    assert done.returncode == 0 and len(lines) == 1, done  # the first scan: all changed
    assert lines[0]["scan"] == 1 and set(lines[0]["tags"]) == {"a", "b"}


def test_timeout_bounds_the_fins_tcp_handshake(capsys: pytest.CaptureFixture[str]) -> None:
    """A FINS/TCP peer that accepts (the kernel completes the TCP handshake of a listening
    socket nobody accepts on) but never answers the node address request."""
    with socket.socket() as silent:
        silent.bind(("127.0.0.1", 0))
        silent.listen(8)
        url = f"tcp://127.0.0.1:{silent.getsockname()[1]}"
        code, out, err = run(capsys, "read", url, "D0", "--timeout", "0.3")
    assert code != 0 and out == ""
    # --timeout bounded the handshake, not the default connect timeout (5 s): the message
    # names the bound that applied. How long the attempt takes is asserted on virtual time
    # (test_endpoint.py::test_tcp_connect_timeout_bounds_a_handshake_that_never_comes).
    assert "no FINS/TCP connection or node address reply" in err and "within 0.3 s" in err
