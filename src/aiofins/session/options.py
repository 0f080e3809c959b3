"""The checks of a :class:`~aiofins.session.Session`'s options, in one place: a bad value
raises :class:`CommandError` naming the option before anything is opened."""

from __future__ import annotations

import math

from ..protocol.errors import CommandError
from ..protocol.frames import check_command
from .sids import MAX_LINGER


def shown(value: float | None) -> str:
    """A number of seconds as its caller would write it in an error message: a whole
    float without its ``.0``. (A compiled session receives ``timeout=0``
    as ``0.0``: mypyc turns an ``int`` passed for a ``float`` into one, see
    docs/packaging.md; the message says ``timeout 0`` either way.)"""
    if isinstance(value, float) and value.is_integer():
        return str(int(value))
    return str(value)


def check_options(
    *,
    gct: int,
    max_in_flight: int,
    timeout: float,
    attempt_timeout: float | None,
    retries: int,
    busy_retries: int,
    breaker_threshold: int,
    busy_backoff: float,
    quarantine_factor: float,
    min_quarantine: float,
    min_linger: float,
    max_sid_spaces: int | None,
    default_sid_spaces: int,
    reconnect_backoff: tuple[float, float],
    breaker_cooldown: tuple[float, float],
    rto_bounds: tuple[float, float],
) -> int:
    """Raise :class:`CommandError` for the first option out of its range (see
    :class:`~aiofins.session.Session`); return ``max_sid_spaces``, the transport's
    ``default_sid_spaces`` if not given."""
    if not 0 <= gct <= 0xFF:
        raise CommandError(f"GCT {gct} out of range 0..255")
    if not 1 <= max_in_flight <= 255:
        raise CommandError(f"max_in_flight {max_in_flight} out of range 1..255")
    if timeout <= 0:
        raise CommandError(f"timeout {shown(timeout)} must be positive")
    if attempt_timeout is not None and attempt_timeout <= 0:
        raise CommandError(f"attempt_timeout {shown(attempt_timeout)} must be positive")
    for name, count in (
        ("retries", retries),
        ("busy_retries", busy_retries),
        ("breaker_threshold", breaker_threshold),
    ):
        if count < 0:
            raise CommandError(f"{name} {count} must not be negative")
    if busy_backoff < 0:
        raise CommandError(f"busy_backoff {shown(busy_backoff)} must not be negative")
    if quarantine_factor <= 0:
        raise CommandError(f"quarantine_factor {shown(quarantine_factor)} must be positive")
    if not 0 <= min_quarantine < math.inf:
        raise CommandError(f"min_quarantine {shown(min_quarantine)} must be 0 or more seconds")
    if not 0 <= min_linger <= MAX_LINGER:
        raise CommandError(f"min_linger {shown(min_linger)} must be 0..{MAX_LINGER} seconds")
    if max_sid_spaces is None:
        max_sid_spaces = default_sid_spaces
    elif not 1 <= max_sid_spaces <= 254:
        raise CommandError(f"max_sid_spaces {max_sid_spaces} out of range 1..254")
    for name, (low, high) in (
        ("reconnect_backoff", reconnect_backoff),
        ("breaker_cooldown", breaker_cooldown),
    ):
        if not 0 <= low <= high:
            raise CommandError(f"{name} {(low, high)} must be (min, max), 0 <= min <= max")
    low, high = rto_bounds
    if not 0 < low <= high < math.inf:
        raise CommandError(f"rto_bounds {rto_bounds} must be (min, max), 0 < min <= max")
    return max_sid_spaces


def check_call(
    mrc: int, src: int, params: bytes, timeout: float, retries: int, cap: float | None
) -> None:
    """Refuse a call's options (``cap``: its ``attempt_timeout``) or a command no FINS
    frame can carry, before anything is done (what :meth:`Session.begin` calls only when
    its one comparison found something wrong)."""
    if not timeout > 0:
        raise CommandError(f"timeout {shown(timeout)} must be positive")
    if retries < 0:
        raise CommandError(f"retries {retries} must not be negative")
    if cap is not None and not cap > 0:
        raise CommandError(f"attempt_timeout {shown(cap)} must be positive")
    check_command(mrc, src, params)
