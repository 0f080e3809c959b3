"""Fault injection for the virtual PLC's servers.

A :class:`FaultPlan` decides, frame by frame, what goes wrong: drop the request or the
response, delay it (or answer after a client would have given up), duplicate it, hold it back
until the next response has gone out (reorder), corrupt or truncate it, answer a chosen end
code, set the CPU error flags (``0040``/``0080``), answer ``2604`` when too many commands are
in progress, refuse the FINS/TCP node allocation.

Every decision comes from one seeded :class:`random.Random` that draws the same number of
values for every request in arrival order, so the same seed gives the same fault sequence
whatever the rules are. Rules apply per run (``rule``) and per command code (``per_command``).
"""

from __future__ import annotations

import logging
import math
import random
import time
from collections.abc import Awaitable, Callable, Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Protocol, TextIO

import anyio
from anyio.abc import TaskGroup

from ..protocol.endcodes import (
    CPU_ERROR_FLAGS,
    FATAL_CPU_ERROR_FLAG,
    NON_FATAL_CPU_ERROR_FLAG,
    RELAY_ERROR_FLAG,
)
from ..protocol.errors import DecodeError
from ..protocol.header import CommandFrame, ResponseFrame
from .state import BUSY

#: "The node receiving the command is already processing 5 commands" (manual 5-1-3).
BUSY_END_CODE = BUSY
#: Commands a CPU Unit processes at once before it answers 2604 (manual 5-1-3).
DEFAULT_MAX_CONCURRENT = 5
#: Delayed (or late) answers a dispatcher holds at once; more are dropped and counted.
DEFAULT_MAX_HELD = 1000
_HEX_DIGITS = b"0123456789ABCDEF"
_logger = logging.getLogger(__name__)


def _check_probability(name: str, value: float) -> None:
    if not 0.0 <= value <= 1.0:
        raise ValueError(f"{name} probability {value} out of range 0..1")


@dataclass(frozen=True, slots=True)
class Delay:
    """A response delay in seconds: fixed (``minimum == maximum``) or uniform in a range."""

    minimum: float
    maximum: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.minimum) and math.isfinite(self.maximum)):
            raise ValueError(f"delay range {self.minimum}..{self.maximum} is not finite")
        if not 0.0 <= self.minimum <= self.maximum:
            raise ValueError(f"delay range {self.minimum}..{self.maximum} is not 0 <= min <= max")

    @classmethod
    def parse_ms(cls, text: str) -> Delay:
        """Parse ``"MS"`` or ``"MIN-MAX"`` (milliseconds), e.g. ``"50"`` or ``"10-200"``."""
        low, sep, high = text.partition("-")
        try:
            lo = float(low)
            hi = float(high) if sep else lo
        except ValueError:
            raise ValueError(f"delay {text!r} is not MS or MIN-MAX (milliseconds)") from None
        return cls(lo / 1000.0, hi / 1000.0)

    def pick(self, u: float) -> float:
        return self.minimum + u * (self.maximum - self.minimum)


@dataclass(frozen=True, slots=True)
class FaultRule:
    """What may go wrong with one command. Probabilities are per request, 0..1.

    ``late`` answers after ``late_after`` seconds instead of ``delay``. ``end_code`` replaces
    the PLC's answer (no data; a relay trailer ``relay`` when bit 15 is set) with probability
    ``end_code_probability``. ``flags`` (``0x40`` non-fatal, ``0x80`` fatal CPU error) are
    OR-ed into the end code of every response.
    """

    drop_request: float = 0.0
    drop_response: float = 0.0
    delay: Delay | None = None
    duplicate: float = 0.0
    reorder: float = 0.0
    corrupt: float = 0.0
    truncate: float = 0.0
    late: float = 0.0
    late_after: float = 0.0
    end_code: int | None = None
    end_code_probability: float = 1.0
    relay: tuple[int, int] = (0, 0)
    flags: int = 0

    def __post_init__(self) -> None:
        for name in (
            "drop_request",
            "drop_response",
            "duplicate",
            "reorder",
            "corrupt",
            "truncate",
            "late",
            "end_code_probability",
        ):
            _check_probability(name, getattr(self, name))
        if not (math.isfinite(self.late_after) and self.late_after >= 0):
            raise ValueError(f"late_after {self.late_after} must be a finite number >= 0")
        if self.end_code is not None and not 0 <= self.end_code <= 0xFFFF:
            raise ValueError(f"end code {self.end_code:#x} out of range 0..0xFFFF")
        if self.flags & ~CPU_ERROR_FLAGS:
            raise ValueError(
                f"flags {self.flags:#x} may only combine"
                f" {NON_FATAL_CPU_ERROR_FLAG:#x} and {FATAL_CPU_ERROR_FLAG:#x}"
            )
        if not all(0 <= b <= 0xFF for b in self.relay):
            raise ValueError(f"relay point {self.relay} out of range 0..255")


