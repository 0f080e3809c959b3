"""Host Link FINS server on a serial device (a tty, a USB adapter or a pty).

The device is opened and configured with pyserial (``serial.Serial``), then read and written
without threads through :func:`anyio.wait_readable` / :func:`anyio.wait_writable` on its file
descriptor, so it works under asyncio and trio alike (POSIX only: ttys are pollable there).
Host Link is half-duplex: commands are answered one at a time, in order. Lines for another
Host Link unit number, or with a bad FCS or format, get no answer (counted in
:attr:`SerialServer.ignored_lines`).
"""

from __future__ import annotations

import dataclasses
import errno
import os
from dataclasses import dataclass

import anyio
from anyio.abc import TaskStatus

from ..protocol.endcodes import CPU_ERROR_FLAGS, EndCode
from ..protocol.errors import CommandError, DecodeError
from ..protocol.header import ICF_NO_RESPONSE, ICF_RESPONSE, ResponseFrame
from ..protocol.hostlink import (
    MAX_COMMAND_CHARS,
    MAX_RESPONSE_DATA_BYTES,
    LineDecoder,
    decode_command,
    encode_response,
)
from .faults import Dispatcher
from .state import RESPONSE_TOO_LONG


@dataclass(frozen=True, slots=True)
class SerialSettings:
    """Line settings: by default Omron's Host Link factory setting, 9600 baud 7E2, as the
    client's. Ptys accept only 8N1 on Linux: ``SerialSettings(bytesize=8, parity="N",
    stopbits=1)`` there (and ``?bytesize=8&parity=N&stopbits=1`` in the client's URL)."""

    baudrate: int = 9600
    bytesize: int = 7
    parity: str = "E"
    stopbits: float = 2

    def url_options(self) -> list[str]:
        """The client URL's options for these settings (none for the client's defaults)."""
        options = []
        if self.baudrate != 9600:
            options.append(f"baudrate={self.baudrate}")
        if (self.bytesize, self.parity, self.stopbits) != (7, "E", 2):
            stop = int(self.stopbits) if self.stopbits == int(self.stopbits) else self.stopbits
            options.append(f"bytesize={self.bytesize}&parity={self.parity}&stopbits={stop}")
        return options


class SerialServer:
    """Serve a :class:`~aiofins.simulator.faults.Dispatcher` as Host Link unit ``unit``."""

    def __init__(
        self,
        dispatcher: Dispatcher,
        device: str,
        *,
        unit: int = 0,
        settings: SerialSettings | None = None,
    ) -> None:
        if not 0 <= unit <= 31:
            raise ValueError(f"Host Link unit number {unit} out of range 0..31")
        self.dispatcher = dispatcher
        self.device = device
        self.unit = unit
        self.settings = settings if settings is not None else SerialSettings()
        self.ignored_lines = 0
        self._fd = -1

    async def serve(self, *, task_status: TaskStatus[str] = anyio.TASK_STATUS_IGNORED) -> None:
        """Answer Host Link lines until cancelled or the device goes away."""
        s = self.settings
        try:
            import serial  # type: ignore[import-untyped]  # no types-pyserial in the env
        except ImportError as exc:  # the optional ``serial`` extra
            raise CommandError(
                "serving a serial device needs pyserial, which is not installed: "
                "pip install -e '.[serial]' in a clone of aiofins (or pip install pyserial)"
            ) from exc
        port = serial.Serial(
            self.device,
            baudrate=s.baudrate,
            bytesize=s.bytesize,
            parity=s.parity,
            stopbits=s.stopbits,
            timeout=0,
            write_timeout=0,
        )
        try:
            self._fd = port.fileno()
            os.set_blocking(self._fd, False)
            task_status.started(self.device)
            decoder = LineDecoder(max_chars=MAX_COMMAND_CHARS)
            while True:
                await anyio.wait_readable(self._fd)
                try:
                    data = os.read(self._fd, 4096)
                except BlockingIOError:
                    continue
                except OSError as exc:
                    if exc.errno == errno.EIO:  # the other end of a pty closed
                        return
                    raise
                if not data:
                    return
                for line in decoder.feed(data):
                    await self._line(line)
        finally:
            self._fd = -1
            port.close()

    async def _line(self, line: bytes) -> None:
        try:
            command = decode_command(line)
        except DecodeError:
            self.ignored_lines += 1
            return
        if command.unit != self.unit:
            self.ignored_lines += 1
            return
        request_icf = command.frame.header.icf

        def encode(response: bytes) -> bytes:
            frame = ResponseFrame.decode(response)
            if len(frame.data) > MAX_RESPONSE_DATA_BYTES:
                # 110B response too long: a Host Link response carries at most 538 data bytes
                flags = frame.end_code.raw & CPU_ERROR_FLAGS
                frame = dataclasses.replace(
                    frame, end_code=EndCode(RESPONSE_TOO_LONG | flags), data=b"", relay=None
                )
            if not command.full_header:
                # the short form answers the ICF it was sent with, response bit set ("40")
                icf = (request_icf | ICF_RESPONSE) & ~ICF_NO_RESPONSE & 0xFF
                frame = dataclasses.replace(
                    frame, header=dataclasses.replace(frame.header, icf=icf)
                )
            return encode_response(frame, unit=command.unit, full_header=command.full_header)

        await self.dispatcher.dispatch(
            command.frame.encode(),
            self._write,
            peer=f"serial:{self.device}",
            encode=encode,
            from_network=False,
        )

    async def _write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            if self._fd < 0:
                raise anyio.ClosedResourceError
            try:
                written = os.write(self._fd, view)
            except BlockingIOError:
                written = 0
            view = view[written:]
            if view:
                await anyio.wait_writable(self._fd)
