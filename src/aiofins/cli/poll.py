"""``aiofins poll URL [TAG...] [--tags FILE] [--interval S] [--count N] [--changes-only] [--json]``.

A tag is ``ADDRESS[:TYPE]`` or ``NAME=ADDRESS[:TYPE]`` (``temp=D100:float32``, ``CIO 0.01``);
``--tags FILE`` adds the tags of a CSV file (``name,address,type`` or a CX-Programmer symbol
table, see :mod:`aiofins.tagfile`).
Each scan prints one line (or, with ``--json``, one JSON document per line).
"""

from __future__ import annotations

import argparse
import dataclasses
import json

import anyio

from ..poller import Poller, Snapshot
from ..pool import Pool
from ..protocol.errors import CommandError
from ..tagfile import load_tags
from .options import add_timeout, add_url_and_tags
from .plc import warn_of_cpu_errors
from .text import escape


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser("poll", help="poll tags periodically and print each scan")
    add_url_and_tags(p)
    p.add_argument("--interval", type=float, default=1.0, help="seconds between scans")
    p.add_argument("--count", type=int, default=0, help="stop after N scans (0: run until ^C)")
    p.add_argument("--changes-only", action="store_true", help="print only changed tags")
    p.add_argument("--dest", help="destination FINS address NET.NODE.UNIT")
    p.add_argument("--src", help="source FINS address NET.NODE.UNIT")
    add_timeout(p, 2.0, "seconds per attempt")
    p.add_argument("--json", action="store_true", help="one JSON document per scan")
    p.set_defaults(func=run, trailing="tags")  # TAGs after options too: see cli.main


def parse_tags(texts: list[str]) -> dict[str, str]:
    tags: dict[str, str] = {}
    for text in texts:
        name, sep, spec = text.partition("=")
        if not sep:
            name, spec = text, text
        if not name.strip() or not spec.strip():
            raise CommandError(f"tag {text!r} is not ADDRESS[:TYPE] or NAME=ADDRESS[:TYPE]")
        if name.strip() in tags:
            raise CommandError(f"tag name {name.strip()!r} is given twice")
        tags[name.strip()] = spec.strip()
    return tags


def format_line(snap: Snapshot) -> str:
    parts = []
    for name, reading in snap.readings.items():
        value = reading.value
        text = f"{value:.6g}" if isinstance(value, float) else escape(value)
        mark = "" if reading.quality.value == "good" else f"({reading.quality.value})"
        parts.append(f"{name}={text}{mark}")
    line = f"#{snap.scan} " + " ".join(parts)
    return line if snap.error is None else f"{line}  ({escape(snap.error)})"


def to_json(snap: Snapshot) -> str:
    return json.dumps(
        {
            "scan": snap.scan,
            "timestamp": snap.timestamp,
            "duration": snap.duration,
            "error": snap.error,
            "tags": {
                name: {"value": r.value, "quality": r.quality.value, "timestamp": r.timestamp}
                for name, r in snap.readings.items()
            },
        },
        sort_keys=True,
    )


def collect_tags(args: argparse.Namespace) -> dict[str, str]:
    """The tags of the TAG arguments and the ``--tags`` files (``poll`` and ``watch``)."""
    tags = parse_tags(args.tags)
    for path in args.tag_files:
        for name, spec in load_tags(path).items():
            if name in tags:
                raise CommandError(f"tag name {name!r} is given twice ({path})")
            tags[name] = spec
    if not tags:
        raise CommandError("no tags: give ADDRESS[:TYPE] arguments or --tags FILE")
    if args.count < 0:
        raise CommandError(f"--count {args.count}: give a number of scans, or 0 to run until ^C")
    return tags


async def poll(args: argparse.Namespace) -> None:
    tags = collect_tags(args)
    options = {
        "timeout": args.timeout,
        "dest": args.dest,
        "src": args.src,
        "tcp_connect_timeout": args.timeout,  # bounds the FINS/TCP connect and handshake too
    }
    pool = Pool(read_only=True, **options)  # polling only reads: nothing else can be sent
    # Every scan is delivered (--count counts scans); --changes-only filters here.
    poller = Poller(pool)
    # Before anything opens: a bad URL, tag or interval is an error, not a scan error.
    poller.add_group("cli", args.url, tags, interval=args.interval, timeout=args.timeout)
    async with pool, poller:
        warned = False
        async for snap in poller:
            if not warned and snap.error is None:  # CPU error flags (0040/0080): say so once
                async with pool.client(args.url) as client:
                    warned = warn_of_cpu_errors(client.last_end_code)
            shown: Snapshot | None = snap
            if args.changes_only:
                changed = {n: r for n, r in snap.readings.items() if n in snap.changed}
                shown = dataclasses.replace(snap, readings=changed) if changed else None
            if shown is not None:
                print(to_json(shown) if args.json else format_line(shown), flush=True)
            if args.count and snap.scan >= args.count:
                break


def run(args: argparse.Namespace) -> int:
    anyio.run(poll, args)
    return 0