@dataclass(frozen=True, slots=True)
class FaultDecision:
    """The faults drawn for one request."""

    drop_request: bool = False
    drop_response: bool = False
    delay: float = 0.0
    late: bool = False
    duplicate: bool = False
    reorder: bool = False
    #: ``(position in 0..1, XOR mask 1..255)``
    corrupt: tuple[float, int] | None = None
    #: fraction of the response kept, 0..1
    truncate: float | None = None
    end_code: int | None = None
    relay: tuple[int, int] = (0, 0)
    flags: int = 0


NO_FAULT = FaultDecision()
#: A rule that injects nothing (the default of a :class:`FaultPlan`).
NO_FAULT_RULE = FaultRule()


@dataclass(slots=True)
class FaultCounters:
    """Frames served and faults injected so far."""

    requests: int = 0
    responses: int = 0
    dropped_requests: int = 0
    dropped_responses: int = 0
    delayed: int = 0
    late: int = 0
    duplicated: int = 0
    reordered: int = 0
    corrupted: int = 0
    truncated: int = 0
    end_codes: int = 0
    flags: int = 0
    busy: int = 0
    tcp_refusals: int = 0
    handler_errors: int = 0
    #: Delayed or late answers dropped because ``max_held`` were already waiting.
    held_dropped: int = 0

    @property
    def faults(self) -> int:
        """Total faults injected."""
        skip = ("requests", "responses", "handler_errors", "held_dropped")
        return sum(v for k, v in self.as_dict().items() if k not in skip)

    def as_dict(self) -> dict[str, int]:
        return asdict(self)


class FrameLog:
    """Hex log of every frame in and out: to a file (path or text stream) or a logger."""

    def __init__(self, target: str | Path | TextIO | logging.Logger) -> None:
        self._logger: logging.Logger | None = None
        self._stream: TextIO | None = None
        self._owned = False
        if isinstance(target, logging.Logger):
            self._logger = target
        elif isinstance(target, (str, Path)):
            self._stream = open(target, "a", encoding="ascii")  # noqa: SIM115
            self._owned = True
        else:
            self._stream = target

    def record(self, direction: str, peer: str, data: bytes) -> None:
        """Write one line: ``direction`` is ``"rx"`` or ``"tx"``."""
        if self._logger is not None:
            self._logger.info("%s %s %s", direction, peer, data.hex(" "))
        elif self._stream is not None:
            self._stream.write(f"{time.time():.6f} {direction} {peer} {data.hex(' ')}\n")
            self._stream.flush()

    def close(self) -> None:
        if self._owned and self._stream is not None:
            self._stream.close()
        self._stream = None


