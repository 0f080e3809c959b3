"""The command line refuses bad values with the API's words, never a traceback (#17 item 4)."""

from __future__ import annotations

import json

import pytest

from .test_cli import run, sim_url  # noqa: F401 - the module's simulator fixture


def test_timeout_nan_is_refused_before_connecting(capsys: pytest.CaptureFixture[str]) -> None:
    for argv in (
        ("read", "udp://127.0.0.1:1", "D0", "--timeout", "nan"),
        ("files", "udp://127.0.0.1:1", "list", "--timeout", "nan"),
        ("poll", "udp://127.0.0.1:1", "D0", "--timeout", "nan"),
    ):
        with pytest.raises(SystemExit) as exit_info:
            run(capsys, *argv)
        assert exit_info.value.code == 2
        err = capsys.readouterr().err
        assert "timeout must be a positive number of seconds; got 'nan'" in err
    code, _, err = run(capsys, "read", "udp://127.0.0.1:1?timeout=nan", "D0")
    assert code == 1 and "timeout must be a positive number of seconds; got 'nan'" in err


def test_values_that_overflow_are_refused(
    sim_url: str,  # noqa: F811
    capsys: pytest.CaptureFixture[str],
) -> None:
    run(capsys, "write", sim_url, "D60", "0", "0", "0", "0")
    for argv, said in (
        (("1e400", "--type", "float64"), "CommandError: value '1e400' overflows float64"),
        (("1e39", "--type", "float32"), "CommandError: value 1e+39 overflows float32"),
        (("0x" + "f" * 5000,), "CommandError: value '0xfffff"),
        (("0x" + "f" * 5000, "--type", "uint64"), "characters) for uint64"),
        (("9" * 5000,), "is too long (5000 characters)"),
    ):
        code, out, err = run(capsys, "write", sim_url, "D60", *argv)
        assert code == 1 and out == "" and said in err, err
        assert "Traceback" not in err
    code, out, _ = run(capsys, "read", sim_url, "D60", "4", "--json")
    assert json.loads(out)["values"] == [0, 0, 0, 0]  # nothing was written
    code, _, _ = run(capsys, "write", sim_url, "D60", "--type", "float64", "--", "-inf")
    assert code == 0  # an infinity asked for by name is an IEEE value a LREAL holds
