"""A virtual PLC for tests that run code as a user would: in a subprocess, told where the
PLC is by ``PLC_URL`` (the examples' and the docs' convention).

The simulator is served by an event loop in a thread of its own, so the test can look into
the PLC's memory (and change it) through :meth:`RunningPLC.call` while the user's code runs.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

from anyio.from_thread import BlockingPortal, start_blocking_portal

from aiofins.simulator import FaultRule, Simulator, VirtualPLC, run_simulator

ROOT = Path(__file__).resolve().parent.parent

T = TypeVar("T")


@dataclass
class RunningPLC:
    """A virtual PLC served on loopback UDP and TCP (free ports)."""

    plc: VirtualPLC
    simulator: Simulator
    portal: BlockingPortal
    #: ``udp://127.0.0.1:PORT``: what a test puts in ``PLC_URL``.
    url: str
    tcp_url: str

    def call(self, func: Callable[..., T], *args: object) -> T:
        """Run ``func(*args)`` in the simulator's event loop thread (a look at its memory)."""
        return self.portal.call(lambda: func(*args))

    def go_silent(self) -> None:
        """From now on the PLC answers nothing (every request dropped), as a PLC whose
        cable was pulled."""
        self.portal.call(lambda: setattr(self.simulator.plan, "rule", FaultRule(drop_request=1.0)))

    def env(self, **extra: str) -> dict[str, str]:
        """The environment of a user's shell with ``PLC_URL`` pointing at this PLC."""
        return {**os.environ, "PLC_URL": self.url, **extra}


@contextmanager
def simulated_plc(plc: VirtualPLC | None = None) -> Iterator[RunningPLC]:
    """Serve ``plc`` (a fresh :class:`VirtualPLC` by default) until the block ends."""
    plc = VirtualPLC() if plc is None else plc
    simulator = run_simulator(plc, udp=("127.0.0.1", 0), tcp=("127.0.0.1", 0))
    with start_blocking_portal() as portal, portal.wrap_async_context_manager(simulator) as sim:
        yield RunningPLC(
            plc,
            sim,
            portal,
            f"udp://127.0.0.1:{sim.udp_port}",
            f"tcp://127.0.0.1:{sim.tcp_port}",
        )


def run_python(
    args: list[str], env: dict[str, str], *, stdin: str | None = None, timeout: float = 120
) -> subprocess.CompletedProcess[str]:
    """``python ARGS...`` in the repository's root, as a user would type it."""
    return subprocess.run(
        [sys.executable, *args],
        input=stdin,
        capture_output=True,
        text=True,
        env=env,
        cwd=ROOT,
        timeout=timeout,
    )