class FaultPlan:
    """Seeded fault configuration, decisions and counters shared by the servers of one run."""

    def __init__(
        self,
        rule: FaultRule | None = None,
        *,
        per_command: Mapping[int, FaultRule] | None = None,
        seed: int | None = None,
        max_concurrent: int | None = None,
        tcp_refusal: int | None = None,
        log: FrameLog | None = None,
        max_held: int = DEFAULT_MAX_HELD,
    ) -> None:
        for name, value in (("max_concurrent", max_concurrent), ("max_held", max_held)):
            if value is None and name == "max_concurrent":
                continue
            # NaN or a float passed '< 1' and then bounded nothing ('waiting >= nan')
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be a whole number, at least 1; got {value!r}")
        if tcp_refusal is not None and not 1 <= tcp_refusal <= 0xFFFFFFFF:
            raise ValueError(f"FINS/TCP refusal code {tcp_refusal:#x} must be non-zero u32")
        self.rule = rule if rule is not None else FaultRule()
        self.per_command: dict[int, FaultRule] = dict(per_command or {})
        self.seed = seed
        self.max_concurrent = max_concurrent
        self.tcp_refusal = tcp_refusal
        self.log = log
        #: Most delayed or late answers held at once (each one waits in a task): over it,
        #: a request that should be answered later is dropped and counted (``held_dropped``).
        self.max_held = max_held
        self.counters = FaultCounters()
        self._rng = random.Random(seed)

    def rule_for(self, command_code: int | None) -> FaultRule:
        if command_code is None:
            return self.rule
        return self.per_command.get(command_code, self.rule)

    def decide(self, request: bytes) -> FaultDecision:
        """Draw the faults for one request (always 13 draws, so sequences stay aligned)."""
        code = int.from_bytes(request[10:12], "big") if len(request) >= 12 else None
        rule = self.rule_for(code)
        rng = self._rng
        u = [rng.random() for _ in range(12)]
        mask = rng.randrange(1, 256)
        late = u[10] < rule.late
        if late:
            delay = rule.late_after
        elif rule.delay is not None:
            delay = rule.delay.pick(u[2])
        else:
            delay = 0.0
        end_code = None
        if rule.end_code is not None and u[11] < rule.end_code_probability:
            end_code = rule.end_code
        return FaultDecision(
            drop_request=u[0] < rule.drop_request,
            drop_response=u[1] < rule.drop_response,
            delay=delay,
            late=late,
            duplicate=u[3] < rule.duplicate,
            reorder=u[4] < rule.reorder,
            corrupt=(u[6], mask) if u[5] < rule.corrupt else None,
            truncate=u[8] if u[7] < rule.truncate else None,
            end_code=end_code,
            relay=rule.relay,
            flags=rule.flags,
        )

    def busy_response(self, request: bytes) -> bytes | None:
        """The 2604 answer to ``request`` (``None`` if it is malformed or wants no answer)."""
        try:
            command = CommandFrame.decode(request)
        except DecodeError:
            return None
        if not command.header.response_required:
            return None
        return ResponseFrame.reply_to(command, BUSY_END_CODE).encode()

    def rewrite(self, response: bytes, decision: FaultDecision) -> bytes:
        """Apply the end-code and flag faults to a FINS response frame."""
        if len(response) < 14:
            return response
        out = bytearray(response)
        if decision.end_code is not None:
            ec = decision.end_code
            out = bytearray(response[:12]) + ec.to_bytes(2, "big")
            if ec & RELAY_ERROR_FLAG:
                out += bytes(decision.relay)
            self.counters.end_codes += 1
        if decision.flags:
            out[13] |= decision.flags
            self.counters.flags += 1
        return bytes(out)

    def damage(self, wire: bytes, decision: FaultDecision, *, hostlink: bool = False) -> bytes:
        """Apply the corrupt and truncate faults to the bytes about to be sent.

        With ``hostlink`` the bytes are a Host Link line: corruption swaps one character
        between ``@`` and ``*`` for another hex digit, truncation keeps the ``*`` CR terminator.
        """
        out = bytearray(wire)
        if decision.corrupt is not None:
            position, mask = decision.corrupt
            lo, hi = (1, len(out) - 2) if hostlink else (0, len(out))
            if hi > lo:
                i = lo + int(position * (hi - lo))
                if hostlink:
                    choices = _HEX_DIGITS.replace(bytes((out[i],)), b"")
                    out[i] = choices[mask % len(choices)]
                else:
                    out[i] ^= mask
                self.counters.corrupted += 1
        if decision.truncate is not None:
            body = out[:-2] if hostlink else out
            if len(body) > 1:
                keep = 1 + int(decision.truncate * (len(body) - 1))
                out = body[:keep] + (b"*\r" if hostlink else b"")
                self.counters.truncated += 1
        return bytes(out)


class FrameHandler(Protocol):
    """What the servers need of a PLC: one FINS command frame in, its response (or none) out."""

    def handle_frame(self, frame: bytes, *, from_network: bool = True) -> bytes | None:
        """``from_network=False``: the frame came in on the CPU's own serial port."""
        ...


#: Sends the bytes of one response to the peer that asked.
Send = Callable[[bytes], Awaitable[None]]


