"""The client: one coroutine per FINS command, plus word/bit/typed reads and writes of any size.

``Client`` sits on a :class:`~aiofins.session.Session`. Every command method builds the
operation's typed request (:mod:`aiofins.protocol.commands`), sends it through the session and
parses the response into the operation's typed result. :meth:`Client.read` and
:meth:`Client.write` take address text (``"D100"``, ``"CIO 0.01"``), split the transfer to the
route's limits and send the chunks pipelined.
"""

from __future__ import annotations

import asyncio
import enum
from array import array
from collections.abc import Callable, Coroutine, Mapping, Sequence
from contextlib import AbstractAsyncContextManager, AsyncExitStack
from types import TracebackType
from typing import Any, NoReturn, TypeVar, cast, overload

import anyio

from ._callplan import (
    FrameWords,
    ReadFrames,
    WriteFrames,
    cacheable,
    read_frames,
    start_address,
    typed_read,
    typed_start,
    value_type,
    write_frames,
)
from ._commands import CommandMethods
from .protocol.areas import MemoryAddress
from .protocol.arrays import (
    FloatArray,
    NumberArray,
    WordArray,
    array_to_words,
    array_type,
    words_to_array,
)
from .protocol.commands import Request, operation_for
from .protocol.commands.memory import MemoryAreaWrite
from .protocol.endcodes import NORMAL, EndCode
from .protocol.errors import (
    CommandError,
    ConnectionLost,
    DecodeError,
    EndCodeError,
    FinsTimeout,
)
from .protocol.guard import changes, check_read_only
from .protocol.header import FinsAddress
from .protocol.inputs import seconds, shown, whole_number
from .protocol.limits import RouteLimits, check_command, limits_for
from .protocol.values import (
    BoolTypeName,
    FloatTypeName,
    IntTypeName,
    Value,
    ValueType,
    WordOrder,
    parse_value_type,
    values_to_words,
    words_to_values,
)
from .session import Response, Session
from .session.response import end_code_of, response_of
from .tags import ReadPlan, compile_tags
from .transport.base import is_asyncio

R = TypeVar("R")

#: End codes that usually mean the FINS addresses (or routing tables) are wrong.
_ADDRESSING_END_CODES = frozenset({0x0105, 0x0201, 0x0202, 0x0205, 0x1004, 0x1005})


def _addressing_hint(dest: FinsAddress, source: FinsAddress) -> str:
    return (
        f"Check the FINS addresses: destination {dest} (DNA.DA1.DA2: the PLC's network, its "
        f"node number as set on its Ethernet/serial unit, unit 0 for the CPU) and source "
        f"{source} (SA1 must be a node the PLC accepts and no other client uses), and the "
        "routing tables for a remote network"
    )


#: Commands whose response with one of these end codes, when it carries data, still holds a
#: complete, shorter result: the records that exist. The manual (5-3-28) calls the end code
#: of a short ERROR LOG READ an "address range overflow", a name it gives 1103 in 5-3-30 and
#: the end-code table gives 1104, so both are taken.
_PARTIAL_RESULTS: dict[int, frozenset[int]] = {
    0x2102: frozenset({0x1103, 0x1104}),
    0x2140: frozenset({0x1103, 0x1104}),
}

AddressLike = str | MemoryAddress
#: ``progress(done, total)``: elements transferred so far, of ``total``.
Progress = Callable[[int, int], object]


class ClientState(enum.Enum):
    """The life of a :class:`Client` made by :func:`aiofins.connect`; :meth:`Client._move`
    makes every change. A client made on a session that is open already
    (``Client(session)``, a :class:`~aiofins.Pool`'s lease) is ``OPEN`` from the start: its
    session is opened and closed by its owner."""

    #: Made by ``connect()``, nothing opened yet: calls raise :class:`~aiofins.ConnectionLost`
    #: saying to ``await plc.open()`` (or to use ``async with``).
    NEW = "new"
    #: :meth:`Client.open` or ``async with`` is making the connection.
    OPENING = "opening"
    #: Connected: calls go to the PLC.
    OPEN = "open"
    #: :meth:`Client.aclose` (or leaving ``async with``) is under way: new calls raise
    #: ``ConnectionLost``, calls still waiting end with it.
    CLOSING = "closing"
    #: Closed, or the connection could not be made: calls raise ``ConnectionLost``. A client
    #: is opened once; ``aiofins.connect(url)`` makes a new one.
    CLOSED = "closed"


#: The changes :meth:`Client._move` allows.
_TRANSITIONS: dict[ClientState, frozenset[ClientState]] = {
    ClientState.NEW: frozenset({ClientState.OPENING, ClientState.CLOSED}),
    ClientState.OPENING: frozenset({ClientState.OPEN, ClientState.CLOSING, ClientState.CLOSED}),
    ClientState.OPEN: frozenset({ClientState.CLOSING}),
    ClientState.CLOSING: frozenset({ClientState.CLOSED}),
    ClientState.CLOSED: frozenset(),
}

#: What makes a client's connection: :func:`aiofins.connect`'s context manager, which yields
#: a client on the open session.
Opener = Callable[[], AbstractAsyncContextManager["Client"]]


class _NoSession:
    """Stands for the session of a client that is not open: any use of it says why."""

    def __init__(self, client: Client) -> None:
        self._client = client

    def __getattr__(self, name: str) -> NoReturn:
        raise ConnectionLost(self._client._not_open())


