"""The ``aiofins`` command line: one module per subcommand (or family of subcommands).

A subcommand module exposes ``register(subparsers)``, ``add_parser(subparsers)`` or
``add_parsers(subparsers)``; each parser it adds sets ``func`` (``Callable[[Namespace], int]``,
the exit code) as a default. To add one, write ``cli/<name>.py`` and list it in
:data:`SUBCOMMANDS`.

A module that fails to import does not take the others down (``aiofins simulate`` must keep
working whatever state the client code is in): its commands are missing and the import error
is printed when the command line cannot be parsed.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import sys
from collections.abc import Callable, Sequence

from .. import __version__
from ..protocol.errors import FinsError, leaf_errors
from . import logs
from .examples import EXAMPLES, MAIN_EXAMPLES, HelpFormatter, epilog
from .text import escape

#: Subcommand modules (relative to this package), in the order ``--help`` lists them.
SUBCOMMANDS: tuple[str, ...] = (
    "plc",
    "poll",
    "watch",
    "doctor",
    "bulk",
    "simulate",
    "demo",
    "gateway",
)

Handler = Callable[[argparse.Namespace], int]


def build_parser() -> argparse.ArgumentParser:
    """The full parser (a subcommand module that fails to import is an error, loudly)."""
    parser = argparse.ArgumentParser(
        prog="aiofins",
        description="Omron FINS client tools and virtual PLC.",
        epilog=epilog(MAIN_EXAMPLES),
        formatter_class=HelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"aiofins {__version__}")
    logs.add_arguments(parser, top=True)
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in SUBCOMMANDS:
        module = importlib.import_module(f".{name}", __name__)
        for hook in ("register", "add_parser", "add_parsers"):
            add = getattr(module, hook, None)
            if add is not None:
                add(subparsers)
                break
        else:  # pragma: no cover - a programming error
            raise RuntimeError(f"aiofins.cli.{name} has no register/add_parser(s)")
    for subparser in subparsers.choices.values():
        logs.add_arguments(subparser, top=False)
    _add_examples(subparsers)
    return parser


def _add_examples(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Every subcommand's ``--help``: a description (its one-line help if it has none) and
    the examples of :data:`~aiofins.cli.examples.EXAMPLES` at the end."""
    helps = {action.dest: action.help for action in subparsers._choices_actions}
    for name, sub in subparsers.choices.items():
        text = helps.get(name)
        if sub.description is None and text:
            sub.description = f"{text[:1].upper()}{text[1:]}."
        if name in EXAMPLES:
            sub.epilog = epilog(EXAMPLES[name])
            if sub.formatter_class is argparse.HelpFormatter:
                sub.formatter_class = HelpFormatter


def stdout_closed() -> int:
    """The reader of our output went away (``aiofins read … | head``): end quietly.

    Like a command killed by SIGPIPE: no message, and the exit code a shell shows for one
    (141). Standard output is pointed at the null device so that Python's last flush at
    exit cannot raise again.
    """
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)
    return 128 + 13  # SIGPIPE's number on every POSIX system


def report(prefix: str, exc: BaseException, expected: tuple[type[BaseException], ...]) -> bool:
    """Print ``exc`` (each error of a group) on stderr if all are ``expected``; whether it did.

    A :class:`FinsError` is printed with its type name, anything else as its message; both
    may quote the PLC, so control characters are shown escaped.
    """
    leaves = leaf_errors(exc)
    if not all(isinstance(e, expected) for e in leaves):
        return False
    for e in leaves:
        text = f"{type(e).__name__}: {e}" if isinstance(e, FinsError) else str(e)
        print(f"{prefix}: {escape(text)}", file=sys.stderr)
    return True


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit code (errors go to stderr)."""
    parser = build_parser()
    args, extras = parser.parse_known_args(argv)
    # A subcommand whose positionals are optional (``poll URL [TAG...]``) names them in
    # ``trailing``: argparse takes none of them once an option follows URL, so the rest
    # arrive here.
    trailing = getattr(args, "trailing", None)
    if extras:
        if trailing is None or any(extra.startswith("-") for extra in extras):
            parser.error(f"unrecognized arguments: {' '.join(extras)}")
        getattr(args, trailing).extend(extras)
    handler: Handler = args.func
    logger = logging.getLogger("aiofins")
    level = logger.level
    log_handler = logs.configure(
        args.verbose,
        args.log_format,
        log_level=args.log_level,
        default=getattr(args, "log_default", logging.ERROR),
    )
    try:
        return handler(args)
    except KeyboardInterrupt:
        return 130
    except Exception as exc:  # a FinsError or OSError, maybe from inside a task group
        if all(isinstance(e, BrokenPipeError) for e in leaf_errors(exc)):
            return stdout_closed()
        if report("aiofins", exc, (FinsError, OSError)):
            return 1
        raise
    finally:
        logger.removeHandler(log_handler)
        logger.setLevel(level)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
