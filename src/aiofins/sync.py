"""A blocking client for scripts and notebooks: ``aiofins.sync.connect(url)``.

Each method of the blocking :class:`Client` is the async :class:`~aiofins.Client`'s method of
the same name, run to its end before it returns, so a script needs neither ``async`` nor
``await``::

    with aiofins.sync.connect("udp://192.168.250.1") as plc:
        words = plc.read("D100", 10)

The methods have the async client's parameters, results and exceptions (a
:class:`~aiofins.FinsTimeout` is raised in the calling thread).

Over UDP and FINS/TCP a call runs in the calling thread: the session's request steps, which
do no I/O, are driven on a blocking socket (see :mod:`aiofins._blocking`); no event loop
and no other thread take part. One call runs at a time: a client may be shared by several
threads, whose calls then take turns (one waits while another's is on the wire).

With ``backend=`` (``"asyncio"``, ``"trio"``; ``backend_options={"use_uvloop": True}``),
and always over a serial line, the async client runs on a private event loop in a thread of
its own and each call is sent there: calls from several threads then run concurrently, as
async tasks would (pipelined up to ``max_in_flight``).

:meth:`Client.close` (or leaving the ``with`` block) closes the session (and joins the
loop's thread); a call waiting in another thread ends with :class:`~aiofins.ConnectionLost`.
Inside a running event loop (``async def``, FastAPI) use the async client instead: a
blocking call there stalls that loop for the call's duration.
"""

from __future__ import annotations

import contextlib
import enum
import functools
import math
import threading
from collections.abc import Callable, Coroutine, Mapping, Sequence
from contextlib import AbstractContextManager, ExitStack
from types import TracebackType
from typing import Any, Concatenate, Generic, ParamSpec, TypeVar, cast, overload

import anyio
from anyio.from_thread import BlockingPortal

from ._blocking import BlockingDriver, run_to_end
from .client import AddressLike, Progress
from .client import Client as AsyncClient
from .connection import Prepared, needs_lookup, prepare
from .connection import connect as _async_connect
from .endpoint import parse_endpoint
from .protocol.arrays import FloatArray, NumberArray, WordArray
from .protocol.endcodes import EndCode
from .protocol.errors import ConnectionLost
from .protocol.header import FinsAddress
from .protocol.values import BoolTypeName, FloatTypeName, IntTypeName, Value, ValueType
from .session import Session
from .tags import ReadPlan
from .transport.blocking import BlockingTransport

__all__ = ["Client", "ClientState", "connect"]

P = ParamSpec("P")
R = TypeVar("R")


class _LoopThread:
    """An event loop in a daemon thread, reached through an anyio blocking portal.

    A daemon thread, so that a script which forgets to close its client still exits (the
    operating system closes the socket).
    """

    def __init__(self, backend: str, backend_options: Mapping[str, Any] | None) -> None:
        self._backend = backend
        self._backend_options = dict(backend_options or {})
        self._ready = threading.Event()
        self._portal: BlockingPortal | None = None
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="aiofins.sync", daemon=True)
        self._thread.start()
        self._ready.wait()
        if self._error is not None:
            raise self._error

    def _run(self) -> None:
        try:
            anyio.run(self._serve, backend=self._backend, backend_options=self._backend_options)
        except BaseException as exc:  # the loop could not start (unknown backend, ...)
            self._error = exc
            self._ready.set()

    async def _serve(self) -> None:
        async with BlockingPortal() as portal:
            self._portal = portal
            self._ready.set()
            await portal.sleep_until_stopped()

    @property
    def portal(self) -> BlockingPortal:
        if self._portal is None:  # pragma: no cover - __init__ raised instead
            raise RuntimeError("the event loop thread did not start")
        return self._portal

    def stop(self) -> None:
        """Stop the loop (cancelling calls still running) and join the thread."""
        if self._thread.is_alive() and self._portal is not None:
            with contextlib.suppress(RuntimeError):  # already stopping
                self._portal.call(self._portal.stop, True)
        self._thread.join()


