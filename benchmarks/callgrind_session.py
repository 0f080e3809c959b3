"""Instructions per request of the session's hot path, counted by callgrind (not timed).

Wall-clock rates on a shared VM move by +-30 %; instruction counts do not. This script runs
a :class:`~aiofins.session.Session` over an in-process transport that answers each command
frame from the event loop's next step (``loop.call_soon``: as a socket's reply would come,
without the socket), under ``valgrind --tool=callgrind``, twice per case: with 2,000 and with
12,000 requests. The difference divided by 10,000 is the marginal cost of one request, free
of interpreter start-up and imports. Cases:

- ``request``: sequential ``await session.request(0x01, 0x01, params)``;
- ``many``: ``session.request_many`` of 100 commands at a time, window 50
  (``max_in_flight=50``), per command;
- ``tasks``: 50 tasks on one session (``max_in_flight=50``), each awaiting
  ``session.request`` in a loop, per request;
- ``read``: sequential ``plc.read("D100", 1)`` of a :class:`~aiofins.client.Client` over
  that session (the public API's usual read), per read;
- ``requestnow`` / ``readnow``: ``request`` / ``read`` with the reply there at once: the
  transport has a ``poll_now`` that hands it over, as a peer on the same core answers
  during the send and the session's read right after the send finds the reply (one loop
  step later if that read is not made);
- ``reads``: the same 50 tasks calling ``plc.read("D100", 1)`` of a
  :class:`~aiofins.client.Client` over that session (the public API), per read;
- ``dm``: ``plc.read("D0", 32768)`` (a full DM area, 33 frames of up to 999 words, pipelined
  with ``max_in_flight=50``), per frame, 5 and 25 reads;
- ``dmarray``: the same through ``plc.read_array("D0", 32768)`` (an ``array('H')``), per frame;
- ``dmframes``: the same 33 frames through ``session.request_many`` with prebuilt parameters,
  their data left alone (the session's share of a big read), per frame;
- ``paced``: sequential requests 5 ms apart (a poller's pace: each answered long before its
  retransmission timeout), with the default ``rto_bounds``, 100 and 600 requests; also
  prints how often the deadline watcher woke (its task ran) in the larger run.

By default the retransmission timeout is held at 1.5-2 s (``rto_bounds=(1.5, 2.0)``): under
valgrind a request takes ~1 ms, so with the adaptive default (20 ms floor) the deadline
watcher would wake every few requests, which it does not at full speed (a request takes
~25 us there). ``--adaptive`` measures with the default bounds all the same.

Usage (stock asyncio; valgrind must be installed)::

    python benchmarks/callgrind_session.py                 # this tree
    python benchmarks/callgrind_session.py --src ../old/src  # another tree (a git worktree)

``--inner CASE N`` runs one workload without valgrind (what the outer run starts).
"""

from __future__ import annotations

import argparse
import asyncio
import inspect
import os
import re
import subprocess
import sys
import tempfile
from typing import Any

SMALL, LARGE = 2_000, 12_000
BATCH = 100
TASKS = 50
PACED_SMALL, PACED_LARGE, PACE = 100, 600, 0.005
#: Full DM reads per run of the ``dm`` cases, and frames per read.
DM_SMALL, DM_LARGE, DM_FRAMES = 5, 25, 33


def _has_rto_bounds(session: type) -> bool:
    """Whether the tree's Session takes ``rto_bounds`` (trees before the adaptive RTO do
    not; a compiled Session has no signature to ask, and is of a tree that does)."""
    try:
        return "rto_bounds" in inspect.signature(session).parameters
    except ValueError:
        return True


