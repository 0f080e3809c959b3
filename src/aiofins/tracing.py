"""OpenTelemetry tracing: a span per FINS request (the ``aiofins[otel]`` extra).

Built on the event hooks: :class:`FinsTracing` starts a client span when a request's frame
goes out (as a child of the caller's current span), adds an event per retransmission, and
ends the span at the reply (its end code; an error end code sets the span's status) or at
the timeout. Attributes: ``fins.endpoint``, ``fins.dest``, ``fins.command_code``
(``"0101"``), ``fins.command_family``, ``fins.sid``, ``fins.end_code`` (``"0000"``) and
``fins.retries``.

::

    tracing = FinsTracing()                       # the global tracer provider
    async with aiofins.connect(url, hooks=tracing.hooks) as plc:
        await plc.read("D100", 10)                # one span "FINS 0101 memory"

A request cancelled by its caller gets no event: its span ends, marked ``cancelled``, when
its SID is used again, so at most one span per SID of a destination stays open.
"""

from __future__ import annotations

from opentelemetry import trace
from opentelemetry.trace import Span, SpanKind, Status, StatusCode, Tracer, TracerProvider

from .hooks import (
    EventHooks,
    RequestRetried,
    RequestSent,
    RequestTimedOut,
    ResponseReceived,
    command_family,
)
from .protocol.frames import ERROR_BITS
from .protocol.header import FinsAddress

__all__ = ["FinsTracing"]

_Key = tuple[str, FinsAddress, int]


class FinsTracing:
    """Spans for requests, from event hooks (give :attr:`hooks` to ``connect``/``Pool``)."""

    def __init__(self, tracer_provider: TracerProvider | None = None) -> None:
        self.tracer: Tracer = trace.get_tracer("aiofins", tracer_provider=tracer_provider)
        self._open: dict[_Key, Span] = {}
        #: The hooks that make the spans.
        self.hooks = EventHooks(
            request_sent=[self.request_sent],
            request_retried=[self.request_retried],
            response_received=[self.response_received],
            request_timed_out=[self.request_timed_out],
        )

    def request_sent(self, event: RequestSent) -> None:
        key = (event.endpoint, event.dest, event.sid)
        stale = self._open.pop(key, None)
        if stale is not None:  # its caller gave up (cancelled): no reply event came
            stale.set_attribute("fins.cancelled", True)
            stale.end()
        family = command_family(event.command_code)
        self._open[key] = self.tracer.start_span(
            f"FINS {event.command_code:04X} {family}",
            kind=SpanKind.CLIENT,
            attributes={
                "fins.endpoint": event.endpoint,
                "fins.dest": str(event.dest),
                "fins.command_code": f"{event.command_code:04X}",
                "fins.command_family": family,
                "fins.sid": event.sid,
                "fins.retries": 0,
            },
        )

    def request_retried(self, event: RequestRetried) -> None:
        span = self._open.get((event.endpoint, event.dest, event.sid))
        if span is not None:
            span.set_attribute("fins.retries", event.attempt - 1)
            span.add_event(
                "retransmission", {"fins.attempt": event.attempt, "fins.elapsed": event.elapsed}
            )

    def response_received(self, event: ResponseReceived) -> None:
        span = self._open.pop((event.endpoint, event.dest, event.sid), None)
        if span is None:
            return
        span.set_attribute("fins.end_code", f"{event.end_code:04X}")
        span.set_attribute("fins.retries", event.attempts - 1)
        if event.end_code & ERROR_BITS:
            span.set_status(Status(StatusCode.ERROR, f"end code {event.end_code:04X}"))
        span.end()

    def request_timed_out(self, event: RequestTimedOut) -> None:
        span = self._open.pop((event.endpoint, event.dest, event.sid), None)
        if span is None:
            return
        span.set_attribute("fins.retries", event.attempts - 1)
        span.set_status(Status(StatusCode.ERROR, f"no reply after {event.attempts} transmissions"))
        span.end()
