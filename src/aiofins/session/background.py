"""The session's own background tasks, cancellable without touching the caller's scope, and
ending at a boundary: an error in one never reaches the caller's task group."""

from __future__ import annotations

import asyncio
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

    A task asked for from an asyncio callback, outside any task (a transport's
    ``connection_lost`` or ``data_received``), is started by ``from_task``'s task instead
    (the session's deadline watcher, woken for it): anyio starts a task only from a task
    (under a loop run by ``asyncio.run`` it raises ``NoEventLoopError`` elsewhere).
    """

    def __init__(
        self,
        task_group: TaskGroup,
        on_error: Callable[[Exception], None] | None = None,
        from_task: Callable[[Callable[[], None]], None] | None = None,
    ) -> None:
        self.task_group = task_group
        self.on_error = on_error
        #: Runs a chore from an already running task, soon (see the class's docstring).
        self.from_task = from_task
        self.scopes: set[anyio.CancelScope] = set()
        self.closed = False

    def child(self, on_error: Callable[[Exception], None]) -> Background:
        """Another set of tasks in the same task group, cancelled on their own (an extra SID
        space's), their errors handed to ``on_error``."""
        return Background(self.task_group, on_error, self.from_task)

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

        def start() -> None:
            self.task_group.start_soon(run)

        if self.from_task is not None and _in_callback():
            self.from_task(start)
        else:
            start()

    def cancel_all(self) -> None:
        self.closed = True
        for scope in list(self.scopes):
            scope.cancel()


def _in_callback() -> bool:
    """Whether the caller is an asyncio callback rather than a task (under trio, code always
    runs in a task: there is no asyncio loop)."""
    try:
        return asyncio.current_task() is None
    except RuntimeError:
        return False