def _workload(case: str, n: int, adaptive: bool) -> None:
    from aiofins._callplan import read_frames
    from aiofins.client import Client
    from aiofins.protocol.header import FinsAddress
    from aiofins.session import Session
    from aiofins.transport.base import Transport

    class NextStepTransport(Transport):
        """Answers every command frame with a 1-word normal completion, one loop step later."""

        def __init__(self) -> None:
            self._sink: Any = None

        @property
        def is_open(self) -> bool:
            return self._sink is not None

        @property
        def description(self) -> str:
            return "callgrind://next-step"

        async def open(self, sink: Any, task_group: Any) -> None:
            self._sink = sink
            loop = asyncio.get_running_loop()
            call_soon = loop.call_soon
            received = sink.frame_received

            def send(frame: bytes) -> None:
                # ICF C0, RSV, GCT, then the source and destination swapped, SID, command.
                head = b"\xc0\x00\x02" + frame[6:9] + frame[3:6] + frame[9:12]
                reply = head + b"\x00\x00\x00\x2a"
                call_soon(received, reply)

            data: dict[bytes, bytes] = {}

            def send_words(frame: bytes) -> None:
                # A 0101 reply with as many words as asked (bytes 16-17: the count).
                head = b"\xc0\x00\x02" + frame[6:9] + frame[3:6] + frame[9:12] + b"\x00\x00"
                count = frame[16:18]
                words = data.get(count)
                if words is None:
                    n = int.from_bytes(count, "big")
                    words = data[count] = bytes(range(256)) * (n // 128) + bytes(2 * n % 256)
                call_soon(received, head + words)

            if case.startswith("dm"):
                send = send_words
            if case.endswith("now"):  # the reply at once (see the module's docstring)
                queued: list[bytes] = []

                def poll() -> None:
                    while queued:
                        received(queued.pop())

                def send_now(frame: bytes) -> None:
                    head = b"\xc0\x00\x02" + frame[6:9] + frame[3:6] + frame[9:12]
                    queued.append(head + b"\x00\x00\x00\x2a")
                    call_soon(poll)  # (if the session does not read at once)

                send = send_now
                self.poll_now = poll

            self.fast_send = send

        async def send(self, frame: bytes, timeout: float | None = None) -> None:
            assert self.fast_send is not None
            self.fast_send(frame)

        async def aclose(self) -> None:
            self._sink = None
            self.fast_send = None

    params = bytes.fromhex("82006400000001")  # D100, 1 word
    options: dict[str, Any] = {}
    if not adaptive and case != "paced" and _has_rto_bounds(Session):
        options["rto_bounds"] = (1.5, 2.0)  # (trees before the adaptive RTO have none)

    async def main() -> None:
        async with Session(
            NextStepTransport(),
            source=FinsAddress(0, 2, 0),
            dest=FinsAddress(0, 1, 0),
            max_in_flight=50,
            **options,
        ) as session:
            if case in ("request", "requestnow"):
                request = session.request
                for _ in range(n):
                    await request(0x01, 0x01, params, idempotent=True)
            elif case in ("read", "readnow"):
                read = Client(session).read
                for _ in range(n):
                    await read("D100", 1)
            elif case in ("tasks", "reads"):
                request = session.request
                read = Client(session).read

                async def caller(count: int) -> None:
                    if case == "tasks":
                        for _ in range(count):
                            await request(0x01, 0x01, params, idempotent=True)
                    else:
                        for _ in range(count):
                            await read("D100", 1)

                await asyncio.gather(*(caller(n // TASKS) for _ in range(TASKS)))
            elif case in ("dm", "dmarray", "dmframes"):
                plc = Client(session)
                big: Any = plc.read_array if case == "dmarray" else plc.read
                assert len(await big("D0", 32768)) == 32768
                if case == "dmframes":
                    commands = list(read_frames("D0", 32768, 999).commands)
                    for _ in range(n):
                        await session.request_many(commands, idempotent=True)
                else:
                    for _ in range(n):
                        await big("D0", 32768)
            elif case == "paced":
                watcher: Any = session._watcher  # counts its task's wake-ups
                wakes = 0
                expire = watcher.expire

                def counted(now: float) -> None:
                    nonlocal wakes
                    wakes += 1
                    expire(now)

                watcher.expire = counted
                request = session.request
                for _ in range(n):
                    await request(0x01, 0x01, params, idempotent=True)
                    await asyncio.sleep(PACE)
                print(f"wakes {wakes}")
            else:
                commands = [(0x01, 0x01, params)] * BATCH
                for _ in range(n // BATCH):
                    await session.request_many(commands, idempotent=True)

    asyncio.run(main())


def _instructions(case: str, n: int, src: str | None, adaptive: bool) -> tuple[int, str]:
    env = dict(os.environ)
    if src:
        env["PYTHONPATH"] = os.path.abspath(src)
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "callgrind.out")
        command = [
            "valgrind",
            "--tool=callgrind",
            f"--callgrind-out-file={out}",
            sys.executable,
            __file__,
            "--inner",
            case,
            str(n),
        ]
        if adaptive:
            command.append("--adaptive")
        run = subprocess.run(command, check=True, env=env, capture_output=True, text=True)
        with open(out) as f:
            text = f.read()
    match = re.search(r"^(?:summary|totals): (\d+)", text, re.MULTILINE)
    assert match, "no totals in callgrind's output"
    return int(match.group(1)), run.stdout.strip()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--src", help="the src/ directory of the tree to measure")
    parser.add_argument("--adaptive", action="store_true", help="default rto_bounds")
    parser.add_argument("--cases", default="request,many")
    parser.add_argument("--inner", nargs=2, metavar=("CASE", "N"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.inner:
        _workload(args.inner[0], int(args.inner[1]), args.adaptive)
        return
    for case in args.cases.split(","):
        low, high, unit = (SMALL, LARGE, 1)
        if case == "paced":
            low, high = PACED_SMALL, PACED_LARGE
        elif case.startswith("dm"):
            low, high, unit = DM_SMALL, DM_LARGE, DM_FRAMES
        small, _ = _instructions(case, low, args.src, args.adaptive)
        large, said = _instructions(case, high, args.src, args.adaptive)
        per = (large - small) / (high - low) / unit
        extra = f" ({said} in {high} requests)" if said else ""
        what = "frame" if unit > 1 else "request"
        print(f"{case:8s} {per / 1000:8.1f}k instructions per {what}{extra}", flush=True)


if __name__ == "__main__":
    main()
