"""``aiofins poll URL --tags FILE`` against a simulator process."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import pytest

from .test_cli import run, simulator_url

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def sim_url() -> Iterator[str]:
    with simulator_url() as url:
        yield url


def test_poll_reads_the_tags_of_a_cx_programmer_file_and_arguments(
    sim_url: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert run(capsys, "write", sim_url, "D100", "21.5", "--type", "float32")[0] == 0
    assert run(capsys, "write", sim_url, "D7", "9")[0] == 0
    symbols = str(ROOT / "examples" / "line1_symbols.csv")
    code, out, err = run(
        capsys, "poll", sim_url, "extra=D7", "--tags", symbols, "--count", "1", "--json"
    )
    assert code == 0, err
    tags = json.loads(out)["tags"]
    assert set(tags) == {"extra", "Temperature", "PartCount", "Running", "Setpoint", "Recipe"}
    assert tags["Temperature"]["value"] == 21.5 and tags["extra"]["value"] == 9


def test_poll_refuses_a_bad_tag_file_naming_the_line(
    sim_url: str, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    path = tmp_path / "bad.csv"
    path.write_text("a,D0\nb,NOPE12\n")
    code, out, err = run(capsys, "poll", sim_url, "--tags", str(path), "--count", "1")
    assert code != 0 and out == ""
    assert f"{path}:2" in err and "NOPE12" in err
    code, out, err = run(capsys, "poll", sim_url, "a=D1", "--tags", str(path.with_name("x")))
    assert code != 0 and "No such file" in err
    path.write_text("a,D0\n")
    code, out, err = run(capsys, "poll", sim_url, "a=D1", "--tags", str(path), "--count", "1")
    assert code != 0 and "given twice" in err
    code, out, err = run(capsys, "poll", sim_url, "--count", "1")
    assert code != 0 and "no tags" in err


def test_tags_may_follow_options(sim_url: str, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run(capsys, "poll", sim_url, "a=D1", "--count", "1", "b=D2", "--json")
    assert code == 0, err
    assert set(json.loads(out)["tags"]) == {"a", "b"}
    with pytest.raises(SystemExit):
        run(capsys, "poll", sim_url, "a=D1", "--count", "1", "--bogus")
    assert "unrecognized arguments: --bogus" in capsys.readouterr().err
