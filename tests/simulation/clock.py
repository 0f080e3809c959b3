"""The process-wide source-node registry, fresh for each simulated run.

The session reads the event loop's clock itself (``aiofins.session.clock``: a loop whose
``time()`` is its own, as :class:`~tests.simulation.loop.VirtualTimeLoop`'s, is read
directly), so a run needs no patching of the session. What a run does need: the registry of
UDP source nodes (``SOURCE_NODES``, shared by every session of the process) starts empty on
the run's clock, so which nodes a run's sessions take depends on the seed alone, not on what
an earlier run (or test) still holds or cools.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from aiofins.session.nodes import SOURCE_NODES


@contextmanager
def session_clock(clock: Callable[[], float]) -> Iterator[None]:
    nodes: Any = SOURCE_NODES
    state = (nodes._held, nodes._cooling, nodes._clock)
    nodes._held, nodes._cooling, nodes._clock = {}, {}, clock
    try:
        yield
    finally:
        nodes._held, nodes._cooling, nodes._clock = state
