"""The request multiplexer: :class:`Session`, :class:`Response`, :class:`SessionStats`."""

from __future__ import annotations

from .core import Session
from .response import Response, SessionStats

__all__ = ["Response", "Session", "SessionStats"]
