"""aiofins.sync: the blocking client, against the virtual PLC served from another thread.

Calls run in the calling thread (UDP, FINS/TCP) or, with ``backend=``, on a private event
loop's thread; the tests of what both promise run in both modes (``MODES``). The direct
path's own tests are in test_sync_direct.py."""

from __future__ import annotations

import inspect
import socket
import threading
from array import array
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor

import pytest
from anyio.from_thread import start_blocking_portal

import aiofins
import aiofins.sync
from aiofins.protocol.addresses import parse_address
from aiofins.protocol.commands.memory import MemoryAreaRead
from aiofins.simulator import VirtualPLC, run_simulator


@pytest.fixture(scope="module")
def url() -> Iterator[str]:
    """A virtual PLC on loopback UDP, served by an event loop in a thread of its own."""
    with (
        start_blocking_portal() as portal,
        portal.wrap_async_context_manager(run_simulator(VirtualPLC(), udp=("127.0.0.1", 0))) as sim,
    ):
        yield f"udp://127.0.0.1:{sim.udp_port}"


def _loop_threads() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name == "aiofins.sync"]


#: The two modes of a blocking client: calls in the calling thread, or on a loop's thread.
MODES = pytest.mark.parametrize("backend", [None, "asyncio"], ids=["direct", "loop"])


def test_reads_and_writes_words_values_and_commands(url: str) -> None:
    with aiofins.sync.connect(url) as plc:
        plc.write("D100", [1, 2, 0x10])
        assert plc.read("D100", 3) == [1, 2, 16]
        plc.write_value("D200", 21.5, "float32")
        assert plc.read_value("D200", "float32") == 21.5
        plc.write_values("D300", [-1, 7], "int32")
        assert plc.read_values("D300", "int32", 2) == [-1, 7]
        plc.write("CIO 0.00", [1, 0])
        assert plc.read_bit("CIO 0.00") is True
        assert plc.read_tags({"t": "D200:float32", "x": "D101"}) == {"t": 21.5, "x": 2}
        assert plc.cpu_unit_status_read().mode.name == "PROGRAM"
        result = plc.call(MemoryAreaRead(parse_address("D100"), 2))
        assert list(result.values) == [1, 2]
        assert plc.last_end_code is not None and plc.last_end_code.raw == 0
        assert plc.dest == plc.async_client.dest


def test_typed_values_are_typed_by_their_type_name(url: str) -> None:
    with aiofins.sync.connect(url) as plc:
        plc.write_value("D700", 21.5, "float32")
        plc.write_value("D702", -7, "int32")
        plc.write("CIO 1.00", [1, 0])
        # Annotated assignments: mypy --strict fails here if the overloads give the union.
        x: float = plc.read_value("D700", "float32")
        n: int = plc.read_value("D702", "int32")
        w: int = plc.read_value("D700")
        b: bool = plc.read_value("CIO 1.00", "bit")
        bits: list[bool] = plc.read_values("CIO 1.00", "bit", 2)
        ns: list[int] = plc.read_values("D702", "DINT", 1)
        assert (x, n, b, bits, ns) == (21.5, -7, True, [True, False], [-7])
        assert isinstance(w, int) and type(x) is float


def test_arrays_of_words_and_typed_values(url: str) -> None:
    with aiofins.sync.connect(url) as plc:
        words = array("H", [(i * 3) & 0xFFFF for i in range(3000)])
        plc.write_array("D1000", words, allow_split=True)
        got: array[int] = plc.read_array("D1000", 3000)  # mypy: array[int] for words
        assert got.typecode == "H" and got == words
        assert plc.read("D1000", 3) == [0, 3, 6]
        plc.write_array("D5000", array("f", [-2.5, 0.5]), "float32")
        floats: array[float] = plc.read_array("D5000", 2, "float32")
        assert floats.tolist() == [-2.5, 0.5]
        assert plc.read("D5000", 2) == [0x0000, 0xC020]  # CDAB


@MODES
def test_a_plc_error_is_raised_in_the_calling_thread(url: str, backend: str | None) -> None:
    with (
        aiofins.sync.connect(url, backend=backend) as plc,
        pytest.raises(aiofins.EndCodeError) as caught,
    ):
        plc.write("A0", [1])  # A0-A447 are read-only
    assert caught.value.end_code.raw == 0x2101


