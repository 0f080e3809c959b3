"""The session's own background tasks, cancellable without touching the caller's scope, and
ending at a boundary: an error in one never reaches the caller's task group."""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import Any

import anyio
from anyio.abc import TaskGroup


class Background:
    """Starts the session's own tasks (and its transport's reader) so that closing cancels
    them and nothing else.

    (Cancelling the task group's scope would also cancel the body of the caller's
    ``async with session:`` block.) An exception escaping a task is handed to ``on_error``
    (the session logs it, counts it and fails the link) instead of the task group.
    """

    def __init__(
        self,
        task_group: TaskGroup,
        on_error: Callable[[Exception], None] | None = None,
    ) -> None:
        self.task_group = task_group
        self.on_error = on_error
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
                except Exception as exc:
                    if self.on_error is None:
                        raise
                    if not self.closed:
                        self.on_error(exc)
                finally:
                    self.scopes.discard(scope)

        self.task_group.start_soon(run)

    def cancel_all(self) -> None:
        self.closed = True
        for scope in list(self.scopes):
            scope.cancel()
