"""The session's own background tasks, cancellable without touching the caller's scope."""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import Any

import anyio
from anyio.abc import TaskGroup


class Background:
    """Starts the session's own tasks so that closing cancels them and nothing else.

    (Cancelling the task group's scope would also cancel the body of the caller's
    ``async with session:`` block.)
    """

    def __init__(self, task_group: TaskGroup) -> None:
        self.task_group = task_group
        self.scopes: set[anyio.CancelScope] = set()
        self.closed = False

    def start_soon(self, func: Callable[..., Awaitable[Any]], *args: Any) -> None:
        async def run() -> None:
            if self.closed:
                return
            with anyio.CancelScope() as scope:
                self.scopes.add(scope)
                try:
                    await func(*args)
                finally:
                    self.scopes.discard(scope)

        self.task_group.start_soon(run)

    def cancel_all(self) -> None:
        self.closed = True
        for scope in list(self.scopes):
            scope.cancel()
