"""The virtual PLC core: one FINS command frame in, one response frame out. No sockets.

Address handling (manual 5-1, wire-format §1): a frame is ours when DNA is 0 or our network
and DA1 is our node, 0 (the local PLC) or FF (broadcast, executed without a response). A
frame for another network is answered with a relay error (bit 15 + network/node trailer) or
dropped, as configured. The response swaps the addresses and echoes RSV, GCT, SID and MRC/SRC.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from ..protocol.addresses import parse_span
from ..protocol.areas import MemoryAddress, find_spec
from ..protocol.commands import Request, operation_for
from ..protocol.commands.access import AccessRightAcquire
from ..protocol.commands.memory import (
    MemoryAreaFill,
    MemoryAreaRead,
    MemoryAreaTransfer,
    MemoryAreaWrite,
    MultipleMemoryAreaRead,
)
from ..protocol.commands.parameter import PARAMETER_AREA_WORDS, ParameterArea, ParameterAreaRead
from ..protocol.commands.status import FatalError, NonFatalError
from ..protocol.endcodes import (
    FATAL_CPU_ERROR_FLAG,
    NON_FATAL_CPU_ERROR_FLAG,
    RELAY_ERROR_FLAG,
    EndCode,
)
from ..protocol.errors import CommandError, DecodeError
from ..protocol.files import Disk
from ..protocol.header import CommandFrame, FinsAddress, Header, ResponseFrame
from ..protocol.values import Value, parse_value_type, values_to_words, words_to_values
from . import restrictions
from .filememory import FileMemory
from .handlers import HANDLERS, Call, GatewayHandler, default_gateway
from .memory import IOMemory
from .state import (
    ACCESS_RIGHT_HELD,
    ADDRESS_RANGE_EXCEEDED,
    AREA_MISSING,
    COMMAND_TOO_SHORT,
    LOG_CAPACITY,
    NO_ROUTE,
    NORMAL,
    TOO_MANY_WORDS,
    UNDEFINED_COMMAND,
    CommandFailed,
    Mode,
)

BROADCAST_NODE = 0xFF
LOCAL_NODE = 0x00
PROGRAM_AREA_BYTES = 0x20000  # 128 KiB of UM (CJ2M-CPU33: 10 K steps; kept simple)

#: (command, codec end code) pairs where the manual prescribes data with the error, so the
#: handler answers instead of the codec: 0201 over 498 words reads 498 and answers 1108;
#: 0201 past the end of the area returns what exists with 1104 (manual 5-3-7).
_HANDLER_DECIDES = frozenset(
    (ParameterAreaRead.command_code(), end_code)
    for end_code in (TOO_MANY_WORDS, ADDRESS_RANGE_EXCEEDED)
)
#: ACCESS RIGHT ACQUIRE refused with 3001 answers the holder's address (manual 5-3-24).
_ACCESS_RIGHT_ACQUIRE = AccessRightAcquire.command_code()
#: The whole parameter area, code 8000 (manual 5-3-7).
PARAMETER_WORDS = PARAMETER_AREA_WORDS[ParameterArea.ALL]
#: What an NJ/NX CPU model answers for I/O memory no variable is AT-mapped to: area
#: missing (1101), the CJ-series memory is not there for FINS.
NOT_AT_MAPPED = AREA_MISSING

#: (area, EM bank) -> the wire words of one AT-mapped span, first and last.
_Span = tuple[tuple[str, int | None], int, int]


def _span_of(address: MemoryAddress, elements: int) -> _Span | None:
    """The area and wire words ``elements`` elements from ``address`` touch; ``None`` for an
    address outside every area."""
    spec = find_spec(address.area_code, address.word)
    if spec is None:
        return None
    if address.is_bit:
        last = address.word + (address.bit + max(elements, 1) - 1) // 16
    else:
        last = address.word + max(elements, 1) * max(address.element_size // 2, 1) - 1
    return (spec.area, spec.bank), address.word, last


#: Error code ranges → (fatal?, bit of the 0601 fatal / non-fatal error word), per the
#: error codes of 5-3-27 and the 0601 bit layout (wire-format §6, 0601).
_ERROR_BITS: tuple[tuple[int, int, bool, int], ...] = (
    (0xC101, 0xC2FF, True, FatalError.FALS_ERROR),
    (0x80F1, 0x80F1, True, FatalError.MEMORY_ERROR),
    (0x80C0, 0x80C7, True, FatalError.IO_BUS_ERROR),
    (0x80E9, 0x80EA, True, FatalError.DUPLICATION_ERROR),
    (0x82F0, 0x82F0, True, FatalError.INNER_BOARD_ERROR),
    (0x80E1, 0x80E1, True, FatalError.TOO_MANY_IO_POINTS),
    (0x80E0, 0x80E0, True, FatalError.IO_SETTING_ERROR),
    (0x80F0, 0x80F0, True, FatalError.PROGRAM_ERROR),
    (0x809F, 0x809F, True, FatalError.CYCLE_TIME_OVER),
    (0x4101, 0x42FF, False, NonFatalError.FAL_ERROR),
    (0x008B, 0x008B, False, NonFatalError.INTERRUPT_TASK_ERROR),
    (0x009A, 0x009A, False, NonFatalError.BASIC_IO_UNIT_ERROR),
    (0x009B, 0x009B, False, NonFatalError.PLC_SETUP_ERROR),
    (0x00E7, 0x00E7, False, NonFatalError.IO_VERIFICATION_ERROR),
    (0x02F0, 0x02F0, False, NonFatalError.INNER_BOARD_ERROR),
    (0x0200, 0x020F, False, NonFatalError.CPU_BUS_UNIT_ERROR),
    (0x0300, 0x035F, False, NonFatalError.SPECIAL_IO_UNIT_ERROR),
    (0x00A0, 0x00A1, False, NonFatalError.SYSMAC_BUS_ERROR),
    (0x00F7, 0x00F7, False, NonFatalError.BATTERY_ERROR),
    (0x0400, 0x040F, False, NonFatalError.CPU_BUS_UNIT_SETTING_ERROR),
    (0x0500, 0x055F, False, NonFatalError.SPECIAL_IO_UNIT_SETTING_ERROR),
)


def error_bit(code: int) -> tuple[bool, int]:
    """(fatal?, error-word bit) of an error code; unknown codes count as non-fatal, no bit."""
    for low, high, fatal, bit in _ERROR_BITS:
        if low <= code <= high:
            return fatal, int(bit)
    return False, 0


@dataclass(frozen=True, slots=True)
class ErrorRecord:
    """One error log record (2102): error codes 1 and 2 and when it happened."""

    code1: int
    code2: int
    time: datetime


@dataclass(frozen=True, slots=True)
class WriteRecord:
    """One FINS write access log record (2140): who wrote with which command, when."""

    source: FinsAddress
    command_code: int
    time: datetime
    weekday: int  # as CLOCK READ would have answered then


class VirtualPLC:
    """A CS/CJ CPU Unit answering FINS commands from memory."""

    def __init__(
        self,
        *,
        network: int = 0,
        node: int = 1,
        unit: int = 0,
        mode: Mode = Mode.PROGRAM,
        model: str = "CJ2M-CPU33",
        version: str = "02.01",
        um_read_protected: bool = False,
        um_write_protected: bool = False,
        network_write_protection: bool = False,
        write_allowed_nodes: Iterable[tuple[int, int]] = (),
        relay_error: int | None = NO_ROUTE,
        em_banks: int = 25,
        memory_card: bool = True,
        em_file_memory: bool = True,
        clock: Callable[[], float] = time.time,
        gateway: GatewayHandler = default_gateway,
        at_mapped: Iterable[tuple[str, int]] | None = None,
    ) -> None:
        if not 1 <= node <= 254:
            raise CommandError(f"node {node} out of range 1..254 (a PLC's FINS node number)")
        self.address = FinsAddress(network, node, unit)
        self.memory = IOMemory(em_banks=em_banks, clock=clock)
        self.mode = mode
        self.model = model
        self.version = version
        self.um_read_protected = um_read_protected
        self.um_write_protected = um_write_protected
        self.network_write_protection = network_write_protection
        self.write_allowed_nodes = frozenset(write_allowed_nodes)
        #: End code (bit 15 added) answered for another network; ``None`` drops the frame.
        self.relay_error = relay_error
        self.clock = clock
        self.clock_offset = 0.0
        self.weekday_delta = 0
        self.gateway = gateway
        self.access_holder: FinsAddress | None = None
        self.error_log: list[ErrorRecord] = []
        self.write_log: list[WriteRecord] = []
        self.messages: dict[int, str] = {}
        self.fal_messages: dict[int, str] = {}
        self.fatal_errors = 0  # 0601 fatal error bits; non-zero sets end-code bit 7
        self.non_fatal_errors = 0  # 0601 non-fatal error bits; non-zero sets bit 6
        self.error_code = 0  # highest-priority current error (0601)
        self.error_message = ""
        self.current_errors: list[int] = []
        self.cycle_times: list[int] = [10] * 8  # 0.1 ms units
        self.cycle_min = 10
        self.cycle_max = 10
        self.program = bytearray(PROGRAM_AREA_BYTES)
        self.program_length = 0
        self.parameter_memory = bytearray(2 * PARAMETER_WORDS)
        self.file_memory: dict[int, FileMemory] = {}
        if memory_card:
            self.file_memory[Disk.MEMORY_CARD] = FileMemory(
                capacity=64 * 1024 * 1024, clock=self.now
            )
        if em_file_memory:
            self.file_memory[Disk.EM_FILE_MEMORY] = FileMemory(capacity=512 * 1024, clock=self.now)
        self.frames_handled = 0
        self.frames_ignored = 0
        self.commands: Counter[int] = Counter()
        #: An NJ/NX CPU's FINS view of I/O memory: only the spans variables are AT-mapped
        #: to, ``(address, words)`` (``("D0", 100)``: D0..D99); anything else is answered
        #: with :data:`NOT_AT_MAPPED`. ``None`` (a CS/CJ CPU): all of it.
        self.at_mapped: list[_Span] | None = None
        if at_mapped is not None:
            spans = []
            for text, words in at_mapped:
                span = _span_of(parse_span(text, words), words)
                if span is None:  # pragma: no cover - parse_span checked the area
                    raise CommandError(f"AT mapping {text!r}: no such area")
                spans.append(span)
            self.at_mapped = spans

    @property
    def mode(self) -> Mode:
        """Operating mode; cyclic task 0's task flag (TK00) is ON while the program runs."""
        return self._mode

    @mode.setter
    def mode(self, mode: Mode) -> None:
        self._mode = Mode(mode)
        running = int(self._mode is not Mode.PROGRAM)
        self.memory.task_flags[0] = running
        self.memory.task_status[0] = running

    # ---- I/O memory by address text (tests and demos) ----------------------------------------

    def read(self, address: str, count: int = 1) -> list[int]:
        """``count`` elements from ``address`` (``"D100"``, ``"CIO 0.01"``, ``"T5"``) as
        :meth:`aiofins.Client.read` would return them: words, or 0/1 for bits and flags.

        Straight from memory: no FINS frame, no restriction checks.
        """
        if count < 0:
            raise CommandError(f"count must not be negative, got {count}")
        start = parse_span(address, count)
        memory = self.memory
        if start.element_size == 1:
            bits = memory.read_bits(start.area_code, start.word, start.bit, count)
            return [int(b) for b in bits]
        return memory.read_words(start.area_code, start.word, count)

    def write(self, address: str, values: Sequence[int]) -> None:
        """Set elements from ``address`` as the PLC's own program would (read-only areas
        too): words, or 0/1 for bits."""
        start = parse_span(address, len(values))
        limit = (1 << (8 * start.element_size)) - 1 if start.element_size > 1 else 1
        for value in values:  # as the client refuses them: no silent masking
            if not isinstance(value, int) or not 0 <= value <= limit:
                raise CommandError(f"{address}: value {value!r} out of range 0..{limit}")
        memory = self.memory
        if start.element_size == 1:
            memory.write_bits(start.area_code, start.word, start.bit, [bool(v) for v in values])
        else:
            memory.write_words(start.area_code, start.word, values)

    def read_value(self, address: str, vtype: str = "uint16") -> Value:
        """One typed value (``"float32"``, ``"string:8"``, ...; Omron's CDAB word order)."""
        value_type = parse_value_type(vtype)
        return words_to_values(value_type, self.read(address, value_type.words))[0]

    def write_value(self, address: str, value: Value, vtype: str = "uint16") -> None:
        """Store one typed value as the PLC program would."""
        self.write(address, values_to_words(parse_value_type(vtype), [value]))

    # ---- time -------------------------------------------------------------------------------

    def now(self) -> datetime:
        """The PLC clock: real time plus the offset set by CLOCK WRITE."""
        return datetime.fromtimestamp(self.clock() + self.clock_offset)

    def set_clock(self, when: datetime, weekday: int | None) -> None:
        """CLOCK WRITE: move the clock; an omitted day of week keeps its previous value."""
        previous = self.weekday()
        self.clock_offset = (when - datetime.fromtimestamp(self.clock())).total_seconds()
        target = previous if weekday is None else weekday
        self.weekday_delta = (target - self._weekday(self.now())) % 7

    @staticmethod
    def _weekday(when: datetime) -> int:
        return (when.weekday() + 1) % 7  # FINS: 0 = Sunday

    def weekday(self) -> int:
        """Day of week as 0701 returns it (the PLC does not check it against the date)."""
        return (self._weekday(self.now()) + self.weekday_delta) % 7

    # ---- logs -------------------------------------------------------------------------------

    def log_error(self, code1: int, code2: int = 0) -> None:
        """Record an error in the error log (20 records, oldest dropped)."""
        self.error_log.append(ErrorRecord(code1, code2, self.now()))
        del self.error_log[:-LOG_CAPACITY]

    def log_write(self, source: FinsAddress, command_code: int) -> None:
        """Manual 5-3-30: one record per node (overwritten), appended at the end, 20 max."""
        self.write_log = [r for r in self.write_log if r.source != source]
        self.write_log.append(WriteRecord(source, command_code, self.now(), self.weekday()))
        del self.write_log[:-LOG_CAPACITY]

    def raise_error(self, code: int, *, message: str = "") -> None:
        """Make an error current (0601 shows it, 2101 clears it) and log it."""
        if code not in self.current_errors:
            self.current_errors.append(code)
        if message:
            self.error_message = message
        self.log_error(code)
        self.refresh_error_state()

    def most_serious_error(self) -> int | None:
        """The current error 0601 reports and 2101 FFFE clears ("the most serious", manual
        5-3-17; "the highest priority error", 5-3-27): fatal before non-fatal, then the
        earliest raised."""
        errors = self.current_errors
        return next((code for code in errors if error_bit(code)[0]), errors[0] if errors else None)

    def refresh_error_state(self) -> None:
        """Recompute the 0601 error words and error code from the current errors."""
        self.fatal_errors = self.non_fatal_errors = 0
        for code in self.current_errors:
            fatal, bit = error_bit(code)
            if fatal:
                self.fatal_errors |= bit
            else:
                self.non_fatal_errors |= bit
        self.error_code = self.most_serious_error() or 0
        if not self.current_errors:
            self.error_message = ""

    def start_operation(self) -> None:
        """PROGRAM → RUN/MONITOR: the maximum and minimum cycle times start afresh."""
        self.cycle_min = self.cycle_max = self.cycle_times[-1]

    # ---- frames -----------------------------------------------------------------------------

    def handle_frame(self, frame: bytes, *, from_network: bool = True) -> bytes | None:
        """Answer one FINS command frame; ``None`` when there is nothing to send back.

        ``from_network=False`` marks a frame from the CPU Unit's own serial port (Host Link):
        network write protection does not apply to it.
        """
        try:
            command = CommandFrame.decode(frame)
        except DecodeError:
            self.frames_ignored += 1
            return None
        response = self.handle(command, from_network=from_network)
        return None if response is None else response.encode()

    def handle(self, command: CommandFrame, *, from_network: bool = True) -> ResponseFrame | None:
        """Answer one decoded command frame (see the module docstring for addressing)."""
        header = command.header
        dest = header.destination
        if dest.network not in (0, self.address.network):
            self.frames_ignored += 1
            if self.relay_error is None or not header.response_required:
                return None
            return self._reply(command, RELAY_ERROR_FLAG | self.relay_error, b"", relay=True)
        if dest.node not in (self.address.node, LOCAL_NODE, BROADCAST_NODE):
            self.frames_ignored += 1
            return None
        return self.answer(command, from_network=from_network)

    def answer(self, command: CommandFrame, *, from_network: bool = True) -> ResponseFrame | None:
        """Execute a command already known to be for this PLC (a plant's routing decided
        that) and build its response; ``None`` for a broadcast or a no-response command."""
        header = command.header
        self.frames_handled += 1
        self.commands[command.command_code] += 1
        end_code, data = self.execute(command, from_network=from_network)
        if header.destination.node == BROADCAST_NODE or not header.response_required:
            return None
        return self._reply(command, end_code, data)

    def _reply(
        self, command: CommandFrame, end_code: int, data: bytes, relay: bool = False
    ) -> ResponseFrame:
        h = command.header
        # A relay error comes from the relaying unit itself (its own network, node and unit).
        me = (
            self.address
            if relay
            else FinsAddress(h.destination.network, self.address.node, h.destination.unit)
        )
        reply = Header(h.source, me, sid=h.sid, icf=0xC0, rsv=h.rsv, gct=h.gct)
        if not relay:
            if self.fatal_errors:
                end_code |= FATAL_CPU_ERROR_FLAG
            if self.non_fatal_errors:
                end_code |= NON_FATAL_CPU_ERROR_FLAG
        trailer = (self.address.network, self.address.node) if relay else None
        return ResponseFrame(reply, command.mrc, command.src, EndCode(end_code), data, trailer)

    # ---- execution --------------------------------------------------------------------------

    def conditions(
        self, source: FinsAddress, *, from_network: bool = True
    ) -> restrictions.Conditions:
        """The restriction-table conditions for a command from ``source``."""
        refused = (
            from_network
            and self.network_write_protection
            and (source.network, source.node) not in self.write_allowed_nodes
        )
        return restrictions.Conditions(
            mode=self.mode,
            access_right_elsewhere=self.access_holder is not None and self.access_holder != source,
            um_read_protected=self.um_read_protected,
            um_write_protected=self.um_write_protected,
            network_write_refused=refused,
        )

    def _mapped(self, request: Request[Any]) -> bool:
        """Whether every I/O memory word ``request`` touches is AT-mapped (NJ/NX)."""
        touched: list[tuple[MemoryAddress, int]]
        if isinstance(request, MemoryAreaRead | MemoryAreaFill):
            touched = [(request.address, request.count)]
        elif isinstance(request, MemoryAreaWrite):
            touched = [(request.address, len(request.data) // request.address.element_size)]
        elif isinstance(request, MultipleMemoryAreaRead):
            touched = [(address, 1) for address in request.addresses]
        elif isinstance(request, MemoryAreaTransfer):
            touched = [(request.source, request.count), (request.destination, request.count)]
        else:
            return True
        mapped = self.at_mapped or []
        for address, elements in touched:
            span = _span_of(address, elements)
            if span is None or not any(
                key == span[0] and first <= span[1] and span[2] <= last
                for key, first, last in mapped
            ):
                return False
        return True

    def execute(self, command: CommandFrame, *, from_network: bool = True) -> tuple[int, bytes]:
        """Run one command: (end code, response data)."""
        code, params, source = command.command_code, command.params, command.header.source
        handler = HANDLERS.get(code)
        if handler is None:
            return UNDEFINED_COMMAND, b""
        try:
            # The protocol codec is the judge of a malformed command, when it knows the code.
            op = operation_for(command.mrc, command.src, params)
        except DecodeError:
            op = None
        request: Request[Any] | None = None
        try:
            if op is not None:
                request = op.decode(params)
        except DecodeError as exc:
            if (code, exc.end_code) not in _HANDLER_DECIDES:
                return exc.end_code or COMMAND_TOO_SHORT, b""
        if self.at_mapped is not None and request is not None and not self._mapped(request):
            return NOT_AT_MAPPED, b""
        row = restrictions.restriction_for(code, params)
        if restrictions.is_write_row(row):
            # manual 5-3-30: the log keeps every FINS write access, whatever the setting
            self.log_write(source, code)
        refused = restrictions.check_row(row, self.conditions(source, from_network=from_network))
        if refused is not None:
            holder = self.access_holder
            if code == _ACCESS_RIGHT_ACQUIRE and refused == ACCESS_RIGHT_HELD and holder:
                return refused, bytes((holder.network, holder.node, holder.unit))
            return refused, b""
        try:
            return NORMAL, handler(self, Call(code, params, source, request))
        except CommandFailed as exc:
            return exc.end_code, exc.data
        except DecodeError as exc:
            return exc.end_code or COMMAND_TOO_SHORT, b""
