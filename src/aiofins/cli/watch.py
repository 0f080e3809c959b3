"""``aiofins watch URL [TAG...] [--tags FILE]``: a live view of tags in the terminal.

One row per tag: its value, its quality, a sparkline of its recent values and their range,
redrawn after every scan (`rich <https://rich.readthedocs.io/>`_, the ``watch`` extra). The
tags are those of ``aiofins poll``; the scans are the :class:`~aiofins.Poller`'s, so a PLC
that stops answering turns its tags STALE (the last value kept) and says why in the header.

The parts that decide what is shown (:class:`Trend`, :func:`sparkline`) need no terminal and
no ``rich``; only :func:`render` and :func:`watch` use it.
"""

from __future__ import annotations

import argparse
import math
import time
from collections import deque
from collections.abc import Sequence
from contextlib import suppress
from typing import TYPE_CHECKING

import anyio

from ..poller import Poller, Quality, Snapshot, TagReading
from ..pool import Pool
from ..protocol.errors import CommandError
from .options import add_timeout, add_url_and_tags
from .poll import collect_tags
from .text import escape

if TYPE_CHECKING:
    from rich.console import RenderableType

#: Eight heights of a sparkline, lowest first.
BARS = "▁▂▃▄▅▆▇█"
#: What the trend column shows for a scan whose value was not read (or not a number).
GAP = " "
INSTALL_HINT = "aiofins watch needs rich: pip install -e '.[watch]' (or pip install rich)"


