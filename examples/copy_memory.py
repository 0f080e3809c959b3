"""Copy a block of memory from one PLC to another (or within one PLC), then verify it.

Commissioning a replacement CPU, or cloning a line's setpoints to a new line: read the words
from the source, write them to the target and read them back. Large blocks are split into
frames the route carries (the client's chunking); nothing is written if the read fails.

    python examples/copy_memory.py D1000 500 --to D5000              # within PLC_URL's PLC
    python examples/copy_memory.py D1000 500 --target udp://192.168.250.2
    PLC_URL=udp://192.168.250.1 python examples/copy_memory.py E0_0 32768 --target tcp://10.0.0.9
"""

from __future__ import annotations

import argparse
import os

import anyio

import aiofins

PLC_URL = os.environ.get("PLC_URL", "udp://127.0.0.1")


async def copy(source: str, target: str, start: str, count: int, to: str) -> None:
    async with aiofins.connect(source, timeout=2.0, read_only=True) as plc:
        words = await plc.read(start, count)
    print(f"read {len(words)} words from {start} on {source}")
    async with aiofins.connect(target, timeout=2.0) as plc:
        await plc.write(to, words, allow_split=True)  # one frame or many: not atomic
        if await plc.read(to, count) != words:
            raise SystemExit(f"verify failed: {to} on {target} differs after the write")
    print(f"wrote and verified {len(words)} words at {to} on {target}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("start", help="first word, e.g. D1000")
    parser.add_argument("count", type=int, help="number of words")
    parser.add_argument("--source", default=PLC_URL, help="PLC to read (default: $PLC_URL)")
    parser.add_argument("--target", default=PLC_URL, help="PLC to write (default: $PLC_URL)")
    parser.add_argument("--to", help="first word to write (default: START)")
    args = parser.parse_args()
    anyio.run(copy, args.source, args.target, args.start, args.count, args.to or args.start)
