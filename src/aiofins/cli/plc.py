"""``aiofins read|write|status|info|clock|ping|run|stop URL ...``: one-shot commands.

``write``, ``run``, ``stop`` and ``clock --set`` change the PLC: on a terminal they ask first
unless ``--yes``; ``--read-only`` refuses them (see :mod:`aiofins.cli.options`).

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

from ..client import Client, type_for_value
from ..connection import connect
from ..protocol.commands.mode import RunMode
from ..protocol.endcodes import EndCode
from ..protocol.errors import CommandError
from ..protocol.inputs import float_value, shown
from ..protocol.values import TYPE_NAMES, Value, parse_value_type
from .options import URL_HELP, add_read_only, add_timeout, add_yes, confirm, refuse
from .text import escape

Handler = Callable[[Client, argparse.Namespace], Awaitable[Any]]


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("url", help=URL_HELP)
    p.add_argument("--dest", help="destination FINS address NET.NODE.UNIT")
    p.add_argument("--src", help="source FINS address NET.NODE.UNIT")
    add_timeout(p, 2.0, "seconds per attempt, and for a FINS/TCP connect and handshake (default 2)")
    p.add_argument("--json", action="store_true", help="print one JSON document")
    add_read_only(p)


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
    p.add_argument("address", help='first address, e.g. D100, "CIO 0.00", E3_100')
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
    add_yes(p)
    p.set_defaults(func=_runner(_write, _ask_write))

    for name, handler, text in (
        ("status", _status, "CPU UNIT STATUS READ (0601): mode, errors, messages"),
        ("info", _info, "CPU UNIT DATA READ (0501): model, version, areas"),
        ("clock", _clock, "CLOCK READ (0701); with --set, CLOCK WRITE (0702) first"),
        ("ping", _ping, "round-trip time of CPU UNIT STATUS READ (0601), in ms"),
    ):
        p = sub.add_parser(name, help=text)
        _common(p)
        if name == "ping":
            p.add_argument("--count", type=int, default=4, help="number of pings (default 4)")
        if name == "clock":
            p.add_argument(
                "--set",
                nargs="?",
                const="now",
                metavar="TIME",
                help="CLOCK WRITE (0702) first: an ISO time (2026-01-02T03:04:05) or, alone, "
                "this computer's local time",
            )
            add_yes(p)
            p.set_defaults(func=_runner(handler, _ask_clock))
            continue
        p.set_defaults(func=_runner(handler))

    p = sub.add_parser("run", help="RUN (0401): switch the PLC to MONITOR (default) or RUN mode")
    _common(p)
    p.add_argument(
        "--mode",
        choices=("monitor", "run"),
        default="monitor",
        help="mode to switch to (default monitor)",
    )
    add_yes(p)
    p.set_defaults(func=_runner(_run, lambda a: f"switch {a.url} to {a.mode.upper()} mode?"))

    p = sub.add_parser("stop", help="STOP (0402): switch the PLC to PROGRAM mode")
    _common(p)
    add_yes(p)
    p.set_defaults(func=_runner(_stop, lambda a: f"stop {a.url} (switch it to PROGRAM mode)?"))


Question = Callable[[argparse.Namespace], str | None]


def _runner(
    handler: Handler, question: Question | None = None
) -> Callable[[argparse.Namespace], int]:
    def run(args: argparse.Namespace) -> int:
        text = question(args) if question is not None and not args.read_only else None
        if text is not None and not confirm(args, text):
            return refuse(args.command)
        result = anyio.run(with_client, handler, args)
        if args.json:
            print(json.dumps(result, default=_json_default, sort_keys=True))
        else:
            _print_text(result)
        return 0

    return run


async def with_client(handler: Handler, args: argparse.Namespace) -> Any:
    """Connect as the command line's options say, run ``handler(plc, args)``, warn of CPU
    error flags in the last reply, and return what the handler returned."""
    async with connect(
        args.url,
        dest=args.dest,
        src=args.src,
        timeout=args.timeout,
        tcp_connect_timeout=args.timeout,  # bounds the FINS/TCP connect and handshake too
        read_only=args.read_only,
    ) as plc:
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


#: Longer integer text is no value of any PLC type (and Python refuses to convert decimal
#: text over 4,300 digits): refused up front with a clear message.
_MAX_INTEGER_TEXT = 64


def _parse_value(text: str, kind: str) -> Value:
    """A command-line value of a type's kind; :class:`CommandError` says what was expected."""
    if kind == "string":
        return text
    if kind.startswith("float"):
        return float_value("value", text, kind)
    if len(text) > _MAX_INTEGER_TEXT:
        raise CommandError(f"value {shown(text)} is too long ({len(text)} characters) for {kind}")
    try:
        return int(text, 0)
    except ValueError:
        raise CommandError(f"value {text!r} is not an integer (0x.. hex accepted)") from None


