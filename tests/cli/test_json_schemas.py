"""Every ``--json`` document is the one docs/cli-json.md documents (validated by its schema)."""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path
from typing import Any

import pytest
from jsonschema import Draft202012Validator

from aiofins.cli import build_parser, main

PAGE = Path(__file__).resolve().parents[2] / "docs" / "cli-json.md"


def _schemas() -> dict[str, dict[str, Any]]:
    """The page's schemas by command (``"read"``, ``"files list"``), from their titles."""
    schemas: dict[str, dict[str, Any]] = {}
    for block in re.findall(r"```json\n(.*?)```", PAGE.read_text(), re.DOTALL):
        schema = json.loads(block)
        title = re.fullmatch(r"aiofins (.+) --json", schema["title"])
        assert title is not None, schema["title"]
        Draft202012Validator.check_schema(schema)
        schemas[title.group(1)] = schema
    return schemas


SCHEMAS = _schemas()


def _json_commands() -> set[str]:
    """Subcommands with a ``--json`` option (``files``: its actions that print JSON)."""
    subparsers = build_parser()._subparsers
    assert subparsers is not None
    (action,) = subparsers._group_actions
    assert isinstance(action, argparse._SubParsersAction)
    names = set()
    for name, parser in action.choices.items():
        if any("--json" in a.option_strings for a in parser._actions):
            names |= {"files list", "files delete"} if name == "files" else {name}
    return names


def test_every_command_with_json_output_has_a_documented_schema() -> None:
    commands = _json_commands()
    assert commands <= set(SCHEMAS), f"document {commands - set(SCHEMAS)} in {PAGE.name}"
    assert set(SCHEMAS) <= commands, "a schema for a command that does not exist"


def _documents(capsys: pytest.CaptureFixture[str], *argv: str) -> list[Any]:
    assert main(list(argv)) == 0
    out = capsys.readouterr().out
    return [json.loads(line) for line in out.splitlines()]


def _check(command: str, document: Any) -> None:
    errors = [e.message for e in Draft202012Validator(SCHEMAS[command]).iter_errors(document)]
    assert not errors, (command, document, errors)


def test_each_document_matches_its_schema(
    url: str, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    seen: set[str] = set()

    def check(command: str, *argv: str, lines: int = 1) -> list[Any]:
        documents = _documents(capsys, *command.split()[:1], url, *command.split()[1:], *argv)
        assert len(documents) == lines, documents
        for document in documents:
            _check(command, document)
        seen.add(command)
        return documents

    (written,) = check("write", "D100", "1", "2", "--json")
    assert written == {"address": "D100", "written": 2}
    (words,) = check("read", "D100", "2", "--json")
    assert words["values"] == [1, 2]
    for argv in (
        ("D200", "--type", "float32"),
        ("D210", "--type", "string:4"),
        ("CIO 0.00", "3"),
        ("D0", "2", "--type", "bit"),
    ):
        check("read", *argv, "--json")
    (status,) = check("status", "--json")
    assert status["mode"] == "RUN"
    (info,) = check("info", "--json")
    assert info["model_data"]["model"] == "CJ2M-CPU33"
    check("clock", "--json")
    (doctor,) = check("doctor", "--json")
    assert doctor["exit_code"] == 0 and doctor["reachable"] is True
    assert {f["check"] for f in doctor["findings"]} >= {"udp", "node", "cpu", "rtt"}
    (ping,) = check("ping", "--count", "2", "--json")
    assert ping["count"] == 2
    scans = check(
        "poll", "t=D200:float32", "D100", "--count", "2", "--interval", "0.05", "--json", lines=2
    )
    assert [s["scan"] for s in scans] == [1, 2] and scans[0]["tags"]["D100"]["value"] == 1

    local = tmp_path / "RECIPE.CSV"
    local.write_text("a,b\n")
    assert main(["files", url, "put", "RECIPE.CSV", str(local)]) == 0
    (clock,) = check("clock", "--set", "2026-01-02T03:04:05", "--yes", "--json")
    assert clock["time"] == "2026-01-02T03:04:05"
    (mode,) = check("run", "--mode", "run", "--yes", "--json")
    assert mode == {"mode": "RUN"}
    (mode,) = check("stop", "--yes", "--json")
    assert mode == {"mode": "PROGRAM"}
    (mode,) = check("run", "--yes", "--json")
    assert mode == {"mode": "MONITOR"}

    (entries,) = check("files list", "--json")
    assert [e["name"] for e in entries] == ["RECIPE.CSV"]
    (deleted,) = check("files delete", "RECIPE.CSV", "--json")
    assert deleted == {"deleted": 1}
    assert seen == set(SCHEMAS)


def test_a_schema_refuses_what_it_does_not_document() -> None:
    """The schemas are strict: a renamed or missing field fails the test above."""
    validator = Draft202012Validator(SCHEMAS["read"])
    assert validator.is_valid({"address": "D0", "type": "raw", "values": [1]})
    assert not validator.is_valid({"address": "D0", "type": "raw", "value": [1]})
    assert not validator.is_valid({"address": "D0", "type": "raw", "values": [1], "x": 0})
