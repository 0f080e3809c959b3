"""FINS over Host Link (serial, ASCII hex lines ending ``*`` CR).

The line carries one command at a time (``max_in_flight = 1``); the session queues the rest.
The session hands us binary FINS frames; we re-encode each as a Host Link line (short header
for the directly connected CPU, full header when routing) and turn each reply line back into a
binary frame with a 10-byte header, so the session matches it like any other reply. A reply
with a bad FCS (or any other framing fault) is dropped and counted in :attr:`frame_errors`;
the request then times out and may be retried.

Under asyncio the port is driven by ``serial_asyncio_fast``; under other anyio backends (trio)
pyserial is used in non-blocking mode with ``anyio.wait_readable`` (POSIX only).
"""

from __future__ import annotations

import asyncio
import errno
import importlib
from typing import Any

import anyio

from ..protocol.errors import CommandError, ConnectionLost, DecodeError
from ..protocol.header import CommandFrame, FinsAddress
from ..protocol.hostlink import LineDecoder, decode_response, encode_command
from .base import FrameSink, TaskSpawner, Transport, is_asyncio, wrap_os_error


def _import_serial(name: str) -> Any:
    """A serial package (pyserial or pyserial-asyncio-fast), imported when a port is opened:
    they are optional (the ``serial`` extra), and Ethernet-only users do without them."""
    try:
        return importlib.import_module(name)
    except ImportError as exc:
        package = {"serial": "pyserial", "serial_asyncio_fast": "pyserial-asyncio-fast"}[name]
        raise CommandError(
            f"serial:// needs {package}, which is not installed: pip install -e '.[serial]' "
            f"in a clone of aiofins (or pip install {package})"
        ) from exc


class _LineHandler:
    """Turns received bytes into binary FINS frames for the sink."""

    def __init__(self, owner: SerialTransport, sink: FrameSink) -> None:
        self.owner = owner
        self.sink = sink
        self.decoder = LineDecoder()

    def feed(self, data: bytes) -> None:
        owner = self.owner
        for line in self.decoder.feed(data):
            try:
                unit, response = decode_response(line, full_header=owner._full_header)
            except DecodeError as exc:
                owner.frame_errors += 1
                self.sink.frame_dropped(str(exc))
                continue
            if unit != owner.unit:
                owner.frame_errors += 1
                self.sink.frame_dropped(f"Host Link reply from unit {unit}, expected {owner.unit}")
                continue
            self.sink.frame_received(response.encode())


class _SerialProtocol(asyncio.Protocol):
    def __init__(self, owner: SerialTransport, handler: _LineHandler) -> None:
        self.owner = owner
        self.handler = handler
        self.transport: asyncio.BaseTransport | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport

    def data_received(self, data: bytes) -> None:
        self.handler.feed(data)

    def connection_lost(self, exc: Exception | None) -> None:
        if self.owner._aio is self.transport:
            self.owner._aio = None
            self.handler.sink.connection_lost(exc or ConnectionLost("serial port closed"))


