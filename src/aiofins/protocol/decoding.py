"""Server-side decoding: turn a builder's argument error into the end code a PLC answers.

A command's ``decode`` reads raw fields and hands them to the same builders a client uses;
those raise :class:`CommandError` / :class:`AddressError`. Inside :func:`as_decode_error`
such an error becomes :class:`DecodeError` carrying the end code a PLC would answer.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from .errors import AddressError, CommandError, DecodeError

#: End code a PLC answers for a parameter it cannot accept (``110C`` parameter error).
PARAMETER_ERROR = 0x110C


@contextmanager
def as_decode_error(what: str | None, end_code: int = PARAMETER_ERROR) -> Iterator[None]:
    """Re-raise :class:`CommandError` / :class:`AddressError` as :class:`DecodeError`.

    The message is ``"{what}: {error}"`` (just the error's when ``what`` is ``None``). The
    end code is the error's own ``end_code`` when set (a builder that knows the PLC's answer,
    e.g. ``1103`` address range error), else ``end_code``.
    """
    try:
        yield
    except (CommandError, AddressError) as exc:
        message = str(exc) if what is None else f"{what}: {exc}"
        code = end_code if exc.end_code is None else exc.end_code
        raise DecodeError(message, end_code=code) from exc