class _LoopRunner:
    """Runs each call on a :class:`_LoopThread`'s event loop (calls from several threads run
    there concurrently)."""

    def __init__(self, loop: _LoopThread, state: Callable[[], ClientState]) -> None:
        self.loop = loop
        self.state = state

    def call(self, method: Callable[..., Coroutine[Any, Any, R]], args: Any, kwargs: Any) -> R:
        async def run() -> R:
            return await method(*args, **kwargs)

        try:
            return self.loop.portal.call(run)
        except RuntimeError:  # the portal stopped between the caller's check and the call
            state = self.state()
            if state is ClientState.OPEN:
                raise
            raise ConnectionLost(f"the blocking client is {state.value}") from None

    def interrupt(self) -> None:
        """Nothing to do: closing the session ends the calls waiting on the loop."""


class _DirectRunner:
    """Runs each call in the calling thread on a :class:`~aiofins._blocking.BlockingDriver`,
    one at a time (a lock): the async client's coroutine runs to its end without an event
    loop (see :func:`~aiofins._blocking.run_to_end`)."""

    def __init__(self, driver: BlockingDriver, state: Callable[[], ClientState]) -> None:
        self.driver = driver
        self.state = state
        self.lock = threading.RLock()
        #: A call runs (in the thread holding the lock).
        self.busy = False
        #: The client is closing or closed: calls are refused.
        self.closed = False

    def call(self, method: Callable[..., Coroutine[Any, Any, R]], args: Any, kwargs: Any) -> R:
        return self.blocking(method)(*args, **kwargs)

    def blocking(self, method: Callable[P, Coroutine[Any, Any, R]]) -> Callable[P, R]:
        """``method`` as a blocking function: each call runs it to its end under the lock
        (:func:`~aiofins._blocking.run_to_end`, inlined: this runs once per call)."""
        lock = self.lock

        def blocking(*args: P.args, **kwargs: P.kwargs) -> R:
            with lock:
                if self.busy or self.closed:
                    raise self._refusal()
                self.busy = True
                try:
                    coro = method(*args, **kwargs)
                    try:
                        coro.send(None)
                    except StopIteration as done:
                        result: R = done.value
                        return result
                    return run_to_end(coro)  # (suspended: refused)
                finally:
                    self.busy = False

        return blocking

    def _refusal(self) -> Exception:
        if self.closed:
            return ConnectionLost(f"the blocking client is {self.state().value}")
        # (the lock is the thread's own: a callback of its running call)
        return RuntimeError(
            "a call of the blocking client from inside one of its calls (a progress or "
            "on_response callback): call it after the outer call returns"
        )

    def interrupt(self) -> None:
        """Refuse calls from now on; end a call waiting in another thread (its socket is
        shut down)."""
        self.closed = True
        self.driver.interrupt()

    def close(self) -> None:
        """Close the driver once no call runs (a call interrupted ends first)."""
        with self.lock:
            self.driver.close()


_Runner = _LoopRunner | _DirectRunner


class _Blocking(Generic[P, R]):
    """A blocking method made from a coroutine method of the async client.

    ``read = _Blocking(AsyncClient.read)`` in the class body gives the blocking client a
    ``read`` with the async method's parameters and result type, as mypy and IDEs see them.
    """

    def __init__(self, method: Callable[Concatenate[AsyncClient, P], Coroutine[Any, Any, R]]):
        self._name = method.__name__
        self.__doc__ = method.__doc__
        self.__wrapped__ = method

    def __set_name__(self, owner: type[Any], name: str) -> None:
        self._name = name

    @overload
    def __get__(self, instance: None, owner: type[Any]) -> _Blocking[P, R]: ...

    @overload
    def __get__(self, instance: Client, owner: type[Any]) -> Callable[P, R]: ...

    def __get__(
        self, instance: Client | None, owner: type[Any]
    ) -> _Blocking[P, R] | Callable[P, R]:
        if instance is None:
            return self
        method: Callable[P, Coroutine[Any, Any, R]] = getattr(instance.async_client, self._name)
        runner = instance._runner
        if isinstance(runner, _DirectRunner):
            blocking = runner.blocking(method)
        else:
            loop_runner = runner

            def blocking(*args: P.args, **kwargs: P.kwargs) -> R:
                return loop_runner.call(method, args, kwargs)

        functools.update_wrapper(blocking, method)  # name, docstring, signature

        # Made once per client: the instance's attribute hides this descriptor from now on.
        instance.__dict__[self._name] = blocking
        return blocking


