"""Option types and guards shared by the subcommands: ``--timeout``, ``--read-only``, ``--yes``.

Values are checked by :mod:`aiofins.protocol.inputs`, so ``--timeout nan`` gets the words
``timeout=nan`` gets from the API and ``?timeout=nan`` from a URL.

Commands that change a PLC's memory, mode or files (``write``, ``run``, ``stop``,
``clock --set``, ``files delete``, ``restore --stop``) ask for confirmation when stdin is a
terminal, unless ``--yes`` is given. Without a terminal (a script, a pipe, cron) they proceed
as they always did: scripts keep working, and a script cannot answer a question anyway.
``--read-only`` refuses every such command before anything is sent.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable

from ..protocol.errors import CommandError
from ..protocol.inputs import seconds


def argument_type(check: Callable[[str], object]) -> Callable[[str], object]:
    """An argparse ``type=`` from a check of :mod:`aiofins.protocol.inputs` (its message
    becomes argparse's, exit code 2)."""

    def convert(text: str) -> object:
        try:
            return check(text)
        except CommandError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    convert.__name__ = getattr(check, "__name__", "value")
    return convert


#: ``--timeout``: a positive, finite number of seconds.
timeout_seconds = argument_type(lambda value: seconds("timeout", value, text=True))


URL_HELP = "udp://HOST[:PORT], tcp://HOST[:PORT] or serial://DEVICE?baudrate=N"


def add_url_and_tags(p: argparse.ArgumentParser) -> None:
    """URL, then tags as arguments and/or ``--tags FILE`` (``poll`` and ``watch``)."""
    p.add_argument("url", help=URL_HELP)
    p.add_argument("tags", nargs="*", help="ADDRESS[:TYPE] or NAME=ADDRESS[:TYPE]")
    p.add_argument(
        "--tags",
        dest="tag_files",
        action="append",
        default=[],
        metavar="FILE",
        help="CSV of name,address,type or a CX-Programmer symbol table (repeatable)",
    )


def add_timeout(p: argparse.ArgumentParser, default: float, help: str) -> None:
    p.add_argument("--timeout", type=timeout_seconds, default=default, help=help)


def add_read_only(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--read-only",
        action="store_true",
        help="refuse every command that changes the PLC (memory, mode, clock, files, logs, "
        "forced bits) before anything is sent",
    )


def add_yes(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "-y", "--yes", action="store_true", help="do not ask for confirmation on a terminal"
    )


def confirm(args: argparse.Namespace, question: str) -> bool:
    """Whether to go on with a command that changes the PLC: ``--yes``, no terminal on stdin
    (scripts), or the user answered yes to ``question`` on stderr."""
    stdin = sys.stdin
    if getattr(args, "yes", False) or stdin is None or not stdin.isatty():
        return True
    sys.stderr.write(f"{question} [y/N] ")
    sys.stderr.flush()
    answer = stdin.readline()  # "" at end of input (^D): no
    return answer.strip().lower() in ("y", "yes")


def refuse(what: str) -> int:
    """Say the user declined; the exit code of a declined command (1)."""
    print(f"aiofins: {what}: not confirmed, nothing sent", file=sys.stderr)
    return 1
