"""A real Mosquitto broker on a free loopback port, and an MQTT subscriber that records.

The gateway (aiomqtt) is asyncio only: its async tests run under asyncio and uvloop.
Tests skip only when the ``mosquitto`` binary is missing (CI installs it).
"""

from __future__ import annotations

import getpass
import json
import shutil
import socket
import subprocess
import time
from collections.abc import AsyncIterator, Callable, Iterator, Sequence
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import aiomqtt
import anyio
import anyio.abc
import pytest

from aiofins.simulator import VirtualPLC, run_simulator
from aiofins.simulator.runner import Simulator

from ..conftest import Backend


@pytest.fixture(params=["asyncio", pytest.param(("asyncio", {"use_uvloop": True}), id="uvloop")])
def anyio_backend(request: pytest.FixtureRequest) -> Backend:
    """aiomqtt runs on asyncio only (stock and uvloop)."""
    backend: Backend = request.param
    if backend != "asyncio":
        pytest.importorskip("uvloop")
    return backend


#: Seconds after which a wait that should end is called a hang: a guard, never a timing bound
#: (the suite may run on a machine at load 20).
HANG = 120.0


async def eventually(condition: Callable[[], object]) -> None:
    """Until ``condition()`` holds, looked at every 10 ms (a counter nothing signals), with
    :data:`HANG` as the guard."""
    with anyio.fail_after(HANG):
        while not condition():
            await anyio.sleep(0.01)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Broker:
    """``mosquitto`` with a config file written here; :meth:`start` returns once it listens."""

    def __init__(
        self, directory: Path, *, persistence: bool = False, settings: Sequence[str] = ()
    ) -> None:
        self.directory = directory
        self.port = free_port()
        self.persistence = persistence
        #: More mosquitto.conf lines for the listener (TLS files, password file, ...).
        self.settings = list(settings)
        self.proc: subprocess.Popen[str] | None = None

    def start(self) -> None:
        conf = self.directory / "mosquitto.conf"
        lines = [
            f"listener {self.port} 127.0.0.1",
            *(self.settings or ["allow_anonymous true"]),
            "log_dest stderr",
            "log_type error",
        ]
        # A subscriber of the tests that falls behind (a busy machine) must not lose QoS 1
        # messages in the broker: mosquitto keeps at most 1,000 queued per client by default
        # and drops the rest uncounted, so a test counting replies would miss some.
        lines.append("max_queued_messages 0")
        # Started as root, mosquitto would switch to user "mosquitto", which cannot read or
        # write here: it stays who we are.
        lines.append(f"user {getpass.getuser()}")
        if self.persistence:
            lines += ["persistence true", f"persistence_location {self.directory}/"]
        conf.write_text("\n".join(lines) + "\n")
        self.proc = subprocess.Popen(
            ["mosquitto", "-c", str(conf)],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        # Its log is block-buffered in a pipe: ready is when the port accepts a connection.
        deadline = time.monotonic() + HANG
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                assert self.proc.stderr is not None
                raise AssertionError(f"mosquitto exited: {self.proc.stderr.read()}")
            try:
                socket.create_connection(("127.0.0.1", self.port), timeout=1).close()
                return
            except OSError:
                time.sleep(0.01)
        raise AssertionError(f"mosquitto did not listen within {HANG:g} s")

    def stop(self) -> None:
        if self.proc is not None:
            self.proc.terminate()
            self.proc.wait(timeout=10)
            if self.proc.stderr is not None:
                self.proc.stderr.close()
            self.proc = None


def need_mosquitto() -> None:
    if shutil.which("mosquitto") is None:
        pytest.skip("mosquitto is not installed (apt-get install mosquitto)")


@pytest.fixture
def broker(tmp_path: Path) -> Iterator[Broker]:
    need_mosquitto()
    b = Broker(tmp_path)
    b.start()
    try:
        yield b
    finally:
        b.stop()


class Client(aiomqtt.Client):
    """The tests' MQTT peer: aiomqtt's client with one race of its own closed. When paho
    has output, aiomqtt asks the loop to watch the socket for writing one step later
    (``call_soon_threadsafe(loop.add_writer, ...)``: paho may call from the thread that
    connects). If the broker goes away within that step, paho has closed the socket by
    then, and uvloop raises ``RuntimeError`` ("the handler is closed") out of that loop
    callback, which fails whatever test runs (a subscriber's PUBACK as a test stops the
    broker: tests/gateway/test_daemon.py's broker restart under uvloop, once in ten
    runs of the suite). Here the step first checks that the socket is still paho's, and a
    watch the loop refuses all the same (uvloop closes an fd's poll handle when the poll
    reports an error and keeps it in its table, before paho has closed the socket: loaded
    run 1 of 5 on 7adb26e) counts as the broken connection it is, as a failed write does."""

    def _on_socket_register_write(self, client: Any, userdata: Any, sock: Any) -> None:
        fd, loop = sock.fileno(), self._loop

        def broken(exc: Exception) -> None:  # (aiomqtt's own reaction to a broken connection)
            if not self._disconnected.done():
                self._disconnected.set_exception(exc)

        def write() -> None:
            try:
                client.loop_write()
            except Exception as exc:
                broken(exc)

        def watch() -> None:
            if client.socket() is sock:  # (None once paho closed it)
                try:
                    loop.add_writer(fd, write)
                except (RuntimeError, OSError, ValueError) as exc:  # (a handle or fd closed)
                    broken(exc)

        loop.call_soon_threadsafe(watch)


@dataclass
class Received:
    topic: str
    payload: bytes
    retain: bool

    def json(self) -> Any:
        return json.loads(self.payload)


@dataclass
class Subscriber:
    """Records every message of its topic filters; :meth:`wait_for` waits for a condition."""

    messages: list[Received] = field(default_factory=list)
    _changed: anyio.Event = field(default_factory=anyio.Event)

    def on(self, topic: str) -> list[Any]:
        return [m.json() for m in self.messages if m.topic == topic]

    def add(self, message: Received) -> None:
        self.messages.append(message)
        self._changed.set()
        self._changed = anyio.Event()

    async def wait_for(self, condition: Callable[[], object], timeout: float = HANG) -> None:
        with anyio.fail_after(timeout):
            while not condition():
                await self._changed.wait()


@asynccontextmanager
async def subscribe(
    port: int,
    *topics: str,
    identifier: str | None = None,
    clean: bool = True,
    into: Subscriber | None = None,
) -> AsyncIterator[Subscriber]:
    """A subscriber for the ``async with`` block; a broker that went away meanwhile is no
    error when it ends."""
    sub = into or Subscriber()
    yielded = False
    try:
        async with Client(
            "127.0.0.1", port, identifier=identifier, clean_session=clean, timeout=2
        ) as client:
            for topic in topics:
                await client.subscribe(topic, qos=1)
            async with anyio.create_task_group() as tg:

                async def pump() -> None:
                    try:
                        async for m in client.messages:
                            assert isinstance(m.payload, bytes)
                            sub.add(Received(str(m.topic), m.payload, m.retain))
                    except aiomqtt.MqttError:  # the broker went away (a test stopped it)
                        pass

                tg.start_soon(pump)
                yielded = True
                yield sub
                tg.cancel_scope.cancel()
    except aiomqtt.MqttError:
        if not yielded:
            raise


@asynccontextmanager
async def simulators(count: int) -> AsyncIterator[list[Simulator]]:
    """``count`` virtual PLCs on loopback UDP, side by side in one task group (a failure is
    one error, not a nest of ``count`` groups)."""
    sims: list[Simulator] = []
    stop = anyio.Event()
    async with anyio.create_task_group() as tg:

        async def serve(*, task_status: anyio.abc.TaskStatus[None]) -> None:
            async with run_simulator(VirtualPLC(), udp=("127.0.0.1", 0)) as sim:
                sims.append(sim)
                task_status.started()
                await stop.wait()

        for _ in range(count):
            await tg.start(serve)
        yield sims
        stop.set()


@asynccontextmanager
async def publisher(port: int) -> AsyncIterator[Client]:
    """An MQTT 5 client (message expiry) to publish set requests with."""
    async with Client("127.0.0.1", port, protocol=aiomqtt.ProtocolVersion.V5) as client:
        yield client
