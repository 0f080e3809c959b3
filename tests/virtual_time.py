"""Running a test on virtual time: trio's ``MockClock(autojump_threshold=0)`` or asyncio on
looptime's loop, both of which jump the clock whenever every task waits. The session reads
the loop's clock (aiofins/session/clock.py), so timeouts, retransmissions and delays take no
wall time and their times are exact (looptime's to its resolution, 1 us). uvloop's clock
cannot be made virtual: tests of time run under these two instead."""

from __future__ import annotations

import functools
import inspect
from collections.abc import Awaitable, Callable
from typing import Any

import anyio
import looptime
import pytest
import trio
import trio.testing

#: The backends with a virtual clock, for ``pytest.mark.parametrize("backend", ...)``.
VIRTUAL_BACKENDS = ("trio", "asyncio")


def run_on_virtual_time(main: Callable[[], Awaitable[None]], backend: str = "trio") -> None:
    """Run ``main`` from virtual time 0 under ``backend`` (see :data:`VIRTUAL_BACKENDS`)."""
    if backend == "trio":
        trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))
        return
    # Through anyio's runner, so that a protocol callback outside any task (a real socket's
    # datagram_received starting a task) still finds anyio's asyncio backend.
    anyio.run(
        main,
        backend="asyncio",
        backend_options={"loop_factory": lambda: looptime.new_event_loop(start=0.0)},
    )


def on_virtual_time(test: Callable[..., Awaitable[None]]) -> Callable[..., None]:
    """An async test run on virtual time under each of :data:`VIRTUAL_BACKENDS` (uvloop's
    clock cannot be made virtual): a test whose assertions depend on how much time passes,
    exact whatever the machine's load. Its fixtures must be synchronous ones (``caplog``,
    ``tmp_path``); it gets them as before, and a ``backend`` parameter besides."""
    signature = inspect.signature(test)

    @functools.wraps(test)
    def run(backend: str, **fixtures: Any) -> None:
        run_on_virtual_time(lambda: test(**fixtures), backend)

    backend = inspect.Parameter("backend", inspect.Parameter.POSITIONAL_OR_KEYWORD)
    run.__signature__ = signature.replace(  # type: ignore[attr-defined]
        parameters=[backend, *signature.parameters.values()], return_annotation=None
    )
    marked: Callable[..., None] = pytest.mark.parametrize("backend", VIRTUAL_BACKENDS)(run)
    return marked
