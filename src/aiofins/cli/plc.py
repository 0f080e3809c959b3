"""``aiofins read|write|status|info|clock|ping URL ...``: one-shot commands against a PLC.

Stable interface (scripts depend on it): ``--json`` prints one JSON document on stdout; errors
go to stderr with a non-zero exit code. A response with the CPU error flags (end code bits 6/7)
still succeeds; a warning goes to stderr. ``--dest NET.NODE.UNIT``, ``--src NET.NODE.UNIT`` and
``--timeout S`` work on every command.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from collections.abc import Awaitable, Callable
from datetime import datetime
from enum import Enum
from typing import Any

import anyio

from ..client import Client
from ..connection import connect
from ..protocol.endcodes import EndCode
from ..protocol.errors import CommandError
from ..protocol.values import TYPE_NAMES, Value, parse_value_type
from .text import escape

Handler = Callable[[Client, argparse.Namespace], Awaitable[Any]]


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("url", help="udp://HOST[:PORT], tcp://HOST[:PORT] or serial://DEVICE?baudrate=N")
    p.add_argument("--dest", help="destination FINS address NET.NODE.UNIT")
    p.add_argument("--src", help="source FINS address NET.NODE.UNIT")
    p.add_argument("--timeout", type=float, default=2.0, help="seconds per attempt (default 2)")
    p.add_argument("--json", action="store_true", help="print one JSON document")


def add_parsers(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    types = f"value type: {', '.join(TYPE_NAMES)} (string:N; :ABCD etc. for word order)"
    p = sub.add_parser("read", help="read words, bits or typed values")
    _common(p)
    p.add_argument("address", help='e.g. D100, "CIO 0.01", W5, E3_100, T10')
    p.add_argument("count", nargs="?", type=int, default=1, help="number of values (default 1)")
    p.add_argument("--type", default=None, help=types)
    p.set_defaults(func=_runner(_read))

    p = sub.add_parser("write", help="write words, bits or typed values")
    _common(p)
    p.add_argument("address")
    p.add_argument(
        "values",
        nargs="+",
        help="values to write (0x.. hex accepted for integers; put -- before the values if one "
        "starts with - and is not a plain number, e.g. -- -1e10)",
    )
    p.add_argument("--type", default=None, help=types)
    p.add_argument(
        "--allow-split", action="store_true", help="allow a non-atomic write of several frames"
    )
    p.set_defaults(func=_runner(_write))

    for name, handler, text in (
        ("status", _status, "CPU UNIT STATUS READ (0601): mode, errors, messages"),
        ("info", _info, "CPU UNIT DATA READ (0501): model, version, areas"),
        ("clock", _clock, "CLOCK READ (0701)"),
        ("ping", _ping, "round-trip time of CPU UNIT STATUS READ (0601), in ms"),
    ):
        p = sub.add_parser(name, help=text)
        _common(p)
        if name == "ping":
            p.add_argument("--count", type=int, default=4, help="number of pings (default 4)")
        p.set_defaults(func=_runner(handler))


def _runner(handler: Handler) -> Callable[[argparse.Namespace], int]:
    def run(args: argparse.Namespace) -> int:
        result = anyio.run(_with_client, handler, args)
        if args.json:
            print(json.dumps(result, default=_json_default, sort_keys=True))
        else:
            _print_text(result)
        return 0

    return run


async def _with_client(handler: Handler, args: argparse.Namespace) -> Any:
    async with connect(args.url, dest=args.dest, src=args.src, timeout=args.timeout) as plc:
        result = await handler(plc, args)
        warn_of_cpu_errors(plc.last_end_code)
        return result


def warn_of_cpu_errors(end_code: EndCode | None) -> bool:
    """End code bits 6/7 do not fail a command; say on stderr that the PLC has an error
    (and return whether it did)."""
    if end_code is None:
        return False
    kinds = [
        kind
        for kind, flag in (
            ("fatal", end_code.fatal_cpu_error),
            ("non-fatal", end_code.non_fatal_cpu_error),
        )
        if flag
    ]
    if kinds:
        print(
            f"aiofins: warning: the PLC reports a {' and a '.join(kinds)} CPU error "
            f"(end code {end_code.raw:04X}); 'aiofins status' shows which",
            file=sys.stderr,
        )
    return bool(kinds)


def _json_default(value: object) -> object:
    if isinstance(value, datetime):
        return value.isoformat()
    if isinstance(value, bytes):
        return value.hex()
    if hasattr(value, "name") and hasattr(value, "value"):
        return str(getattr(value, "name", value))
    return str(value)


def _print_text(result: Any, prefix: str = "") -> None:
    """``key: value`` lines; nested objects as ``outer.inner: value``. Values come from the
    PLC: control characters are shown escaped (:func:`~aiofins.cli.text.escape`)."""
    if isinstance(result, dict):
        for key, value in result.items():
            if isinstance(value, dict):
                _print_text(value, f"{prefix}{key}.")
                continue
            if isinstance(value, list):
                value = " ".join(escape(v) for v in value)
            elif not isinstance(value, (int, str)):
                value = _json_default(value)
            print(f"{prefix}{key}: {escape(value)}")
    else:
        print(escape(result))


async def _read(plc: Client, args: argparse.Namespace) -> dict[str, Any]:
    values: list[Value] | list[int]
    if args.type:
        values = await plc.read_values(args.address, args.type, args.count, timeout=args.timeout)
    else:
        values = await plc.read(args.address, args.count, timeout=args.timeout)
    return {"address": args.address, "type": args.type or "raw", "values": values}


def _parse_value(text: str, kind: str) -> Value:
    """A command-line value of a type's kind; :class:`CommandError` says what was expected."""
    if kind == "string":
        return text
    try:
        return float(text) if kind.startswith("float") else int(text, 0)
    except ValueError:
        expected = "a number" if kind.startswith("float") else "an integer (0x.. hex accepted)"
        raise CommandError(f"value {text!r} is not {expected}") from None