class Dispatcher:
    """Runs requests through a :class:`FaultPlan` to a PLC and sends what comes out.

    One dispatcher serves one PLC node: the concurrency limit and the held (reordered)
    response are shared by every peer and every server of that node.
    """

    def __init__(self, plc: FrameHandler, plan: FaultPlan | None = None) -> None:
        self.plc = plc
        self.plan = plan if plan is not None else FaultPlan()
        self.in_flight = 0
        #: Delayed or late answers waiting in their own task (at most ``plan.max_held``).
        self.waiting = 0
        self._held: tuple[list[bytes], Send, str] | None = None

    def _handle(self, request: bytes, from_network: bool) -> bytes | None:
        """The PLC's answer to ``request``; ``None`` also when the PLC failed on it."""
        try:
            if from_network:
                return self.plc.handle_frame(request)
            # Host Link on the CPU's own port: not a network, so no network write protection.
            return self.plc.handle_frame(request, from_network=False)
        except Exception:
            # a PLC bug must not take the server down; it is logged and counted
            self.plan.counters.handler_errors += 1
            _logger.exception("the PLC failed on frame %s", request.hex(" "))
            return None

    @property
    def quiet(self) -> bool:
        """No fault, limit or log can apply to the next request: :meth:`answer_now` may."""
        plan = self.plan
        return (
            plan.rule == NO_FAULT_RULE
            and not plan.per_command
            and plan.max_concurrent is None
            and plan.log is None
            and self._held is None
        )

    def answer_now(self, request: bytes) -> bytes | None:
        """Answer ``request`` synchronously (only while :attr:`quiet`); ``None``: no answer.

        The fast path of the asyncio UDP server; :meth:`dispatch` does the same with faults.
        """
        counters = self.plan.counters
        counters.requests += 1
        response = self._handle(request, True)
        if response is not None:
            counters.responses += 1
        return response

    async def dispatch(
        self,
        request: bytes,
        send: Send,
        *,
        peer: str = "",
        encode: Callable[[bytes], bytes] | None = None,
        task_group: TaskGroup | None = None,
        from_network: bool = True,
    ) -> None:
        """Handle one request frame.

        ``encode`` turns a FINS response into the medium's bytes when the fault damage must
        apply to them (a Host Link line). A request that must wait (delay, late answer) runs
        in ``task_group`` when given, so later requests are not held up; every other request
        is answered before this returns, in arrival order.
        """
        plan = self.plan
        counters = plan.counters
        counters.requests += 1
        if plan.log is not None:
            plan.log.record("rx", peer, request)
        decision = plan.decide(request)
        if decision.drop_request:
            counters.dropped_requests += 1
            return
        if plan.max_concurrent is not None and self.in_flight >= plan.max_concurrent:
            busy = plan.busy_response(request)
            if busy is not None:
                counters.busy += 1
                await self._send([encode(busy) if encode else busy], send, peer)
            return
        later = task_group if decision.delay > 0 else None  # answered from its own task
        if later is not None and self.waiting >= plan.max_held:
            counters.held_dropped += 1  # one task per held answer: bounded, not a leak
            return
        if decision.delay > 0:
            if decision.late:
                counters.late += 1
            else:
                counters.delayed += 1
        self.in_flight += 1
        if later is not None:
            self.waiting += 1
            later.start_soon(
                self._answer_later, request, decision, send, peer, encode, from_network
            )
        else:
            await self._answer(request, decision, send, peer, encode, from_network)

    async def _answer_later(
        self,
        request: bytes,
        decision: FaultDecision,
        send: Send,
        peer: str,
        encode: Callable[[bytes], bytes] | None,
        from_network: bool,
    ) -> None:
        try:
            await self._answer(request, decision, send, peer, encode, from_network)
        finally:
            self.waiting -= 1

    async def _answer(
        self,
        request: bytes,
        decision: FaultDecision,
        send: Send,
        peer: str,
        encode: Callable[[bytes], bytes] | None,
        from_network: bool = True,
    ) -> None:
        plan = self.plan
        counters = plan.counters
        try:
            if decision.delay > 0:
                await anyio.sleep(decision.delay)
            response = self._handle(request, from_network)
        finally:
            self.in_flight -= 1
        if response is None:
            return
        response = plan.rewrite(response, decision)
        if decision.drop_response:
            counters.dropped_responses += 1
            return
        wire = encode(response) if encode else response
        wire = plan.damage(wire, decision, hostlink=encode is not None)
        copies = [wire, wire] if decision.duplicate else [wire]
        if decision.duplicate:
            counters.duplicated += 1
        if decision.reorder and self._held is None:
            counters.reordered += 1
            self._held = (copies, send, peer)
            return
        held, self._held = self._held, None
        await self._send(copies, send, peer)
        if held is not None:
            await self._send(*held)

    async def _send(self, copies: list[bytes], send: Send, peer: str) -> None:
        for wire in copies:
            # counted when handed to the medium, so counters are final once a peer has it
            self.plan.counters.responses += 1
            if self.plan.log is not None:
                self.plan.log.record("tx", peer, wire)
            try:
                await send(wire)
            except (anyio.ClosedResourceError, anyio.BrokenResourceError, OSError):
                return  # the peer went away; a real PLC would not notice either


__all__ = [
    "BUSY_END_CODE",
    "DEFAULT_MAX_CONCURRENT",
    "DEFAULT_MAX_HELD",
    "NO_FAULT",
    "Delay",
    "Dispatcher",
    "FaultCounters",
    "FaultDecision",
    "FaultPlan",
    "FaultRule",
    "FrameHandler",
    "FrameLog",
    "Send",
]