class ClientState(enum.Enum):
    """The life of a blocking :class:`Client`; :meth:`Client._move` makes every change."""

    #: Connected: each call runs on the private loop.
    OPEN = "open"
    #: :meth:`Client.close` is under way: new calls are refused, the session is closing (calls
    #: still waiting end with :class:`~aiofins.ConnectionLost`), then the loop thread stops.
    CLOSING = "closing"
    #: The session is closed and the loop thread joined; calls raise ``ConnectionLost``.
    CLOSED = "closed"


#: The changes :meth:`Client._move` allows.
_TRANSITIONS: dict[ClientState, frozenset[ClientState]] = {
    ClientState.OPEN: frozenset({ClientState.CLOSING}),
    ClientState.CLOSING: frozenset({ClientState.CLOSED}),
    ClientState.CLOSED: frozenset(),
}


class Client:
    """A blocking FINS client: the methods of :class:`aiofins.Client`, without ``await``.

    Made by :func:`connect`. Each method runs the async client's method of the same name on
    the private event loop and returns its result (or raises its exception). The async
    client is :attr:`async_client`; ``with`` closes the client on leaving the block.
    """

    def __init__(
        self,
        async_client: AsyncClient,
        runner: Callable[[Callable[[], ClientState]], _Runner],
        resources: ExitStack,
    ):
        #: The async client underneath: its coroutines run in the calling thread on the
        #: blocking driver, or (``backend=``, serial) on the private loop only.
        self.async_client = async_client
        self._resources = resources
        self._state = ClientState.OPEN
        self._lock = threading.Lock()
        self._runner = runner(lambda: self._state)

    @property
    def state(self) -> ClientState:
        """Open, closing or closed."""
        return self._state

    def _move(self, to: ClientState) -> bool:
        """Change state if allowed from the current one (thread-safe); whether it changed."""
        with self._lock:
            if to not in _TRANSITIONS[self._state]:
                return False
            self._state = to
            return True

    def _call(
        self, method: Callable[P, Coroutine[Any, Any, R]], /, *args: P.args, **kwargs: P.kwargs
    ) -> R:
        if self._state is not ClientState.OPEN:
            raise ConnectionLost(f"the blocking client is {self._state.value}")
        return self._runner.call(method, args, kwargs)

    def _call_any(
        self, method: Callable[..., Coroutine[Any, Any, Any]], /, *args: Any, **kwargs: Any
    ) -> Any:
        """:meth:`_call` for a method whose signature the caller's annotations give (one with
        overloads, or ``**kw``: mypy cannot take those apart)."""
        return self._call(method, *args, **kwargs)

    def close(self) -> None:
        """Close the session and stop the loop thread (joined before this returns).

        Calls still waiting in other threads end with :class:`~aiofins.ConnectionLost`.
        Closing a client that is closing or closed does nothing.
        """
        if not self._move(ClientState.CLOSING):
            return
        try:
            self._runner.interrupt()
            self._resources.close()
        finally:
            self._move(ClientState.CLOSED)

    def __enter__(self) -> Client:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    @property
    def dest(self) -> FinsAddress:
        """The PLC's FINS address (the default destination of every call)."""
        return self.async_client.dest

    @property
    def last_end_code(self) -> EndCode | None:
        """End code of the latest normal response (the CPU error flags 0040/0080)."""
        return self.async_client.last_end_code

    def compile_tags(self, tags: Mapping[str, str], *, max_gap: int = 8) -> ReadPlan:
        """Compile a tag list for this client's route limits (no I/O)."""
        return self.async_client.compile_tags(tags, max_gap=max_gap)

    # Methods taking ``**kw`` (the read/write options) are written out: mypy cannot take
    # their signatures apart from ``self`` (nor an overloaded one's).

    def read_bit(self, address: AddressLike, **kw: Any) -> bool:
        """Read one bit (``"CIO 0.01"``) as a bool."""
        return bool(self._call_any(self.async_client.read_bit, address, **kw))

    @overload
    def read_value(self, address: AddressLike, vtype: FloatTypeName, **kw: Any) -> float: ...
    @overload
    def read_value(self, address: AddressLike, vtype: BoolTypeName, **kw: Any) -> bool: ...
    @overload
    def read_value(self, address: AddressLike, vtype: IntTypeName = "uint16", **kw: Any) -> int: ...
    @overload
    def read_value(self, address: AddressLike, vtype: str | ValueType, **kw: Any) -> Value: ...
    def read_value(
        self, address: AddressLike, vtype: str | ValueType = "uint16", **kw: Any
    ) -> Value:
        """Read one typed value: ``plc.read_value("D200", "float32")``, typed as the async
        method's overloads say (a ``float`` here)."""
        value: Value = self._call_any(self.async_client.read_value, address, vtype, **kw)
        return value

    @overload
    def read_values(
        self, address: AddressLike, vtype: FloatTypeName, count: int, **kw: Any
    ) -> list[float]: ...
    @overload
    def read_values(
        self, address: AddressLike, vtype: BoolTypeName, count: int, **kw: Any
    ) -> list[bool]: ...
    @overload
    def read_values(
        self, address: AddressLike, vtype: IntTypeName, count: int, **kw: Any
    ) -> list[int]: ...
    @overload
    def read_values(
        self, address: AddressLike, vtype: str | ValueType, count: int, **kw: Any
    ) -> list[Value]: ...
    def read_values(
        self, address: AddressLike, vtype: str | ValueType, count: int, **kw: Any
    ) -> list[Any]:
        """Read ``count`` consecutive typed values (typed as :meth:`read_value` says)."""
        values: list[Any] = self._call_any(
            self.async_client.read_values, address, vtype, count, **kw
        )
        return values

    @overload
    def read_array(
        self,
        address: AddressLike,
        count: int,
        vtype: FloatTypeName,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
        progress: Progress | None = None,
    ) -> FloatArray: ...
    @overload
    def read_array(
        self,
        address: AddressLike,
        count: int,
        vtype: IntTypeName = "uint16",
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
        progress: Progress | None = None,
    ) -> WordArray: ...
    @overload
    def read_array(
        self,
        address: AddressLike,
        count: int,
        vtype: str | ValueType,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
        progress: Progress | None = None,
    ) -> NumberArray: ...
    def read_array(
        self,
        address: AddressLike,
        count: int,
        vtype: str | ValueType = "uint16",
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
        progress: Progress | None = None,
    ) -> NumberArray:
        """Read ``count`` words (or numeric values of ``vtype``) into an :class:`array.array`
        (see :meth:`aiofins.Client.read_array`: ``array('H')`` of host-order words, NumPy
        views it with ``numpy.frombuffer(words, dtype=numpy.uint16)``). ``progress`` is
        called on the loop thread."""
        words: NumberArray = self._call_any(
            self.async_client.read_array,
            address,
            count,
            vtype,
            dest=dest,
            timeout=timeout,
            retries=retries,
            progress=progress,
        )
        return words

    def write_value(
        self, address: AddressLike, value: Value, vtype: str | ValueType = "uint16", **kw: Any
    ) -> None:
        """Write one typed value: ``plc.write_value("D200", 21.5, "float32")``."""
        self._call_any(self.async_client.write_value, address, value, vtype, **kw)

    def write_values(
        self, address: AddressLike, values: Sequence[Value], vtype: str | ValueType, **kw: Any
    ) -> None:
        """Write consecutive typed values."""
        self._call_any(self.async_client.write_values, address, values, vtype, **kw)

    # Each line below is one blocking method with the async method's signature; the test
    # suite checks that every public coroutine method of the async client is here.
    execute = _Blocking(AsyncClient.execute)
    execute_many = _Blocking(AsyncClient.execute_many)
    call = _Blocking(AsyncClient.call)
    read = _Blocking(AsyncClient.read)
    write = _Blocking(AsyncClient.write)
    write_array = _Blocking(AsyncClient.write_array)
    read_tags = _Blocking(AsyncClient.read_tags)
    memory_area_read = _Blocking(AsyncClient.memory_area_read)
    memory_area_write = _Blocking(AsyncClient.memory_area_write)
    memory_area_fill = _Blocking(AsyncClient.memory_area_fill)
    multiple_memory_area_read = _Blocking(AsyncClient.multiple_memory_area_read)
    memory_area_transfer = _Blocking(AsyncClient.memory_area_transfer)
    parameter_area_read = _Blocking(AsyncClient.parameter_area_read)
    parameter_area_write = _Blocking(AsyncClient.parameter_area_write)
    parameter_area_clear = _Blocking(AsyncClient.parameter_area_clear)
    program_area_read = _Blocking(AsyncClient.program_area_read)
    program_area_write = _Blocking(AsyncClient.program_area_write)
    program_area_clear = _Blocking(AsyncClient.program_area_clear)
    run = _Blocking(AsyncClient.run)
    stop = _Blocking(AsyncClient.stop)
    cpu_unit_data_read = _Blocking(AsyncClient.cpu_unit_data_read)
    connection_data_read = _Blocking(AsyncClient.connection_data_read)
    cpu_unit_status_read = _Blocking(AsyncClient.cpu_unit_status_read)
    cycle_time_read = _Blocking(AsyncClient.cycle_time_read)
    clock_read = _Blocking(AsyncClient.clock_read)
    clock_write = _Blocking(AsyncClient.clock_write)
    message_read = _Blocking(AsyncClient.message_read)
    message_clear = _Blocking(AsyncClient.message_clear)
    fal_fals_read = _Blocking(AsyncClient.fal_fals_read)
    access_right_acquire = _Blocking(AsyncClient.access_right_acquire)
    access_right_forced_acquire = _Blocking(AsyncClient.access_right_forced_acquire)
    access_right_release = _Blocking(AsyncClient.access_right_release)
    error_clear = _Blocking(AsyncClient.error_clear)
    error_log_read = _Blocking(AsyncClient.error_log_read)
    error_log_clear = _Blocking(AsyncClient.error_log_clear)
    fins_write_access_log_read = _Blocking(AsyncClient.fins_write_access_log_read)
    fins_write_access_log_clear = _Blocking(AsyncClient.fins_write_access_log_clear)
    file_name_read = _Blocking(AsyncClient.file_name_read)
    single_file_read = _Blocking(AsyncClient.single_file_read)
    single_file_write = _Blocking(AsyncClient.single_file_write)
    file_memory_format = _Blocking(AsyncClient.file_memory_format)
    file_delete = _Blocking(AsyncClient.file_delete)
    file_copy = _Blocking(AsyncClient.file_copy)
    file_name_change = _Blocking(AsyncClient.file_name_change)
    memory_area_file_transfer = _Blocking(AsyncClient.memory_area_file_transfer)
    parameter_area_file_transfer = _Blocking(AsyncClient.parameter_area_file_transfer)
    program_area_file_transfer = _Blocking(AsyncClient.program_area_file_transfer)
    create_delete_directory = _Blocking(AsyncClient.create_delete_directory)
    memory_cassette_transfer = _Blocking(AsyncClient.memory_cassette_transfer)
    forced_set_reset = _Blocking(AsyncClient.forced_set_reset)
    forced_set_reset_cancel = _Blocking(AsyncClient.forced_set_reset_cancel)
    convert_to_compoway_f_command = _Blocking(AsyncClient.convert_to_compoway_f_command)
    convert_to_modbus_rtu_command = _Blocking(AsyncClient.convert_to_modbus_rtu_command)
    convert_to_modbus_ascii_command = _Blocking(AsyncClient.convert_to_modbus_ascii_command)


