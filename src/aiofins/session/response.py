"""What a request returns, and the session's counters."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from ..protocol.endcodes import EndCode
from ..protocol.header import Header

if TYPE_CHECKING:
    from collections.abc import Sized

_RING = 1024  # latencies kept for the p99 estimate (a power of two)
RING_MASK = _RING - 1


@dataclass(frozen=True, slots=True)
class Response:
    """A normal-completion response (flags 0040/0080 included, relay errors never).

    ``frame`` is the whole response frame as received; ``data`` the bytes after the end code.
    The header is decoded only when asked for.
    """

    end_code: EndCode
    data: bytes
    frame: bytes

    @property
    def header(self) -> Header:
        return Header.decode(self.frame)

    @property
    def mrc(self) -> int:
        return self.frame[10]

    @property
    def src(self) -> int:
        return self.frame[11]

    @property
    def command_code(self) -> int:
        return (self.frame[10] << 8) | self.frame[11]

    @property
    def relay(self) -> tuple[int, int] | None:
        """Always ``None`` here: a relay error (bit 15) raises :class:`RelayError` instead."""
        return None

    @property
    def fatal_cpu_error(self) -> bool:
        """End code bit 7 (0080): the PLC has a fatal CPU error; the command still worked."""
        return self.end_code.fatal_cpu_error

    @property
    def non_fatal_cpu_error(self) -> bool:
        """End code bit 6 (0040): the PLC has a non-fatal CPU error; the command worked."""
        return self.end_code.non_fatal_cpu_error


_new = object.__new__
_slot: dict[str, Any] = dict(vars(Response))  # the member descriptors of the slots
_set_end_code = _slot["end_code"].__set__
_set_data = _slot["data"].__set__
_set_frame = _slot["frame"].__set__


def new_response(end_code: EndCode, data: bytes, frame: bytes) -> Response:
    """``Response(end_code, data, frame)`` at half the cost (the session's hot path).

    Fills the slots directly instead of through the frozen dataclass's ``__init__``
    (three ``object.__setattr__`` calls); the result is the same in every respect.
    """
    response: Response = _new(Response)
    _set_end_code(response, end_code)
    _set_data(response, data)
    _set_frame(response, frame)
    return response


class SessionStats:
    """Counters of one session; cheap to update on the hot path, read at any time."""

    __slots__ = (
        "_lat_count",
        "_lat_ring",
        "_lat_sum",
        "_pending",
        "background_errors",
        "breaker_rejects",
        "busy_retries",
        "cancelled",
        "completed",
        "connect_failures",
        "connects",
        "disconnects",
        "duplicates",
        "end_code_errors",
        "late_replies",
        "malformed",
        "misdirected",
        "mismatched",
        "retries",
        "sid_exhausted",
        "sid_probes",
        "sid_space_failures",
        "sid_spaces_opened",
        "timeouts",
        "unsolicited",
    )

    def __init__(self, pending: Sized) -> None:
        self._pending = pending
        self.completed = 0
        self.timeouts = 0
        self.cancelled = 0
        self.late_replies = 0
        self.duplicates = 0
        self.unsolicited = 0
        self.mismatched = 0
        #: Replies addressed (DNA DA1 DA2) to another of our addresses than the socket's
        #: that got them (handed to that SID space) or to none of ours (dropped).
        self.misdirected = 0
        self.malformed = 0
        self.retries = 0  # retransmissions (same frame and SID)
        self.background_errors = 0  # background tasks (transport reader...) that raised
        self.sid_exhausted = 0  # times a request found all SIDs of its destination taken
        #: Evidence probes sent while every SID was taken (see spaces.evidence_probe).
        self.sid_probes = 0
        self.sid_spaces_opened = 0  # extra SID spaces (sockets, connections) opened
        self.sid_space_failures = 0  # extra SID spaces that could not be opened
        self.breaker_rejects = 0  # calls failed at once by an open circuit breaker
        self.busy_retries = 0
        self.end_code_errors = 0
        self.connects = 0
        self.connect_failures = 0  # reconnects that failed (the request got ConnectionLost)
        self.disconnects = 0  # connections lost while open (peer closed, socket error)
        self._lat_sum = 0.0
        self._lat_count = 0
        self._lat_ring: list[float] = [0.0] * _RING

    @property
    def in_flight(self) -> int:
        """Requests sent and not yet answered, timed out or cancelled."""
        return len(self._pending)

    @property
    def latency_mean(self) -> float:
        """Mean round-trip time in seconds over every completed request (0.0 if none)."""
        return self._lat_sum / self._lat_count if self._lat_count else 0.0

    @property
    def latency_p99(self) -> float:
        """99th percentile round-trip time in seconds over the last 1,024 replies."""
        ring = sorted(self._lat_ring[: min(self._lat_count, _RING)])
        return ring[min(len(ring) - 1, int(len(ring) * 0.99))] if ring else 0.0

    def as_dict(self) -> dict[str, float]:
        out: dict[str, float] = {n: getattr(self, n) for n in sorted(SESSION_COUNTERS)}
        out["in_flight"] = self.in_flight
        out["latency_mean"] = self.latency_mean
        out["latency_p99"] = self.latency_p99
        return out

    def __repr__(self) -> str:
        inner = ", ".join(f"{k}={v:.6g}" for k, v in self.as_dict().items())
        return f"SessionStats({inner})"


#: The names of :class:`SessionStats`' counters (what a Pool sums per endpoint and the
#: Prometheus collector exports).
SESSION_COUNTERS = tuple(n for n in SessionStats.__slots__ if not n.startswith("_"))


_NORMAL = EndCode(0)


def response_of(frame: bytes) -> Response:
    """The :class:`Response` of a normal-completion reply ``frame`` (its end code read
    from bytes 12-13), made as :func:`new_response` makes one."""
    raw = (frame[12] << 8) | frame[13]
    response: Response = _new(Response)
    _set_end_code(response, EndCode(raw) if raw else _NORMAL)
    _set_data(response, frame[14:])
    _set_frame(response, frame)
    return response


def end_code_of(frame: bytes) -> EndCode:
    """The end code of a reply ``frame`` (bytes 12-13)."""
    raw = (frame[12] << 8) | frame[13]
    return EndCode(raw) if raw else _NORMAL