async def _write(plc: Client, args: argparse.Namespace) -> dict[str, Any]:
    if args.type:
        vtype = parse_value_type(args.type)
        values = [_parse_value(v, vtype.kind) for v in args.values]
        await plc.write_values(
            args.address, values, args.type, allow_split=args.allow_split, timeout=args.timeout
        )
    else:
        words = [int(_parse_value(v, "int")) for v in args.values]
        await plc.write(args.address, words, allow_split=args.allow_split, timeout=args.timeout)
    return {"address": args.address, "written": len(args.values)}


async def _status(plc: Client, args: argparse.Namespace) -> dict[str, Any]:
    s = await plc.cpu_unit_status_read(timeout=args.timeout)
    return {
        "status": s.status,
        "running": s.running,
        "standby": s.standby,
        "battery_present": s.battery_present,
        "flash_writing": s.flash_writing,
        "mode": s.mode.name,
        "fatal_errors": [f.name for f in type(s.fatal_errors) if f in s.fatal_errors],
        "non_fatal_errors": [f.name for f in type(s.non_fatal_errors) if f in s.non_fatal_errors],
        "message_flags": s.message_flags,
        "error_code": f"{s.error_code:04X}",
        "error_message": s.error_message,
    }


async def _info(plc: Client, args: argparse.Namespace) -> dict[str, Any]:
    data = _plain(await plc.cpu_unit_data_read(timeout=args.timeout))
    assert isinstance(data, dict)
    return data


#: Fields the manual marks reserved: left out of ``info``.
_RESERVED = frozenset({"reserved", "system_reserved"})


def _plain(value: object) -> object:
    """JSON-ready data: dataclasses as nested objects (reserved bytes left out), enums by name."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {
            f.name: _plain(getattr(value, f.name))
            for f in dataclasses.fields(value)
            if f.name not in _RESERVED
        }
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, Enum):
        return value.name
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    return _json_default(value)


async def _clock(plc: Client, args: argparse.Namespace) -> dict[str, Any]:
    c = await plc.clock_read(timeout=args.timeout)
    return {"time": c.time, "day_of_week": c.day_of_week}


async def _ping(plc: Client, args: argparse.Namespace) -> dict[str, Any]:
    if args.count < 1:
        raise CommandError(f"--count {args.count}: give the number of pings, at least 1")
    times: list[float] = []
    for _ in range(args.count):
        start = time.perf_counter()
        await plc.cpu_unit_status_read(timeout=args.timeout)
        times.append((time.perf_counter() - start) * 1000)
    return {
        "count": len(times),
        "min_ms": round(min(times), 3),
        "avg_ms": round(sum(times) / len(times), 3),
        "max_ms": round(max(times), 3),
    }
