"""The exception hierarchy of aiofins.

Everything aiofins raises on purpose derives from :class:`FinsError`. Input errors
(:class:`AddressError`, :class:`CommandError`) are raised *before* anything is sent and are also
``ValueError`` so that generic code handling bad input keeps working.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .endcodes import EndCode


def leaf_errors(exc: BaseException) -> list[BaseException]:
    """``exc`` itself, or every exception inside it if it is an exception group (a task
    group's error), flattened."""
    inner = getattr(exc, "exceptions", None)
    if not isinstance(inner, tuple):
        return [exc]
    return [leaf for e in inner for leaf in leaf_errors(e)]


class FinsError(Exception):
    """Root of every error aiofins raises."""


class AddressError(FinsError, ValueError):
    """An I/O memory address that cannot be parsed or is out of the area's range.

    ``end_code``: the FINS end code a PLC answers when a command it received carries this
    address (e.g. ``0x1103`` address range error), where the check knows it; else ``None``.
    """

    def __init__(self, message: str, *, end_code: int | None = None) -> None:
        super().__init__(message)
        self.end_code = end_code


class CommandError(FinsError, ValueError):
    """A command argument that cannot be encoded (count over a limit, odd size, bad value).

    ``end_code``: the FINS end code a PLC answers when a command it received carries this
    argument (e.g. ``0x110C`` parameter error), where the check knows it; else ``None``.
    """

    def __init__(self, message: str, *, end_code: int | None = None) -> None:
        super().__init__(message)
        self.end_code = end_code


class ReadOnlyError(CommandError):
    """A command that changes the PLC, refused by a read-only client before it was sent.

    ``command_code`` is the refused command (``0x0102``), ``changes`` what it would have
    changed (``"I/O memory"``). A :class:`CommandError`: like every input error it is raised
    before anything is sent, and nothing reached the PLC.
    """

    def __init__(self, message: str, *, command_code: int, changes: str) -> None:
        super().__init__(message)
        self.command_code = command_code
        self.changes = changes


class DecodeError(FinsError):
    """Bytes that do not form a valid frame, command or response.

    ``end_code`` is the FINS end code a server should answer with when the bytes were a
    command it received (for example ``0x1002`` *command too short*); ``None`` when the
    problem has no FINS end code (a response we could not parse).
    """

    def __init__(self, message: str, *, end_code: int | None = None) -> None:
        super().__init__(message)
        self.end_code = end_code


class FrameError(DecodeError):
    """A malformed frame at the framing level: header, FCS, FINS/TCP envelope."""


class FinsTcpError(FrameError):
    """A FINS/TCP error code received from the peer (handshake refused, command 3)."""

    def __init__(self, message: str, *, tcp_error_code: int) -> None:
        super().__init__(message)
        self.tcp_error_code = tcp_error_code


class FinsTimeout(FinsError, TimeoutError):
    """No response arrived before the deadline (after every allowed retry)."""


class ConnectionLost(FinsError, ConnectionError):
    """The transport closed or failed while a request was in flight or being sent."""


class CircuitOpen(ConnectionLost):
    """Failed at once, nothing sent: the endpoint failed too many calls in a row (its
    circuit breaker is open) and a probe is testing whether it answers again.

    A :class:`ConnectionLost`, so code that handles a lost link handles this too.
    ``retry_after``: seconds until the next probe may go (0.0 if one is in flight).
    """

    def __init__(self, message: str, *, retry_after: float = 0.0) -> None:
        super().__init__(message)
        self.retry_after = retry_after


class EndCodeError(FinsError):
    """The PLC answered with an end code other than normal completion.

    Carries the decoded :class:`~aiofins.protocol.endcodes.EndCode` (with its name, probable
    cause and correction), the command code it answered and any response data that came with
    it (some commands return partial data with an error, e.g. 0101 past the end of an area).
    """

    main_code: int | None = None  # set on the per-main-code subclasses

    def __init__(
        self, end_code: EndCode, *, command_code: int | None = None, data: bytes = b""
    ) -> None:
        self.end_code = end_code
        self.command_code = command_code
        self.data = data
        super().__init__(self._message())

    def _message(self) -> str:
        ec = self.end_code
        text = f"end code {ec.code:04X}: {ec.name}"
        if self.command_code is not None:
            text = f"command {self.command_code:04X} failed, {text}"
        if ec.cause:
            text += f" ({ec.cause})"
        if ec.correction:
            text += f"; correction: {ec.correction}"
        return text

    @property
    def code(self) -> int:
        """The end code without flag bits, e.g. ``0x1104``."""
        return self.end_code.code


class RelayError(EndCodeError):
    """Bit 15 of the end code: a relay point could not forward the command.

    ``network`` and ``node`` name the relay point where forwarding failed.
    """

    def __init__(
        self,
        end_code: EndCode,
        *,
        network: int,
        node: int,
        command_code: int | None = None,
        data: bytes = b"",
    ) -> None:
        self.network = network
        self.node = node
        super().__init__(end_code, command_code=command_code, data=data)

    def _message(self) -> str:
        return f"relay error at network {self.network} node {self.node}: {super()._message()}"


class ServiceCanceledError(EndCodeError):
    """Main code 00 with sub code 01: the service was canceled."""

    main_code = 0x00


class LocalNodeError(EndCodeError):
    """Main code 01: the local node (our side of the network) has a problem."""

    main_code = 0x01


class DestinationNodeError(EndCodeError):
    """Main code 02: the destination node is missing, busy or timed out."""

    main_code = 0x02


class ControllerError(EndCodeError):
    """Main code 03: communications controller or CPU error at the destination."""

    main_code = 0x03


class ServiceUnsupportedError(EndCodeError):
    """Main code 04: the command is not supported by the destination."""

    main_code = 0x04


class RoutingTableError(EndCodeError):
    """Main code 05: routing tables missing or wrong, or too many relays."""

    main_code = 0x05


class CommandFormatError(EndCodeError):
    """Main code 10: the command frame was malformed (too long, too short, ...)."""

    main_code = 0x10


class ParameterError(EndCodeError):
    """Main code 11: a parameter (area, address, count, ...) was wrong."""

    main_code = 0x11


class ReadNotPossibleError(EndCodeError):
    """Main code 20: the data could not be read."""

    main_code = 0x20


class WriteNotPossibleError(EndCodeError):
    """Main code 21: the data could not be written (read-only, protected, ...)."""

    main_code = 0x21


class ModeError(EndCodeError):
    """Main code 22: not executable in the PLC's current mode."""

    main_code = 0x22


class NoSuchDeviceError(EndCodeError):
    """Main code 23: the device (file memory, clock, ...) does not exist."""

    main_code = 0x23


class CannotStartStopError(EndCodeError):
    """Main code 24: cannot start or stop (table missing)."""

    main_code = 0x24


class UnitError(EndCodeError):
    """Main code 25: a unit error (memory, I/O setting, bus errors)."""

    main_code = 0x25


class CommandRejectedError(EndCodeError):
    """Main code 26: command error (protected, busy, service already executing, ...).

    ``2604`` (more than 5 commands being processed) and ``2605`` (service already executing)
    mean *busy, retry later*; see :attr:`is_busy`.
    """

    main_code = 0x26

    @property
    def is_busy(self) -> bool:
        return self.end_code.code in (0x2604, 0x2605)


class AccessRightError(EndCodeError):
    """Main code 30: another node holds the access right.

    For 0C01 ACCESS RIGHT ACQUIRE the PLC names the holder: ``holder`` is then set.
    """

    main_code = 0x30

    def __init__(
        self, end_code: EndCode, *, command_code: int | None = None, data: bytes = b""
    ) -> None:
        self.holder: tuple[int, int, int] | None = (
            (data[0], data[1], data[2]) if len(data) >= 3 else None
        )
        super().__init__(end_code, command_code=command_code, data=data)


class AbortedError(EndCodeError):
    """Main code 40: the service was aborted."""

    main_code = 0x40


_BY_MAIN_CODE: dict[int, type[EndCodeError]] = {
    cls.main_code: cls
    for cls in (
        LocalNodeError,
        DestinationNodeError,
        ControllerError,
        ServiceUnsupportedError,
        RoutingTableError,
        CommandFormatError,
        ParameterError,
        ReadNotPossibleError,
        WriteNotPossibleError,
        ModeError,
        NoSuchDeviceError,
        CannotStartStopError,
        UnitError,
        CommandRejectedError,
        AccessRightError,
        AbortedError,
    )
    if cls.main_code is not None
}


def error_for_end_code(
    end_code: EndCode, *, command_code: int | None = None, data: bytes = b""
) -> EndCodeError:
    """The most specific exception for a non-normal end code (relay errors excluded)."""
    if end_code.main == 0x00:
        return ServiceCanceledError(end_code, command_code=command_code, data=data)
    cls = _BY_MAIN_CODE.get(end_code.main, EndCodeError)
    return cls(end_code, command_code=command_code, data=data)
