"""``aiofins doctor URL``: diagnose a connection (see :mod:`aiofins.doctor`).

Prints one line per finding (``ok``, ``warning`` or ``problem``), with its fix under it, and
the URL with the fixes applied. Exit code: 0 no problem, 3 the PLC answers but something is
wrong (each problem names its fix), 4 nothing answered; 1 an error (a bad URL, a host name
that does not resolve), 2 bad arguments. ``--json`` prints one document instead
(docs/cli-json.md).

Read-only unless ``--write-test``: then the word at ``--address`` is read and written back
with its own value (a program writing that word meanwhile would see it put back).
"""

from __future__ import annotations

import argparse
import json
from typing import Any

import anyio

from ..doctor import Diagnosis, Severity, diagnose
from .options import add_timeout
from .text import escape


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "doctor",
        help="diagnose a connection: transports, node, reply port, CPU, writes, round trip",
    )
    p.add_argument("url", help="udp://HOST[:PORT] or tcp://HOST[:PORT] (with its options)")
    add_timeout(p, 1.0, "seconds each probe waits (default 1)")
    p.add_argument(
        "--rounds", type=int, default=5, help="status reads timed for the round trip (default 5)"
    )
    p.add_argument(
        "--address", default="D0", help="the word read (and written back) by the checks (D0)"
    )
    p.add_argument(
        "--write-test",
        action="store_true",
        help="write the word at --address back with its own value, to see whether writes "
        "are refused and why (default: read-only checks)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON document")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    async def main() -> Diagnosis:
        return await diagnose(
            args.url,
            timeout=args.timeout,
            rounds=args.rounds,
            address=args.address,
            write_test=args.write_test,
        )

    diagnosis = anyio.run(main)
    if args.json:
        print(json.dumps(diagnosis.as_json(), sort_keys=True))
    else:
        print_text(diagnosis)
    return diagnosis.exit_code


_WIDTH = max(len(s.value) for s in Severity)


def print_text(diagnosis: Diagnosis) -> None:
    """The findings, one a line, each fix under its finding; then the suggested URL."""
    print(f"aiofins doctor {escape(diagnosis.url)}")
    for finding in diagnosis.findings:
        print(f"  {finding.severity.value:<{_WIDTH}}  {finding.check}: {escape(finding.summary)}")
        if finding.fix and finding.severity is not Severity.OK:
            print(f"  {'':<{_WIDTH}}    fix: {escape(finding.fix)}")
    summary: dict[int, Any] = {
        0: "no problem found",
        3: f"{len(diagnosis.problems)} problem(s) found",
        4: "the PLC did not answer",
    }
    print(summary[diagnosis.exit_code])
    if diagnosis.problems and diagnosis.suggested_url not in (None, diagnosis.url):
        print(f"try: {escape(diagnosis.suggested_url)}")
