"""UDP under an asyncio loop without ``add_reader`` (as Windows' proactor loop): the same
session tests as tests/session/test_session_udp.py, on a selector loop whose public
``add_reader``/``add_writer`` raise ``NotImplementedError`` as the proactor loop's do."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any

import pytest

from aiofins.protocol.header import FinsAddress
from aiofins.session import Session
from aiofins.transport import UdpTransport
from aiofins.transport.udp import _EndpointProtocol

from ..session import test_session_udp
from ..session.test_session_udp import answer, udp_responder

pytestmark = pytest.mark.anyio


class NoReaderLoop(asyncio.SelectorEventLoop):
    """A loop lacking what a proactor loop lacks (its own transports still work: they use
    the private ``_add_reader``)."""

    def add_reader(self, fd: Any, callback: Callable[..., object], *args: Any) -> None:  # type: ignore[override]
        raise NotImplementedError

    def add_writer(self, fd: Any, callback: Callable[..., object], *args: Any) -> None:  # type: ignore[override]
        raise NotImplementedError


@pytest.fixture
def anyio_backend() -> tuple[str, dict[str, Any]]:
    return "asyncio", {"loop_factory": NoReaderLoop}


# Every UDP session test, collected again here under the loop above.
globals().update(
    {name: test for name, test in vars(test_session_udp).items() if name.startswith("test_")}
)


async def test_the_loop_lacks_add_reader_and_the_endpoint_path_is_taken() -> None:
    loop = asyncio.get_running_loop()
    assert isinstance(loop, NoReaderLoop)
    with pytest.raises(NotImplementedError):
        loop.add_reader(0, print)
    async with udp_responder(answer) as responder:
        transport = UdpTransport("127.0.0.1", responder.port)
        session = Session(transport, source=FinsAddress(0, 2, 0), dest=FinsAddress(0, 1, 0))
        async with session:
            assert isinstance(transport._aio, _EndpointProtocol)
            assert not transport._aio.direct
            assert transport.poll_now is None  # the proactor's read is always outstanding
            assert transport.local_address is not None
            response = await session.request(0x01, 0x01, bytes.fromhex("82000A000002"))
            assert response.data == bytes.fromhex("100A100B")
        assert not transport.is_open
