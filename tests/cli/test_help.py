"""Every ``--help`` looks the same: a description, a help text per argument (or its choices),
examples that the parser accepts."""

from __future__ import annotations

import argparse
import shlex

import pytest

from aiofins.cli import build_parser
from aiofins.cli.examples import EPILOG_START, EXAMPLES, MAIN_EXAMPLES


def _subcommands() -> dict[str, argparse.ArgumentParser]:
    subparsers = build_parser()._subparsers
    assert subparsers is not None
    (action,) = subparsers._group_actions
    assert isinstance(action, argparse._SubParsersAction)
    return dict(action.choices)


SUBCOMMANDS = _subcommands()


def _example_lines(examples: str) -> list[list[str]]:
    """The command lines (comment lines left out, a trailing ``&`` too)."""
    lines = [shlex.split(line, comments=True) for line in examples.strip().splitlines()]
    return [[word for word in line if word != "&"] for line in lines if line]


@pytest.mark.parametrize("name", sorted(SUBCOMMANDS))
def test_help_has_a_description_help_texts_and_examples(name: str) -> None:
    parser = SUBCOMMANDS[name]
    assert parser.description, name
    # An argument says what it is in a help text, or at least by its choices ({monitor,run}).
    undocumented = [a.dest for a in parser._actions if not a.help and not a.choices]
    assert not undocumented, f"aiofins {name}: {undocumented} have no help text"
    text = parser.format_help()
    assert f"\n{EPILOG_START}\n  # " in text and f"\n  aiofins {name} " in text
    for line in EXAMPLES[name].strip().splitlines():  # kept as written, not re-wrapped
        assert line in text


@pytest.mark.parametrize(
    "argv",
    [
        pytest.param(argv, id=" ".join(argv))
        for name, examples in EXAMPLES.items()
        if name in SUBCOMMANDS
        for argv in _example_lines(examples)
    ]
    + [pytest.param(argv, id=" ".join(argv)) for argv in _example_lines(MAIN_EXAMPLES)[:-1]],
)
def test_every_example_is_a_command_line_the_parser_accepts(argv: list[str]) -> None:
    assert argv[0] == "aiofins"
    args = build_parser().parse_args(argv[1:])
    assert args.command == argv[1]


def test_the_main_help_ends_with_examples() -> None:
    text = build_parser().format_help()
    assert text.rstrip().endswith(MAIN_EXAMPLES.rstrip().splitlines()[-1])
