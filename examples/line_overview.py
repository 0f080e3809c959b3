"""Read the same tags from every PLC of a line at once and print one table row per PLC.

One :class:`aiofins.Pool` keeps a session per PLC; the reads run concurrently in a task
group, so a slow or dead PLC costs its own timeout, not everyone's. A PLC that does not
answer gets a row saying why.

    python examples/line_overview.py                            # just PLC_URL
    python examples/line_overview.py udp://10.0.1.1 udp://10.0.1.2 udp://10.0.1.3
"""

from __future__ import annotations

import argparse
import os

import anyio

import aiofins

PLC_URL = os.environ.get("PLC_URL", "udp://127.0.0.1")

TAGS = {"state": "D0:uint16", "speed": "D10:float32", "count": "D20:uint32", "fault": "W0.00"}


async def overview(urls: list[str]) -> None:
    rows: dict[str, str] = {}

    async def read_one(pool: aiofins.Pool, url: str) -> None:
        try:
            async with pool.client(url) as plc:
                tags = await plc.read_tags(TAGS)
            rows[url] = "  ".join(f"{name}={value!r:<8}" for name, value in tags.items())
        except aiofins.FinsError as exc:
            rows[url] = f"{type(exc).__name__}: {exc}"

    async with (
        aiofins.Pool(timeout=1.0, retries=1, read_only=True) as pool,
        anyio.create_task_group() as tg,
    ):
        for url in urls:
            tg.start_soon(read_one, pool, url)
    width = max(map(len, urls))
    for url in urls:  # in the order given, whichever answered first
        print(f"{url:<{width}}  {rows[url]}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("urls", nargs="*", default=[PLC_URL], help="default: $PLC_URL")
    anyio.run(overview, parser.parse_args().urls)