@MODES
def test_close_joins_the_loop_thread_and_later_calls_fail(url: str, backend: str | None) -> None:
    before = len(_loop_threads())
    plc = aiofins.sync.connect(url, backend=backend)
    assert len(_loop_threads()) == before + (backend is not None)  # direct: no thread
    plc.read("D0")
    states = [plc.state]
    plc.close()
    states.append(plc.state)
    assert states == [aiofins.sync.ClientState.OPEN, aiofins.sync.ClientState.CLOSED]
    assert len(_loop_threads()) == before
    with pytest.raises(aiofins.ConnectionLost, match="closed"):
        plc.read("D0")
    plc.close()  # a second close does nothing


def test_a_failed_connect_leaves_no_thread() -> None:
    before = len(_loop_threads())
    with pytest.raises(aiofins.CommandError):
        aiofins.sync.connect("ftp://127.0.0.1")
    assert len(_loop_threads()) == before


@MODES
def test_a_timeout_is_bounded_and_raised_as_fins_timeout(backend: str | None) -> None:
    # A UDP port nobody answers on: the datagram goes nowhere, the call times out.
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as silent:
        silent.bind(("127.0.0.1", 0))
        port = silent.getsockname()[1]
        with (
            aiofins.sync.connect(
                f"udp://127.0.0.1:{port}", timeout=0.2, retries=0, backend=backend
            ) as plc,
            pytest.raises(aiofins.FinsTimeout),
        ):
            plc.read("D0")


@MODES
def test_threads_share_one_client(url: str, backend: str | None) -> None:
    with aiofins.sync.connect(url, backend=backend) as plc:
        plc.write("D500", list(range(8)))
        with ThreadPoolExecutor(4) as pool:
            results = list(pool.map(lambda i: plc.read(f"D{500 + i}", 1)[0], range(8)))
    assert results == list(range(8))


@pytest.mark.parametrize(
    ("backend", "options"),
    [("asyncio", {}), ("asyncio", {"use_uvloop": True}), ("trio", {})],
    ids=["asyncio", "uvloop", "trio"],
)
def test_each_backend(url: str, backend: str, options: dict[str, bool]) -> None:
    pytest.importorskip("uvloop" if options else backend)
    with aiofins.sync.connect(url, backend=backend, backend_options=options) as plc:
        plc.write("D600", [42])
        assert plc.read("D600") == [42]


def test_every_coroutine_method_of_the_async_client_is_here_with_its_signature() -> None:
    names = [
        name
        for name, member in inspect.getmembers(aiofins.Client)
        if not name.startswith("_")
        and inspect.iscoroutinefunction(member)
        # the async client's own life; the blocking one's is connect() and close()
        and name not in ("open", "aclose")
    ]
    assert len(names) > 47
    for name in names:
        blocking = getattr(aiofins.sync.Client, name, None)
        assert blocking is not None, f"aiofins.sync.Client has no {name}"
        expected = inspect.signature(getattr(aiofins.Client, name))
        got = inspect.signature(getattr(blocking, "__wrapped__", blocking))
        assert got.parameters == expected.parameters, name
        assert blocking.__doc__, name


def test_a_bound_blocking_method_shows_the_async_methods_signature(url: str) -> None:
    with aiofins.sync.connect(url) as plc:
        assert plc.read.__doc__ == aiofins.Client.read.__doc__
        assert str(inspect.signature(plc.read)) == str(inspect.signature(plc.async_client.read))
        assert "count" in inspect.signature(plc.read).parameters


@MODES
def test_close_ends_a_call_waiting_in_another_thread(backend: str | None) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as silent:
        silent.bind(("127.0.0.1", 0))
        silent.settimeout(10)
        plc = aiofins.sync.connect(
            f"udp://127.0.0.1:{silent.getsockname()[1]}", timeout=30, retries=0, backend=backend
        )
        raised: list[BaseException] = []

        def call() -> None:
            try:
                plc.read("D0")
            except BaseException as exc:
                raised.append(exc)

        caller = threading.Thread(target=call)
        caller.start()
        silent.recv(100)  # the request went out: the call is waiting for its reply
        plc.close()
        caller.join(10)  # a bounded wait for the thread's end: the call's own timeout is 30 s
        assert not caller.is_alive()
        assert len(raised) == 1 and isinstance(raised[0], aiofins.ConnectionLost), raised


def test_an_unknown_backend_is_refused_in_the_calling_thread(url: str) -> None:
    before = len(_loop_threads())
    with pytest.raises(LookupError):
        aiofins.sync.connect(url, backend="curio")
    assert len(_loop_threads()) == before
