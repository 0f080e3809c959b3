"""Placeholder: being written."""

from __future__ import annotations

from typing import Any

from ._base import Request

OPERATIONS: tuple[type[Request[Any]], ...] = ()