def connect(
    url: str,
    *,
    backend: str | None = None,
    backend_options: Mapping[str, Any] | None = None,
    **options: Any,
) -> Client:
    """Connect to a PLC and return a blocking :class:`Client`.

    ``url`` and ``options`` are those of :func:`aiofins.connect` (``dest``, ``src``,
    ``timeout``, ``retries``, ...). Over UDP and FINS/TCP each call runs in the calling
    thread, one at a time (see the module). ``backend`` runs the async client on a private
    event loop in a thread of its own instead, where calls from several threads run
    concurrently: ``"asyncio"`` or ``"trio"`` (``backend_options={"use_uvloop": True}`` for
    uvloop); a serial line always does (on asyncio unless ``backend`` says). The connection
    is made before this returns: a bad URL or option raises here. Use it as a context
    manager, or call :meth:`Client.close`.
    """
    if (
        backend is None
        and backend_options is None
        and isinstance(url, str)
        and "transport" not in options
        and parse_endpoint(url).scheme in ("udp", "tcp")
    ):
        return _connect_direct(url, options)
    return _connect_on_loop(url, backend or "asyncio", backend_options, options)


def _connect_direct(url: str, options: dict[str, Any]) -> Client:
    """The client whose calls run in the calling thread on a blocking driver."""
    prepared = _prepare_blocking(url, options)
    session = prepared.session
    transport = session.transport
    assert isinstance(transport, BlockingTransport)
    driver = BlockingDriver(session, transport)
    try:
        driver.open(math.inf)  # bounded by the transport's own connect timeout
        # The async client on the driver: its coroutines complete without suspending.
        async_client = prepared.client(cast(Session, driver))
    except BaseException:
        driver.close()
        prepared.release()
        raise
    made: list[_DirectRunner] = []

    def runner(state: Callable[[], ClientState]) -> _DirectRunner:
        made.append(_DirectRunner(driver, state))
        return made[0]

    resources = ExitStack()
    resources.callback(prepared.release)
    client = Client(async_client, runner, resources)
    resources.callback(made[0].close)  # (first: callbacks run last in, first out)
    return client