class SerialTransport(Transport):
    """Host Link FINS on a serial port (``/dev/ttyUSB0`` or any pyserial URL).

    The line settings default to Omron's Host Link factory setting: 9600 baud, 7 data bits,
    even parity, 2 stop bits (7E2), unit 0.
    """

    max_in_flight = 1
    reconnectable = True

    def __init__(
        self,
        port: str,
        *,
        baudrate: int = 9600,
        bytesize: int = 7,
        parity: str = "E",
        stopbits: float = 2,
        unit: int = 0,
        response_wait: int = 0,
    ) -> None:
        if not 0 <= unit <= 31:
            raise CommandError(f"Host Link unit number {unit} out of range 0..31")
        if not 0 <= response_wait <= 0xF:
            raise CommandError(f"Host Link response wait time {response_wait} out of range 0..15")
        self.port = port
        self.baudrate = baudrate
        self.bytesize = bytesize
        self.parity = parity
        self.stopbits = stopbits
        self.unit = unit
        self.response_wait = response_wait
        #: Reply lines dropped for a bad FCS, bad text, a refused frame or a wrong unit.
        self.frame_errors = 0
        self._full_header = False
        self._aio: asyncio.WriteTransport | None = None
        self._serial: Any = None  # pyserial Serial on non-asyncio backends

    @property
    def is_open(self) -> bool:
        return self._aio is not None or self._serial is not None

    @property
    def description(self) -> str:
        return f"serial://{self.port}?baudrate={self.baudrate}&unit={self.unit}"

    @property
    def line(self) -> str:
        """The line settings in the usual short form: ``9600 7E2``."""
        stop = int(self.stopbits) if self.stopbits == int(self.stopbits) else self.stopbits
        return f"{self.baudrate} {self.bytesize}{self.parity}{stop}"

    def silence_advice(self, dest: FinsAddress, source: FinsAddress) -> str:
        """What to check when the PLC on the line said nothing: the line, not the network."""
        return (
            f"Check the line settings match the PLC's serial port (here {self.line}: baudrate, "
            "bytesize, parity, stopbits; Omron's Host Link factory setting is 9600 7E2), that "
            "the port is in Host Link (SYSWAY) mode, the Host Link unit number (unit="
            f"{self.unit} here, the PLC's in its serial port settings), and the wiring (TX and "
            "RX crossed, RS-232C or RS-422A/485 as the port is, signal ground, an adapter's "
            "2-wire/4-wire switch)"
        )

    def _open_advice(self, exc: BaseException) -> str:
        """What to do about a port that would not open (after the error's own words)."""
        number = getattr(exc, "errno", None)
        if number is None and exc.args and isinstance(exc.args[0], int):
            number = exc.args[0]  # termios.error is (errno, text)
        text = str(exc)
        if number == errno.EACCES or "Permission denied" in text:
            return (
                f"; this user may not open {self.port}: add it to the 'dialout' group "
                "(sudo usermod -aG dialout $USER, then log in again; 'uucp' on some "
                "distributions) or give the device a udev rule"
            )
        if number == errno.ENOENT or "No such file" in text:
            return (
                f"; there is no {self.port}: is the adapter plugged in? "
                "python -m serial.tools.list_ports lists the ports"
            )
        if number == errno.EBUSY or "busy" in text.lower():
            return f"; another program holds {self.port} (fuser {self.port} names it)"
        if number == errno.EINVAL:
            return (
                f"; the device refused the line settings {self.line}: a pseudo-terminal (pty, "
                "socat) takes only 8N1 (?bytesize=8&parity=N&stopbits=1)"
            )
        return ""

    def _settings(self) -> dict[str, Any]:
        return {
            "baudrate": self.baudrate,
            "bytesize": self.bytesize,
            "parity": self.parity,
            "stopbits": self.stopbits,
        }

    async def open(self, sink: FrameSink, task_group: TaskSpawner) -> None:
        if self.is_open:
            return
        handler = _LineHandler(self, sink)
        on_asyncio = is_asyncio()
        package = _import_serial("serial_asyncio_fast" if on_asyncio else "serial")
        try:
            if on_asyncio:
                loop = asyncio.get_running_loop()
                transport, _ = await package.create_serial_connection(
                    loop, lambda: _SerialProtocol(self, handler), self.port, **self._settings()
                )
                self._aio = transport
            else:
                ser = package.serial_for_url(self.port, timeout=0, **self._settings())
                self._serial = ser
                task_group.start_soon(self._reader, ser, handler)
        except Exception as exc:  # OSError, SerialException, ValueError, termios.error
            wrapped = wrap_os_error(exc, f"cannot open {self.description}")
            wrapped.args = (f"{wrapped}{self._open_advice(exc)}",)
            raise wrapped from exc

    async def _reader(self, ser: Any, handler: _LineHandler) -> None:
        exc: BaseException | None = None
        try:
            while True:
                await anyio.wait_readable(ser.fileno())
                data = ser.read(max(1, ser.in_waiting))
                if data:
                    handler.feed(data)
        except Exception as err:  # OSError/SerialException, TypeError, ClosedResourceError
            exc = err
        finally:
            if self._serial is ser:
                self._serial = None
                ser.close()
                handler.sink.connection_lost(
                    wrap_os_error(exc, f"{self.description} failed") if exc else None
                )

    def _encode(self, frame: bytes) -> bytes:
        command = CommandFrame.decode(frame)
        dest = command.header.destination
        self._full_header = dest.network != 0 or dest.node != 0
        return encode_command(
            command, unit=self.unit, wait_time=self.response_wait, full_header=self._full_header
        )

    async def send(self, frame: bytes, timeout: float | None = None) -> None:
        line = self._encode(frame)
        if self._aio is not None:
            self._aio.write(line)
            return
        ser = self._serial
        if ser is None:
            raise ConnectionLost(f"{self.description} is not open")
        try:
            ser.write(line)
        except Exception as exc:
            raise wrap_os_error(exc, f"cannot write to {self.description}") from exc

    async def aclose(self) -> None:
        aio, ser = self._aio, self._serial
        self._aio = None
        self._serial = None
        if aio is not None:
            aio.close()
        if ser is not None:
            anyio.notify_closing(ser.fileno())  # wake the reader before the fd goes away
            ser.close()