def _word(text: str) -> int:
    """A value of ``write`` without ``--type``: a word, 0..65535 (a bit, 0 or 1); a value of
    another type names the ``--type`` that writes it."""
    try:
        value: Value = _parse_value(text, "int")
    except CommandError:
        if len(text) > _MAX_INTEGER_TEXT:
            raise
        try:
            value = float_value("value", text)
        except CommandError:
            value = text
    fix = type_for_value(value)
    if fix is None and isinstance(value, int):
        return value
    kind, what = fix or ("string:N", "text")
    raise CommandError(
        f"value {text!r} is no word (a whole number 0..65535, 0x.. hex accepted); to write "
        f"it as {what}, add --type {kind}"
    )


def _ask_write(args: argparse.Namespace) -> str:
    return f"write {len(args.values)} value(s) to {args.address} of {args.url}?"


def _ask_clock(args: argparse.Namespace) -> str | None:
    return None if args.set is None else f"set the clock of {args.url} to {_clock_time(args)}?"


def _clock_time(args: argparse.Namespace) -> datetime:
    """The time ``clock --set`` writes: ``now`` (local time, to the second) or ISO text."""
    if args.set == "now":
        return datetime.now().replace(microsecond=0)
    try:
        return datetime.fromisoformat(args.set)
    except ValueError:
        raise CommandError(
            f"--set {args.set!r}: give an ISO time such as 2026-01-02T03:04:05, or nothing for "
            "this computer's time"
        ) from None


async def _write(plc: Client, args: argparse.Namespace) -> dict[str, Any]:
    if args.type:
        vtype = parse_value_type(args.type)
        values = [_parse_value(v, vtype.kind) for v in args.values]
        await plc.write_values(
            args.address, values, args.type, allow_split=args.allow_split, timeout=args.timeout
        )
    else:
        words = [_word(v) for v in args.values]
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
    if args.set is not None:
        await plc.clock_write(_clock_time(args), timeout=args.timeout)
    c = await plc.clock_read(timeout=args.timeout)
    return {"time": c.time, "day_of_week": c.day_of_week}


async def _ping(plc: Client, args: argparse.Namespace) -> dict[str, Any]:
    if args.count < 1:
        raise CommandError(f"--count {args.count}: give the number of pings, at least 1")
    times: list[float] = []
    # What the user waits for, in wall time: not the event loop's clock (uvloop's reads in
    # 1 ms steps; a LAN round trip is a fraction of that).
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


async def _run(plc: Client, args: argparse.Namespace) -> dict[str, Any]:
    mode = RunMode.RUN if args.mode == "run" else RunMode.MONITOR
    await plc.run(mode, timeout=args.timeout)
    return {"mode": mode.name}


async def _stop(plc: Client, args: argparse.Namespace) -> dict[str, Any]:
    await plc.stop(timeout=args.timeout)
    return {"mode": "PROGRAM"}