def _prepare_blocking(url: str, options: dict[str, Any]) -> Prepared:
    """:func:`aiofins.connection.prepare` for a blocking transport, run to its end here; a
    host name is looked up in a thread of its own (``prepare`` looks names up through the
    event loop's resolver: the thread runs one for the purpose)."""

    def prepare_now() -> Coroutine[Any, Any, Prepared]:
        return prepare(url, source_held=False, blocking=True, **options)

    if not needs_lookup(parse_endpoint(url)):
        return run_to_end(prepare_now())
    box: list[Prepared | BaseException] = []

    def run() -> None:
        try:
            box.append(anyio.run(prepare_now))
        except BaseException as exc:
            box.append(exc)

    worker = threading.Thread(target=run, name="aiofins.sync.lookup", daemon=True)
    worker.start()
    worker.join()
    result = box[0]
    if isinstance(result, BaseException):
        raise result
    return result


def _connect_on_loop(
    url: str,
    backend: str,
    backend_options: Mapping[str, Any] | None,
    options: dict[str, Any],
) -> Client:
    """The client whose calls run on a private event loop in a thread of its own."""
    loop = _LoopThread(backend, backend_options)
    resources = ExitStack()
    resources.callback(loop.stop)
    try:
        manager: AbstractContextManager[AsyncClient] = loop.portal.wrap_async_context_manager(
            _async_connect(url, **options)
        )
        async_client = resources.enter_context(manager)
    except BaseException:
        resources.close()
        raise
    return Client(async_client, lambda state: _LoopRunner(loop, state), resources)