def sparkline(values: Sequence[float | None]) -> str:
    """One bar per value, scaled between the lowest and the highest (``None``: a gap).

    All values equal: a flat line at mid height, so a constant still shows as a trend.
    """
    numbers = [v for v in values if v is not None]
    if not numbers:
        return GAP * len(values)
    low, high = min(numbers), max(numbers)
    span = high - low
    top = len(BARS) - 1
    bars = []
    for v in values:
        if v is None:
            bars.append(GAP)
        elif span == 0:
            bars.append(BARS[top // 2])
        else:
            bars.append(BARS[round((v - low) / span * top)])
    return "".join(bars)


def as_number(value: object) -> float | None:
    """A value's place on a trend: numbers as they are, bits as 0/1, anything else none."""
    if isinstance(value, bool):
        return float(value)
    if isinstance(value, (int, float)) and math.isfinite(value):
        return float(value)
    return None


class Trend:
    """The last ``length`` values of each tag, one entry per scan (``None`` where a scan
    did not read the tag, so gaps stay in time with the other tags)."""

    def __init__(self, names: Sequence[str], length: int) -> None:
        if length < 1:
            raise CommandError(f"--history {length}: give at least 1 scan")
        self.length = length
        self.history: dict[str, deque[float | None]] = {n: deque(maxlen=length) for n in names}

    def add(self, snap: Snapshot) -> None:
        for name, values in self.history.items():
            reading = snap.readings.get(name)
            good = reading is not None and reading.quality is Quality.GOOD
            values.append(as_number(reading.value) if good and reading is not None else None)

    def line(self, name: str, scans: int | None = None) -> str:
        """The sparkline of the last ``scans`` scans (all kept by default)."""
        values = list(self.history[name])
        return sparkline(values if scans is None else values[-scans:])

    def range(self, name: str) -> tuple[float, float] | None:
        numbers = [v for v in self.history[name] if v is not None]
        return (min(numbers), max(numbers)) if numbers else None


def format_value(reading: TagReading) -> str:
    value = reading.value
    if isinstance(value, float):
        return f"{value:.6g}"
    if value is None:
        return "-"
    return escape(value)


def _number(value: float) -> str:
    return f"{value:.6g}"


#: The table's columns; the trend takes the width the others leave (``trend_width``).
COLUMNS = ("tag", "address", "value", "quality", "trend", "min", "max")
#: Spaces between two columns.
GUTTER = 2


def trend_width(cells: list[list[str]], width: int, history: int) -> int:
    """How many scans the trend column shows in ``width`` characters: what the other
    columns (each as wide as its widest cell or header) leave, at most ``history``, at
    least 1. A narrow terminal shortens the trend (its latest scans kept), not the names
    and values."""
    others = [
        max([len(column), *(len(row[i]) for row in cells)])
        for i, column in enumerate(COLUMNS)
        if column != "trend"
    ]
    room = width - sum(others) - GUTTER * (len(COLUMNS) - 1)
    return max(1, min(history, room))


def render(
    url: str, tags: dict[str, str], snap: Snapshot, trend: Trend, width: int
) -> RenderableType:
    """The screen after ``snap`` for a terminal ``width`` characters wide: a header line
    and the table of tags."""
    from rich.console import Group
    from rich.table import Table
    from rich.text import Text

    when = time.strftime("%H:%M:%S", time.localtime(snap.timestamp))
    header = Text(f"aiofins watch {escape(url)}   scan {snap.scan}   ", style="bold")
    header.append(f"{snap.duration * 1000:.1f} ms   {when}", style="dim")
    if snap.error is not None:
        header.append(f"\n{escape(snap.error)}", style="bold red")
    cells = []
    for name, spec in tags.items():
        reading = snap.readings[name]
        span = trend.range(name)
        low, high = (_number(span[0]), _number(span[1])) if span else ("", "")
        value, state = format_value(reading), reading.quality.value
        cells.append([escape(name), escape(spec), value, state, "", low, high])
    shown = trend_width(cells, width, trend.length)
    table = Table(box=None, pad_edge=False, header_style="bold", padding=(0, GUTTER // 2))
    for column in COLUMNS:
        right = column in ("value", "min", "max")
        size = shown if column == "trend" else None
        table.add_column(
            column,
            justify="right" if right else "left",
            no_wrap=True,
            min_width=size,
            max_width=size,
        )
    styles = {Quality.GOOD: "green", Quality.STALE: "yellow", Quality.ERROR: "red"}
    for name, row in zip(tags, cells, strict=True):
        quality = snap.readings[name].quality
        table.add_row(
            Text(row[0]),
            Text(row[1], style="dim"),
            Text(row[2]),
            Text(row[3], style=styles[quality]),
            Text(trend.line(name, shown), style="cyan"),
            Text(row[5]),
            Text(row[6]),
        )
    footer = Text("Ctrl-C to stop", style="dim")
    return Group(header, Text(""), table, Text(""), footer)


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "watch",
        help="live view of tags in the terminal: values and a trend per tag",
        description="Poll tags and show them live in the terminal: value, quality and a "
        "sparkline of the last scans per tag, redrawn after every scan. Needs the watch "
        "extra (rich).",
    )
    add_url_and_tags(p)
    p.add_argument("--interval", type=float, default=0.5, help="seconds between scans")
    p.add_argument("--history", type=int, default=40, help="scans in the trend (default 40)")
    p.add_argument("--count", type=int, default=0, help="stop after N scans (0: run until ^C)")
    p.add_argument("--dest", help="destination FINS address NET.NODE.UNIT")
    p.add_argument("--src", help="source FINS address NET.NODE.UNIT")
    add_timeout(p, 2.0, "seconds per attempt")
    p.set_defaults(func=run, trailing="tags")  # TAGs after options too: see cli.main


async def watch(args: argparse.Namespace) -> None:
    tags = collect_tags(args)
    trend = Trend(list(tags), args.history)
    try:
        from rich.console import Console
        from rich.live import Live
    except ImportError:
        raise CommandError(INSTALL_HINT) from None
    pool = Pool(
        read_only=True,  # watching only reads: nothing else can be sent
        timeout=args.timeout,
        dest=args.dest,
        src=args.src,
        tcp_connect_timeout=args.timeout,
    )
    poller = Poller(pool)
    poller.add_group("watch", args.url, tags, interval=args.interval, timeout=args.timeout)
    console = Console()
    async with pool, poller:
        with Live(console=console, auto_refresh=False, transient=False) as live:
            async for snap in poller:
                trend.add(snap)
                live.update(render(args.url, tags, snap, trend, console.width), refresh=True)
                if args.count and snap.scan >= args.count:
                    break
        if not console.is_terminal:  # the last screen printed once: end its line
            console.line()


def run(args: argparse.Namespace) -> int:
    with suppress(KeyboardInterrupt):  # Ctrl-C is how a live view ends
        anyio.run(watch, args)
    return 0
