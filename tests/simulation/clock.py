"""Put the session on the event loop's clock for one simulated run.

Thin adapter until the session takes an injected clock (issue 22 item 1): the session's
modules that read ``time.monotonic`` get the virtual loop's ``time`` instead, and the shared
source-node registry (process-wide) starts empty on that clock. Once the session reads the
loop's clock itself, the modules have no ``monotonic`` left and this only resets the registry.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from aiofins.session.nodes import SOURCE_NODES

#: The session's modules that read the monotonic clock.
SESSION_MODULES = (
    "aiofins.session.batch",
    "aiofins.session.breaker",
    "aiofins.session.core",
    "aiofins.session.link",
    "aiofins.session.matching",
    "aiofins.session.nodes",
    "aiofins.session.sids",
    "aiofins.session.spaces",
    "aiofins.session.watcher",
)


@contextmanager
def session_clock(clock: Callable[[], float]) -> Iterator[None]:
    saved: list[tuple[Any, Any]] = []
    for name in SESSION_MODULES:
        module: Any = importlib.import_module(name)
        if hasattr(module, "monotonic"):
            saved.append((module, module.monotonic))
            module.monotonic = clock
    nodes: Any = SOURCE_NODES
    state = (nodes._held, nodes._cooling, nodes._clock)
    nodes._held, nodes._cooling, nodes._clock = {}, {}, clock
    try:
        yield
    finally:
        for module, original in saved:
            module.monotonic = original
        nodes._held, nodes._cooling, nodes._clock = state
