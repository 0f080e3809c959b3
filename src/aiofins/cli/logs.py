"""The one logging set-up of the command line: ``-v``/``-vv``, ``--log-level`` and
``--log-format text|json``, for every command the gateway daemon included.

The library installs no handler of its own (only a ``NullHandler``, the stdlib convention);
while a command runs, the command line installs exactly one handler, on stderr, on the
``aiofins`` logger, so each record is printed once, in one format. Its level:

* ``--log-level LEVEL`` (``DEBUG``, ``INFO``, ``WARNING``, ``ERROR``, ``CRITICAL``) when
  given: it wins over ``-v``;
* else ``-v`` INFO (lifecycle and warnings), ``-vv`` DEBUG (every frame);
* else the command's default: ERROR for one-shot commands (they report failures
  themselves), INFO for ``aiofins gateway`` (a daemon's log is its operators' record).

``--log-format json`` writes one JSON object a line with the record's ``extra`` fields
(endpoint, node, sid, command, group, ...) as keys. The options go before or after the
command (``aiofins -v read ...`` and ``aiofins read ... -v`` both work).
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from typing import Any, TextIO

#: Attributes every LogRecord has; anything else on a record came from ``extra``.
_STANDARD = frozenset(vars(logging.LogRecord("", 0, "", 0, "", (), None))) | {
    "message",
    "asctime",
    "taskName",
}

#: The level of no ``-v``'s default, ``-v`` and ``-vv``.
LEVELS = (logging.ERROR, logging.INFO, logging.DEBUG)
#: ``--log-level`` choices.
LEVEL_NAMES = ("DEBUG", "INFO", "WARNING", "ERROR", "CRITICAL")
TEXT_FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"


class JsonFormatter(logging.Formatter):
    """One JSON object per record: time, level, logger, message, the ``extra`` fields, and
    the traceback (``exc_info``) if any."""

    def format(self, record: logging.LogRecord) -> str:
        document: dict[str, Any] = {
            "time": self.formatTime(record, "%Y-%m-%dT%H:%M:%S"),
            "level": record.levelname,
            "logger": record.name,
            "message": record.getMessage(),
        }
        for name, value in vars(record).items():
            if name not in _STANDARD and not name.startswith("_"):
                document[name] = value if isinstance(value, (int, float, bool)) else str(value)
        if record.exc_info:
            document["exc_info"] = self.formatException(record.exc_info)
        return json.dumps(document)


def _level_name(text: str) -> str:
    name = text.strip().upper()
    if name not in LEVEL_NAMES:
        raise argparse.ArgumentTypeError(
            f"unknown level {text!r}; give one of {', '.join(LEVEL_NAMES)}"
        )
    return name


def add_arguments(parser: argparse.ArgumentParser, *, top: bool) -> None:
    """The logging options; on a subcommand's parser they override the top-level ones only
    when given (``aiofins -v read ...`` and ``aiofins read ... -v`` both work)."""
    default: dict[str, Any] = {} if top else {"default": argparse.SUPPRESS}
    parser.add_argument(
        "-v",
        "--verbose",
        action="count",
        help="log to stderr: -v lifecycle and warnings (INFO), -vv every frame (DEBUG)",
        **({"default": 0} if top else default),
    )
    parser.add_argument(
        "--log-level",
        type=_level_name,
        metavar="LEVEL",
        help="log at this level (DEBUG, INFO, WARNING, ERROR, CRITICAL); wins over -v "
        "(default: ERROR, INFO for the gateway daemon)",
        **({"default": None} if top else default),
    )
    parser.add_argument(
        "--log-format",
        choices=("text", "json"),
        help="log lines as text (default) or one JSON object each",
        **({"default": "text"} if top else default),
    )


def level(verbose: int, log_level: str | None, default: int = logging.ERROR) -> int:
    """The level the options choose: ``--log-level`` if given, else ``-v``/``-vv``, else
    the command's ``default``."""
    if log_level is not None:
        return logging.getLevelName(_level_name(log_level))  # type: ignore[no-any-return]
    if verbose:
        return LEVELS[min(verbose, len(LEVELS) - 1)]
    return default


def configure(
    verbose: int,
    log_format: str,
    stream: TextIO | None = None,
    *,
    log_level: str | None = None,
    default: int = logging.ERROR,
) -> logging.Handler:
    """Send the ``aiofins`` logger's records to ``stream`` (stderr) at the level the options
    chose (see :func:`level`); returns the one handler installed."""
    handler = logging.StreamHandler(stream if stream is not None else sys.stderr)
    if log_format == "json":
        handler.setFormatter(JsonFormatter())
    else:
        handler.setFormatter(logging.Formatter(TEXT_FORMAT))
    logger = logging.getLogger("aiofins")
    logger.addHandler(handler)
    logger.setLevel(level(verbose, log_level, default))
    return handler
