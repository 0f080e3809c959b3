"""``-v``/``-vv`` and ``--log-format text|json``: where the command line sends aiofins' logs.

The library installs no handler (stdlib convention); the command line installs one on
stderr for the ``aiofins`` logger: ERROR by default (the commands say what went wrong, and
warn about CPU error flags, themselves), INFO and WARNING with ``-v``, DEBUG (every frame)
with ``-vv``. ``--log-format json`` writes one JSON object a line with the record's
``extra`` fields (endpoint, node, sid, command, group, ...) as keys.
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

LEVELS = (logging.ERROR, logging.INFO, logging.DEBUG)


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
        "--log-format",
        choices=("text", "json"),
        help="log lines as text (default) or one JSON object each",
        **({"default": "text"} if top else default),
    )


def configure(verbose: int, log_format: str, stream: TextIO | None = None) -> logging.Handler:
    """Send the ``aiofins`` logger's records to ``stream`` (stderr) at the level ``-v``
    chose; returns the handler installed."""
    handler = logging.StreamHandler(stream if stream is not None else sys.stderr)
    if log_format == "json":
        handler.setFormatter(JsonFormatter())
    else:
        handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    logger = logging.getLogger("aiofins")
    logger.addHandler(handler)
    logger.setLevel(LEVELS[min(verbose, len(LEVELS) - 1)])
    return handler