#: The tasks hosting the sessions of clients opened with :meth:`Client.open` under asyncio
#: (the event loop keeps only weak references to tasks).
_HOSTS: set[asyncio.Task[None]] = set()


def _spawn_host(run: Callable[[], Coroutine[Any, Any, None]]) -> None:
    """Start ``run`` in a task of its own, outside the caller's task group and cancel scopes:
    a client opened with :meth:`Client.open` may be closed from any task, in any order."""
    if is_asyncio():
        task = asyncio.get_running_loop().create_task(run())
        _HOSTS.add(task)
        task.add_done_callback(_HOSTS.discard)
    else:  # trio: the run's system nursery, as a task group outlives no caller
        import trio

        trio.lowlevel.spawn_system_task(run)


class Client(CommandMethods):
    """A FINS client for one PLC (``dest``), over one session.

    Options: ``dest`` (the PLC's FINS address; per call too), ``limits`` (the route's
    :class:`RouteLimits`, Ethernet by default), ``routes`` (limits per destination network,
    for destinations behind gateways: ``{3: limits_for(NetworkType.SYSMAC_LINK)}``; a
    network not in it, and network 0, take ``limits``), ``word_order`` for typed values
    (Omron's CDAB by default). Every command is checked against its destination's route
    before it is sent (:func:`~aiofins.protocol.limits.check_command`). CPU error flags of
    the last response (end code bits 6/7) are in :attr:`last_end_code`; they are not raised.

    A client made by :func:`aiofins.connect` is opened and closed either with ``async with``
    or explicitly, for a client kept in an object of its own (a service class)::

        plc = aiofins.connect(url)
        await plc.open()
        ...
        await plc.aclose()

    Used before :meth:`open` or after :meth:`aclose`, a call raises
    :class:`~aiofins.ConnectionLost` saying so; :attr:`state` tells where it stands.
    """

    def __init__(
        self,
        session: Session,
        *,
        dest: FinsAddress | str | None = None,
        limits: RouteLimits | None = None,
        routes: Mapping[int, RouteLimits] | None = None,
        word_order: WordOrder | str = WordOrder.LOW_FIRST,
        read_only: bool = False,
    ) -> None:
        self.session = session
        self.dest = session.dest if dest is None else FinsAddress.of(dest)
        #: The limits of a destination network not in :attr:`routes` (and of network 0).
        self.default_limits = limits if limits is not None else limits_for()
        #: Limits per destination network (its route's smallest, manual 5-2-2).
        self.routes: dict[int, RouteLimits] = dict(routes or {})
        #: The limits of the route to :attr:`dest` (what bulk transfers and tag plans use).
        network = self.dest.network
        self.limits = (
            self.routes.get(network, self.default_limits) if network else self.default_limits
        )
        self.word_order = WordOrder.parse(word_order)
        #: Refuse every command that changes the PLC (:class:`ReadOnlyError`, nothing sent).
        self.read_only = read_only
        #: End code of the latest normal response (look here for the 0040/0080 flags).
        self.last_end_code: EndCode | None = None
        self._twin: Client | None = None
        self._state = ClientState.OPEN
        self._opener: Opener | None = None
        self._where = ""
        self._stack: AsyncExitStack | None = None
        self._host_scope: anyio.CancelScope | None = None
        self._opened: anyio.Event | None = None
        self._close_asked: anyio.Event | None = None
        self._closed: anyio.Event | None = None
        self._failure: Exception | None = None

    @classmethod
    def unopened(cls, opener: Opener, where: str) -> Client:
        """A client in state ``NEW`` whose connection ``opener`` makes when it is opened
        (what :func:`aiofins.connect` returns; ``where`` names the PLC in errors). Its
        ``dest``, ``limits``, ``word_order`` and ``read_only`` are those of the connection
        once open, and so are its ``routes``."""
        client = cls.__new__(cls)
        Client.__init__(client, cast(Session, _NoSession(client)), dest=FinsAddress(0, 0, 0))
        client._state = ClientState.NEW
        client._opener = opener
        client._where = where
        return client

    # -- lifecycle ----------------------------------------------------------------------

    @property
    def state(self) -> ClientState:
        """Where the client stands in its life (see :class:`ClientState`)."""
        return self._state

    def _move(self, to: ClientState) -> None:
        """The one place the state changes; a change :data:`_TRANSITIONS` does not allow is a
        :class:`CommandError` naming both states."""
        if to not in _TRANSITIONS[self._state]:
            raise CommandError(self._refusal(to))
        self._state = to
        if to is ClientState.CLOSED:
            self.session = cast(Session, _NoSession(self))

    def _refusal(self, to: ClientState) -> str:
        where = f"the client of {self._where}"
        if to is ClientState.OPENING and self._state is ClientState.OPEN:
            return f"{where} is open already"
        if to is ClientState.OPENING and self._state is ClientState.OPENING:
            return f"{where} is being opened already"
        if to is ClientState.OPENING:
            return f"{where} is {self._state.value}: aiofins.connect(url) makes a new client"
        return f"{where} cannot go from {self._state.value} to {to.value}"

    def _not_open(self) -> str:
        """What a call on a client that is not open says."""
        where = f"the client of {self._where}"
        state = self._state
        if state is ClientState.NEW:
            return (
                f"{where} is not open: await plc.open() first (and await plc.aclose() when "
                "done), or use async with aiofins.connect(url) as plc"
            )
        if state is ClientState.OPENING:
            return f"{where} is still opening: await plc.open() returns once it is open"
        if state is ClientState.CLOSING:
            return f"{where} is closing"
        return f"{where} is closed: aiofins.connect(url) makes a new client"

    def _owned(self) -> Opener:
        """The opener of a client made by ``connect()``; a client on someone else's session
        is refused (a Pool's lease is given back by leaving ``async with pool.client()``)."""
        if self._opener is None:
            raise CommandError(
                "this client runs on a session opened elsewhere (Client(session), a Pool's "
                "lease): its owner opens and closes it; a lease is given back by leaving "
                "async with pool.client(url)"
            )
        return self._opener

    def _adopt(self, inner: Client) -> None:
        """Take the session and settings of the client ``opener`` made."""
        self.session = inner.session
        self.dest = inner.dest
        self.limits = inner.limits
        self.default_limits = inner.default_limits
        self.routes = inner.routes
        self.word_order = inner.word_order
        self.read_only = inner.read_only

    async def open(self) -> Client:
        """Open the connection (the transport and its session); returns this client.

        The session runs in a task of its own, so :meth:`aclose` may be called from any
        task and clients closed in any order. An error opening (a bad URL or option, a
        FINS/TCP connection refused) is raised here and leaves the client ``CLOSED``.
        """
        opener = self._owned()
        self._move(ClientState.OPENING)
        self._opened, self._close_asked, self._closed = anyio.Event(), anyio.Event(), anyio.Event()
        self._host_scope = anyio.CancelScope()
        _spawn_host(lambda: self._host(opener))
        try:
            await self._opened.wait()
        except BaseException:  # the caller gave up: the connection is not wanted
            self._host_scope.cancel()
            raise
        if self._failure is not None:
            failure, self._failure = self._failure, None
            raise failure
        return self

    async def _host(self, opener: Opener) -> None:
        """The task of an :meth:`open`-ed client: holds its connection open until
        :meth:`aclose` asks; no error leaves it (:meth:`open` raises one met opening)."""
        assert self._opened is not None and self._close_asked is not None
        assert self._closed is not None and self._host_scope is not None
        try:
            with self._host_scope:
                async with opener() as inner:
                    self._adopt(inner)
                    self._move(ClientState.OPEN)
                    self._opened.set()
                    await self._close_asked.wait()
        except Exception as exc:
            if not self._opened.is_set():
                self._failure = exc
        finally:
            if self._state is ClientState.OPEN:  # cancelled from outside: the loop ends
                self._move(ClientState.CLOSING)
            if self._state is not ClientState.CLOSED:
                self._move(ClientState.CLOSED)
            self._opened.set()
            self._closed.set()

    async def aclose(self) -> None:
        """Close the connection: calls still waiting end with
        :class:`~aiofins.ConnectionLost`, later ones raise it. Closing a closed client (or
        one never opened) does nothing."""
        self._owned()
        state = self._state
        if state is ClientState.NEW:
            self._move(ClientState.CLOSED)
            return
        if self._stack is not None:  # opened by async with: left here, in its task
            await self.__aexit__(None, None, None)
            return
        if state in (ClientState.OPENING, ClientState.OPEN):
            self._move(ClientState.CLOSING)
            if self._host_scope is not None and state is ClientState.OPENING:
                self._host_scope.cancel()
            if self._close_asked is not None:
                self._close_asked.set()
        if self._closed is not None:
            with anyio.CancelScope(shield=True):
                await self._closed.wait()

    async def __aenter__(self) -> Client:
        opener = self._owned()
        self._move(ClientState.OPENING)
        stack = AsyncExitStack()
        try:
            inner = await stack.enter_async_context(opener())
        except BaseException:
            self._move(ClientState.CLOSED)
            raise
        self._stack = stack
        self._adopt(inner)
        self._move(ClientState.OPEN)
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> bool | None:
        stack, self._stack = self._stack, None
        if stack is None:  # closed already (aclose() in the block)
            return None
        self._move(ClientState.CLOSING)
        try:
            return await stack.__aexit__(exc_type, exc, tb)
        finally:
            self._move(ClientState.CLOSED)

    def with_read_only(self, read_only: bool = True) -> Client:
        """This client, or a twin on the same session whose only difference is
        ``read_only`` (made once): how a :class:`Pool` lends one session to borrowers that
        differ in ``?read_only=``."""
        if read_only == self.read_only:
            return self
        twin = self._twin
        if twin is None:
            twin = Client(
                self.session,
                dest=self.dest,
                limits=self.default_limits,
                routes=self.routes,
                read_only=read_only,
            )
            twin.word_order = self.word_order
            twin._twin = self
            self._twin = twin
        return twin

    def route_to(self, dest: FinsAddress | str | None = None) -> RouteLimits:
        """The limits of the route to ``dest`` (the client's own by default)."""
        if dest is None:
            return self.limits
        network = FinsAddress.of(dest).network
        if network == self.dest.network:
            return self.limits
        return self.routes.get(network, self.default_limits) if network else self.default_limits

    def guard(self, operation: type[Request[Any]]) -> None:
        """Raise :class:`ReadOnlyError` now if this client is read-only and ``operation``
        changes the PLC: a transfer of several steps (restore, upload) calls it before its
        first frame, even a read, so that a refused transfer sends nothing at all."""
        if self.read_only:
            check_read_only(operation.MRC, operation.SRC, b"", operation.NAME)

    # -- raw and typed requests ---------------------------------------------------------

    async def execute(
        self,
        mrc: int,
        src: int,
        params: bytes = b"",
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
        idempotent: bool = False,
    ) -> Response:
        """Send a raw command (MRC, SRC, parameter bytes); returns the response frame.

        Non-normal end codes raise :class:`~aiofins.EndCodeError` subclasses.
        """
        if retries is not None or (
            timeout is not None and (type(timeout) is not float or not timeout > 0.0)
        ):  # checked unless a positive float (NaN is not > 0): one comparison per call
            timeout, retries = _call_options(timeout, retries)
        if self.read_only:
            _check_read_only(mrc, src, params)
        target = self._target(dest)
        check_command(self.limits if dest is None else self.route_to(target), mrc, src, params)
        session = self.session
        try:  # the session's request path: begin, one await, finish (see Session.begin)
            p = session.begin(mrc, src, params, target, timeout, idempotent, retries)
            if p is not None:
                try:
                    frame = p.reply or await (p.fut or p.wait())
                except BaseException as exc:
                    await session.failed(p, exc, timeout)
            if p is None or not session.finish(p, frame):  # a wait first, or busy
                frame = await session.call(
                    mrc, src, params, target, timeout, idempotent, retries, after=p
                )
        except EndCodeError as exc:
            self._add_addressing_hint(exc, target)
            raise
        except FinsTimeout as exc:
            add_route_hint(exc, target, session.source)
            raise
        response = response_of(frame)
        self.last_end_code = response.end_code
        return response

    async def execute_many(
        self,
        commands: Sequence[tuple[int, int, bytes]],
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
        idempotent: bool = False,
    ) -> list[Response]:
        """Send raw commands pipelined from this one task; their responses in order.

        See :meth:`Session.request_many`; the first error is raised as by :meth:`execute`.
        """
        if retries is not None or (
            timeout is not None and (type(timeout) is not float or not timeout > 0.0)
        ):
            timeout, retries = _call_options(timeout, retries)
        if self.read_only:
            for mrc, src, params in commands:
                _check_read_only(mrc, src, params)
        route = self.route_to(dest)
        for mrc, src, params in commands:
            check_command(route, mrc, src, params)
        return await self._execute_many(
            commands, dest, timeout, retries, None, idempotent=idempotent
        )

    async def _execute_many(
        self,
        commands: Sequence[tuple[int, int, bytes]],
        dest: FinsAddress | str | None,
        timeout: float | None,
        retries: int | None,
        on_response: Callable[[int, Response], object] | None,
        on_frame: Callable[[int, bytes], object] | None = None,
        idempotent: bool = True,
    ) -> list[Response]:
        """:meth:`execute_many` without the read-only check (reads call it directly), with
        the session's ``on_response`` or ``on_frame`` (then no response is returned)."""
        if retries is not None or (
            timeout is not None and (type(timeout) is not float or not timeout > 0.0)
        ):  # checked unless a positive float (NaN is not > 0): one comparison per call
            timeout, retries = _call_options(timeout, retries)
        target = self._target(dest)
        try:
            responses = await self.session.request_many(
                commands,
                dest=target,
                timeout=timeout,
                idempotent=idempotent,
                retries=retries,
                on_response=on_response,
                on_frame=on_frame,
            )
        except EndCodeError as exc:
            self._add_addressing_hint(exc, target)
            raise
        except FinsTimeout as exc:
            add_route_hint(exc, target, self.session.source)
            raise
        if responses:
            self.last_end_code = responses[-1].end_code
        return responses

    def _target(self, dest: FinsAddress | str | None) -> FinsAddress:
        """The destination of a call: the client's, or ``dest`` (``"NET.NODE.UNIT"`` too)."""
        return self.dest if dest is None else FinsAddress.of(dest)

    def _add_addressing_hint(self, exc: EndCodeError, target: FinsAddress) -> None:
        add_addressing_hint(exc, target, self.session.source)

    async def call(
        self,
        request: Request[R],
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> R:
        """Send a typed request and parse its response into the operation's result.

        Log reads (2102, 2140) asked for more records than are stored answer them all with end
        code 1104 (manual 5-3-28/5-3-30); that is returned as a result, with the end code
        left in :attr:`last_end_code`.
        """
        try:
            response = await self.execute(
                request.MRC,
                request.SRC,
                request.encode(),
                dest=dest,
                timeout=timeout,
                retries=retries,
                idempotent=request.IDEMPOTENT,
            )
        except EndCodeError as exc:
            partial = _PARTIAL_RESULTS.get((request.MRC << 8) | request.SRC)
            if partial is None or exc.end_code.code not in partial or not exc.data:
                raise
            self.last_end_code = exc.end_code
            return request.decode_response(exc.data)
        return request.decode_response(response.data)

    # -- words and bits -----------------------------------------------------------------

    async def read(
        self,
        address: AddressLike,
        count: int = 1,
        *,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
        progress: Progress | None = None,
    ) -> list[int]:
        """Read ``count`` elements from ``address`` (words, or 0/1 for bits), any size.

        Transfers over the route's limit go as several 0101 frames, sent pipelined (up to the
        session's in-flight cap) and reassembled in order. ``progress(done, total)`` is called
        with the elements read so far as each frame's reply comes in (under asyncio from the
        session's receive callback: keep it short); an exception it raises ends the read
        and is raised here.
        """
        if type(count) is not int or count < 0:
            count = whole_number("count", count, 0)
        if dest is None and (type(address) is str or type(address) is MemoryAddress):
            plan = read_frames(address, count, self.limits.memory_read_words)  # (_read_plan's
            # usual case inlined: a call less per read)
        else:
            plan = self._read_plan(address, count, dest)
        commands = plan.commands
        if len(commands) == 1:  # the usual read: one frame, no extra coroutine
            mrc, src, params = commands[0]
            if retries is not None or (
                timeout is not None and (type(timeout) is not float or not timeout > 0.0)
            ):  # checked as execute() checks them
                timeout, retries = _call_options(timeout, retries)
            target = self.dest if dest is None else FinsAddress.of(dest)
            session = self.session
            try:  # the session's request path: begin, one await, finish (no coroutine)
                p = session.begin(mrc, src, params, target, timeout, True, retries)
                if p is not None:
                    try:
                        frame = p.reply or await (p.fut or p.wait())
                    except BaseException as exc:
                        await session.failed(p, exc, timeout)
                if p is None or not session.finish(p, frame):  # a wait first, or busy
                    frame = await session.call(
                        mrc, src, params, target, timeout, True, retries, after=p
                    )
            except EndCodeError as exc:
                self._add_addressing_hint(exc, target)
                raise
            except FinsTimeout as exc:
                add_route_hint(exc, target, session.source)
                raise
            # (a normal end code, 0000, read without a call: the usual case)
            self.last_end_code = end_code_of(frame) if frame[12] or frame[13] else NORMAL
            if progress is not None:
                progress(count, count)
            return plan.one(frame)
        if plan.element_size == 2:  # words: each frame's data copied once into an array
            words = await self._fetch_words(plan, dest, timeout, retries, progress)
            return words.tolist()
        return plan.values(await self._fetch(plan, dest, timeout, retries, progress))

    def _read_plan(
        self, address: AddressLike, count: int, dest: FinsAddress | str | None
    ) -> ReadFrames:
        """The 0101 frames of ``count`` elements from ``address`` to ``dest`` (the one place
        :meth:`read` and :meth:`read_array` take their chunking from)."""
        limit = (self.limits if dest is None else self.route_to(dest)).memory_read_words
        if cacheable(address):
            return read_frames(address, count, limit)
        return read_frames(start_address(address, count), count, limit)

    def _write_plan(
        self, address: AddressLike, count: int, dest: FinsAddress | str | None
    ) -> WriteFrames:
        """The 0102 frames of a write of ``count`` elements from ``address`` to ``dest``
        (the one place :meth:`write` and :meth:`write_array` take their chunking from)."""
        limit = (self.limits if dest is None else self.route_to(dest)).memory_write_words
        if cacheable(address):
            return write_frames(address, count, limit)
        return write_frames(start_address(address, count), count, limit)

    async def _fetch(
        self,
        plan: ReadFrames,
        dest: FinsAddress | str | None,
        timeout: float | None,
        retries: int | None,
        progress: Progress | None,
    ) -> list[bytes]:
        """The reply data of every frame of ``plan``, in order (pipelined, reported to
        ``progress`` frame by frame as the replies come in)."""
        commands = plan.commands
        if progress is None:
            responses = await self._execute_many(commands, dest, timeout, retries, None)
            return [response.data for response in responses]
        counts = plan.counts
        count = sum(counts)
        done = 0

        def report(index: int, _response: Response) -> None:
            nonlocal done
            done += counts[index]
            progress(done, count)

        responses = await self._execute_many(commands, dest, timeout, retries, report)
        return [response.data for response in responses]

    async def _fetch_words(
        self,
        plan: ReadFrames,
        dest: FinsAddress | str | None,
        timeout: float | None,
        retries: int | None,
        progress: Progress | None,
    ) -> WordArray:
        """The words of every frame of ``plan`` (a read of words) in one ``array('H')``:
        the batch hands each reply frame to :meth:`FrameWords.put`, which copies its data
        into place (no :class:`Response` per frame), reported to ``progress`` as it comes."""
        sink = FrameWords(plan, progress)
        try:
            await self._execute_many(plan.commands, dest, timeout, retries, None, sink.put)
        finally:
            sink.release()
        last = sink.last
        if last is not None:  # the last command's end code, as for any call
            self.last_end_code = end_code_of(last) if last[12] or last[13] else NORMAL
        return sink.words()

    async def write(
        self,
        address: AddressLike,
        values: Sequence[int],
        *,
        allow_split: bool = False,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
        progress: Progress | None = None,
    ) -> None:
        """Write words (or 0/1 bits) from ``address``.

        A write over the route's limit needs several frames and is therefore **not atomic**:
        the PLC's program may run between them and see half-old, half-new data, and a failure
        midway leaves a partial write. It is refused unless ``allow_split=True``. The frames
        go one after another; ``progress(done, total)`` is called with the elements written
        so far after each.
        """
        if type(values) is not list and type(values) is not tuple:
            _check_words(values)
        count = len(values)
        plan = self._write_plan(address, count, dest)

        def params_of(index: int) -> bytes:
            try:
                return plan.params(index, values)
            except CommandError as exc:
                raise unfit_word(exc, address, values, plan.element_size) from None

        await self._send_writes(plan, params_of, count, allow_split, dest, timeout, retries,
                                progress)  # fmt: skip

    async def _send_writes(
        self,
        plan: WriteFrames,
        params_of: Callable[[int], bytes],
        count: int,
        allow_split: bool,
        dest: FinsAddress | str | None,
        timeout: float | None,
        retries: int | None,
        progress: Progress | None,
    ) -> None:
        """Send the 0102 frames of ``plan`` one after another (``params_of(i)``: frame
        ``i``'s parameters), refusing a split write unless ``allow_split``."""
        frames = plan.frames
        if len(frames) > 1 and not allow_split:
            raise CommandError(
                f"writing {count} elements needs {len(frames)} frames on this route "
                f"(limit {plan.limit}); such a write is not atomic — pass "
                "allow_split=True to accept that"
            )
        if not frames:  # count 0: a normal response that writes nothing (manual 5-3-3)
            await self.call(
                MemoryAreaWrite(plan.start, b""), dest=dest, timeout=timeout, retries=retries
            )
        for i, (offset, n, _) in enumerate(frames):
            params = params_of(i)
            response = await self.execute(
                0x01, 0x02, params, dest=dest, timeout=timeout, retries=retries
            )
            if response.data:
                raise DecodeError(
                    f"{MemoryAreaWrite.NAME}: expected no response data, got "
                    f"{len(response.data)} bytes"
                )
            if progress is not None:
                progress(offset + n, count)

    async def read_bit(self, address: AddressLike, **kw: Any) -> bool:
        """Read one bit (``"CIO 0.01"``) as a bool."""
        return bool((await self.read(address, 1, **kw))[0] & 1)

    # -- big data: arrays ---------------------------------------------------------------

    @overload
    async def read_array(
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
    async def read_array(
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
    async def read_array(
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
    async def read_array(
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
        """Read ``count`` words (or values of a numeric ``vtype``) into an :class:`array.array`.

        ``await plc.read_array("D0", 32768)`` is ``read("D0", 32768)`` without a Python
        ``int`` per word: an ``array('H')`` of the word values (``words[0]`` from
        ``address``) in the host's byte order, which NumPy views without a copy
        (``numpy.frombuffer(words, dtype=numpy.uint16)``). With ``vtype`` (``"float32"``,
        ``"int32:ABCD"``, ...; the client's word order unless the spec names one) it reads
        ``count`` values of that type as :func:`~aiofins.words_to_array` decodes them
        (``array('f')`` for ``float32``). The frames, the pipelining and ``progress``
        (words read so far) are :meth:`read`'s.
        """
        if type(count) is not int or count < 0:
            count = whole_number("count", count, 0)
        t = array_type(self._type(vtype))  # the spec parsed once per client word order
        words = t.words * count
        if not cacheable(address):
            start_address(address, words)  # says what is wrong with the address
        start = typed_start(address, t, count)
        plan = self._read_plan(start, words, dest)
        out = await self._fetch_words(plan, dest, timeout, retries, progress)
        if t.kind == "uint16":  # one word per value, whatever the word order
            return out
        return words_to_array(out, t)

    async def write_array(
        self,
        address: AddressLike,
        values: NumberArray | Sequence[int | float] | Any,
        vtype: str | ValueType = "uint16",
        *,
        allow_split: bool = False,
        dest: FinsAddress | str | None = None,
        timeout: float | None = None,
        retries: int | None = None,
        progress: Progress | None = None,
    ) -> None:
        """Write an :class:`array.array` of words (or of values of a numeric ``vtype``).

        ``values``: an ``array('H')`` of word values in the host's byte order (as
        :meth:`read_array` returns it; a NumPy ``uint16`` array too), sent without a Python
        object per word; with ``vtype`` an array (or buffer, or sequence) of that type's
        values, stored as :func:`~aiofins.array_to_words` says. Frames, ``allow_split`` and
        ``progress`` (words written so far) are :meth:`write`'s.
        """
        t = array_type(self._type(vtype))
        if t.kind == "uint16" and isinstance(values, array) and values.typecode == "H":
            words = values  # sent as it is (each frame's share is swapped in a copy)
        else:
            words = array_to_words(values, t)
        count = len(words)
        if not cacheable(address):
            start_address(address, count)  # says what is wrong with the address
        start = typed_start(address, t, count // t.words)
        plan = self._write_plan(start, count, dest)
        await self._send_writes(plan, lambda index: plan.array_params(index, words), count,
                                allow_split, dest, timeout, retries, progress)  # fmt: skip

    # -- typed values -------------------------------------------------------------------

    def _type(self, vtype: str | ValueType) -> ValueType:
        if isinstance(vtype, ValueType):
            return vtype
        try:
            return value_type(vtype, self.word_order)
        except TypeError:  # unhashable: let the parser say what it takes
            return parse_value_type(vtype, default_word_order=self.word_order)

    @overload
    async def read_value(self, address: AddressLike, vtype: FloatTypeName, **kw: Any) -> float: ...
    @overload
    async def read_value(self, address: AddressLike, vtype: BoolTypeName, **kw: Any) -> bool: ...
    @overload
    async def read_value(
        self, address: AddressLike, vtype: IntTypeName = "uint16", **kw: Any
    ) -> int: ...
    @overload
    async def read_value(
        self, address: AddressLike, vtype: str | ValueType, **kw: Any
    ) -> Value: ...
    async def read_value(
        self, address: AddressLike, vtype: str | ValueType = "uint16", **kw: Any
    ) -> Value:
        """Read one typed value: ``await plc.read_value("D200", "float32")``.

        Its static type follows a literal type name (``float`` for ``"float32"``, ``int`` for
        ``"int32"`` or ``"bcd16"``, ``bool`` for ``"bit"``); other specs (``"string:8"``,
        ``"float32:ABCD"``, a :class:`ValueType`) give the union :data:`Value`.
        """
        if cacheable(address) and (type(vtype) is str or isinstance(vtype, ValueType)):
            plan = typed_read(address, vtype, 1, self.word_order.value)
            value: Value = plan.decode(await self.read(plan.start, plan.words, **kw))[0]
            return value
        return (await self.read_values(address, vtype, 1, **kw))[0]

    @overload
    async def read_values(
        self, address: AddressLike, vtype: FloatTypeName, count: int, **kw: Any
    ) -> list[float]: ...
    @overload
    async def read_values(
        self, address: AddressLike, vtype: BoolTypeName, count: int, **kw: Any
    ) -> list[bool]: ...
    @overload
    async def read_values(
        self, address: AddressLike, vtype: IntTypeName, count: int, **kw: Any
    ) -> list[int]: ...
    @overload
    async def read_values(
        self, address: AddressLike, vtype: str | ValueType, count: int, **kw: Any
    ) -> list[Value]: ...
    async def read_values(
        self, address: AddressLike, vtype: str | ValueType, count: int, **kw: Any
    ) -> list[Any]:  # list[Value], of the one type the overloads name
        """Read ``count`` consecutive typed values (typed as :meth:`read_value` says)."""
        if cacheable(address) and (type(vtype) is str or isinstance(vtype, ValueType)):
            plan = typed_read(address, vtype, count, self.word_order.value)
            return plan.decode(await self.read(plan.start, plan.words, **kw))
        t = self._type(vtype)  # what is wrong with the address: read() says it
        return words_to_values(t, await self.read(address, t.words * count, **kw))

    async def write_value(
        self, address: AddressLike, value: Value, vtype: str | ValueType = "uint16", **kw: Any
    ) -> None:
        """Write one typed value: ``await plc.write_value("D200", 21.5, "float32")``."""
        await self.write_values(address, [value], vtype, **kw)

    async def write_values(
        self, address: AddressLike, values: Sequence[Value], vtype: str | ValueType, **kw: Any
    ) -> None:
        """Write consecutive typed values."""
        t = self._type(vtype)
        start = typed_start(address, t, len(values)) if cacheable(address) else address
        await self.write(start, values_to_words(t, values), **kw)

    # -- tag lists ----------------------------------------------------------------------

    def compile_tags(self, tags: Mapping[str, str], *, max_gap: int = 8) -> ReadPlan:
        """Compile a tag list for this client's route limits (inspect it, reuse it)."""
        return compile_tags(
            tags,
            max_read_words=self.limits.memory_read_words,
            max_multiple_elements=self.limits.multiple_read_elements,
            max_gap=max_gap,
        )

    async def read_tags(
        self,
        tags: Mapping[str, str] | ReadPlan,
        *,
        timeout: float | None = None,
        errors: dict[str, str] | None = None,
    ) -> dict[str, Value]:
        """Read a tag list (``{"temp": "D100:float32", "run": "CIO 0.01"}``) in few frames.

        A tag whose words are no value of its type (invalid BCD, a string not in its
        encoding) raises :class:`DecodeError` naming it; given ``errors``, it is left out of
        the result instead and ``errors[name]`` says why.
        """
        if isinstance(tags, ReadPlan):
            plan = tags
            if plan.cache.get("fits") is not self.limits:  # checked once per plan and limits
                self._check_plan_fits(plan)
        else:
            plan = self.compile_tags(tags)
        n_runs = len(plan.runs)
        if n_runs == 1 and not plan.multiple:  # the usual small list: one frame, no task
            mrc, src, params, _, _ = plan.run_read(0)
            if timeout is not None and (type(timeout) is not float or not timeout > 0.0):
                timeout, _ = _call_options(timeout, None)  # checked as execute() checks it
            session = self.session
            try:  # (the session's request path directly: no coroutine per scan)
                p = session.begin(mrc, src, params, self.dest, timeout, True)
                if p is not None:
                    try:
                        frame = p.reply or await (p.fut or p.wait())
                    except BaseException as exc:
                        await session.failed(p, exc, timeout)
                if p is None or not session.finish(p, frame):  # a wait first, or busy
                    frame = await session.call(mrc, src, params, self.dest, timeout, True, after=p)
            except EndCodeError as exc:
                self._add_addressing_hint(exc, self.dest)
                raise
            self.last_end_code = end_code_of(frame)
            return plan.decode((plan.run_words(0, frame[14:]),), (), errors)
        commands, multiple = plan.scan_commands()
        responses = await self.execute_many(commands, timeout=timeout, idempotent=True)
        run_words = [plan.run_words(i, responses[i].data) for i in range(n_runs)]
        multi: list[Sequence[int]] = [
            [item.value for item in m.decode_response(response.data).items]
            for m, response in zip(multiple, responses[n_runs:], strict=True)
        ]
        return plan.decode(run_words, multi, errors)

    def _check_plan_fits(self, plan: ReadPlan) -> None:
        """Refuse a plan compiled for larger frames than this client's route carries."""
        sizes: tuple[int, int] | None = plan.cache.get("sizes")
        if sizes is None:
            sizes = plan.cache["sizes"] = (
                max((run.count for run in plan.runs), default=0),
                max((len(frame) for frame in plan.multiple), default=0),
            )
        limits = self.limits
        too_big = []
        if sizes[0] > limits.memory_read_words:
            too_big.append(
                f"0101 frames of up to {sizes[0]} words (the route carries "
                f"{limits.memory_read_words})"
            )
        if sizes[1] > limits.multiple_read_elements:
            too_big.append(
                f"0104 frames of up to {sizes[1]} elements (the route carries "
                f"{limits.multiple_read_elements})"
            )
        if too_big:
            raise CommandError(
                f"the tag plan has {' and '.join(too_big)}: compile it with this client "
                "(compile_tags)"
            )
        plan.cache["fits"] = limits


def add_route_hint(exc: FinsTimeout, target: FinsAddress, source: FinsAddress) -> None:
    """A routed request (DNA not 0) sent with source network 0 gets no reply through a
    gateway: the destination answers onto its own network. Its timeout says so."""
    if target.network and not source.network:
        exc.args = (
            f"{exc}. The request went to network {target.network} with source network 0: "
            "the PLC answers onto its own network, where we are not; give our network "
            "(connect(..., source_network=N), ?source_network=N or src=N.NODE.0)",
        )


def add_addressing_hint(exc: EndCodeError, target: FinsAddress, source: FinsAddress) -> None:
    """End codes that usually mean wrong node addressing (a request from ``source`` to
    ``target``) say which addresses to check."""
    if exc.end_code.code in _ADDRESSING_END_CODES:
        exc.args = (f"{exc}. {_addressing_hint(target, source)}",)


def unfit_word(
    error: CommandError, address: AddressLike, values: Sequence[object], size: int
) -> CommandError:
    """``error`` (a value :meth:`Client.write` cannot put in a word) as a message that names
    the typed write taking the value: a word holds a whole number 0..65535."""
    if size != 2:
        return error
    for value in values:
        fix = type_for_value(value)
        if fix is not None:
            kind, what = fix
            text = shown(value)
            return CommandError(
                f"{text} is no word value (a word holds a whole number 0..65535); to write it "
                f"as {what}, use write_value({str(address)!r}, {text}, {kind!r}) "
                f"(write_values for several; on the command line: --type {kind})"
            )
    return error


def type_for_value(value: object) -> tuple[str, str] | None:
    """The value type that holds ``value`` where a word cannot, and what it is
    (``("float32", "a REAL (2 words; ...)")``); ``None`` for a word value or no value."""
    if isinstance(value, str):
        return (
            f"string:{max(2, len(value) + len(value) % 2)}",
            "text (one word per two characters)",
        )
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    if isinstance(value, float):
        return ("float32", "a REAL (2 words; 'float64' for an LREAL, 4 words)")
    if 0 <= value <= 0xFFFF:
        return None
    if -0x8000 <= value < 0:
        return ("int16", "an INT (1 word)")
    if -0x80000000 <= value <= 0xFFFFFFFF:
        return ("int32", "a DINT (2 words)") if value < 0 else ("uint32", "a UDINT (2 words)")
    if -(1 << 63) <= value < 1 << 64:
        return ("int64", "an LINT (4 words)") if value < 0 else ("uint64", "a ULINT (4 words)")
    return None


def _call_options(timeout: float | None, retries: int | None) -> tuple[float | None, int | None]:
    """A call's ``timeout`` and ``retries``, checked (NaN would disable the deadline;
    ``math.inf`` is no time limit, which a call may ask for)."""
    return (
        None if timeout is None else seconds("timeout", timeout, allow_inf=True),
        None if retries is None else whole_number("retries", retries, 0),
    )


def _check_words(values: object) -> None:
    """``values`` of :meth:`Client.write` must be a sequence of element values."""
    if isinstance(values, (bytes, bytearray, memoryview)):
        raise CommandError(
            f"values must be a sequence of word (or bit) values, got {type(values).__name__}: "
            "pass list(data) for one element per byte, or memory_area_write(address, data) "
            "for the raw bytes"
        )
    if isinstance(values, str) or not isinstance(values, Sequence):
        raise CommandError(
            "values must be a sequence of word (or bit) values such as [1, 2, 3]; "
            f"got {shown(values)}"
        )


def _check_read_only(mrc: int, src: int, params: bytes) -> None:
    """:func:`check_read_only`, naming the command as the manual does."""
    if changes(mrc, src, params) is not None:
        try:
            name = operation_for(mrc, src, params).NAME
        except DecodeError:
            name = ""
        check_read_only(mrc, src, params, name)
