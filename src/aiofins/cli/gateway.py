"""``aiofins gateway CONFIG.toml [--shard I/N] [--check]``: the MQTT polling daemon.

Reads and checks the whole configuration first (every mistake reported with FILE:LINE,
exit code 2, nothing connected), then runs until SIGINT or SIGTERM. The shard comes from
``--shard``, else ``AIOFINS_SHARD=I/N`` or ``AIOFINS_SHARDS=N`` with the host name's ordinal
(see :mod:`aiofins.gateway.sharding`). Needs the ``gateway`` extra (paho-mqtt,
prometheus_client).
"""

from __future__ import annotations

import argparse
import gc
import logging
import os
import signal
import sys
from typing import TYPE_CHECKING, Any

import anyio

from ..protocol.errors import CommandError

log = logging.getLogger("aiofins.gateway")
#: Seconds at most that the garbage collector waits for every PLC's first scan at start.
START_GC_PAUSE = 30.0

if TYPE_CHECKING:
    SubParsers = argparse._SubParsersAction[argparse.ArgumentParser]
else:
    SubParsers = Any


def add_parser(sub: SubParsers) -> None:
    p = sub.add_parser(
        "gateway",
        help="poll PLCs and publish their tags to MQTT (needs aiofins[gateway])",
        description="Run the MQTT gateway described by CONFIG (TOML; see docs/gateway.md) "
        "until SIGINT/SIGTERM.",
    )
    p.add_argument("config", help="the gateway's TOML configuration")
    p.add_argument("--shard", metavar="I/N", help="poll only shard I of N (env AIOFINS_SHARD)")
    p.add_argument("--check", action="store_true", help="check the configuration and exit")
    # Logging options are the shared ones (cli/logs.py); the daemon logs at INFO by default.
    p.set_defaults(func=run, log_default=logging.INFO)


def run(args: argparse.Namespace) -> int:
    from ..gateway.config import ConfigError, load_config
    from ..gateway.sharding import parse_shard, shard_from_env

    try:
        config = load_config(args.config)
        shard = parse_shard(args.shard) if args.shard else shard_from_env(os.environ)
    except ConfigError as exc:
        for line in exc.problems:
            print(line, file=sys.stderr)
        return 2
    except CommandError as exc:
        print(f"aiofins gateway: {exc}", file=sys.stderr)
        return 2
    if args.check:
        mine = len(config.plcs) if shard is None else len(shard.select(p.name for p in config.plcs))
        print(f"{args.config}: OK, {mine} of {len(config.plcs)} PLCs, {len(config.groups)} groups")
        return 0
    try:
        from ..gateway.daemon import Gateway
    except ImportError as exc:
        print(
            f"aiofins gateway needs: pip install -e '.[gateway]' in a clone of aiofins ({exc})",
            file=sys.stderr,
        )
        return 2

    fatal: list[BaseException] = []

    async def freeze(gateway: Gateway) -> None:
        """Python's cyclic garbage collector is off while the gateway starts, and once every
        PLC has been scanned (or after :data:`START_GC_PAUSE` s) the objects it holds for
        good are frozen and collection resumes: a full collection over the 400,000 objects
        of a 1,000-PLC gateway held the loop 0.3-0.8 s, five times during its start and now
        and then after, delaying every scan; from then on full collections skip them."""
        with anyio.move_on_after(START_GC_PAUSE):
            await gateway.wait_scanned()
        gc.freeze()
        gc.enable()
        log.debug("%d objects frozen (gc.freeze)", gc.get_freeze_count())

    async def main() -> None:
        gc.disable()  # until freeze(): no full collections while the heap is built
        gateway = Gateway(config, shard=shard)
        async with gateway:
            with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
                async with anyio.create_task_group() as tg:

                    async def stop() -> None:
                        async for _ in signals:
                            gateway.close()
                            return

                    tg.start_soon(stop)
                    tg.start_soon(freeze, gateway)
                    port = gateway.http_port
                    print(
                        f"gateway {gateway.name}: {len(gateway.plcs)} PLCs"
                        + (f", http://{config.http.host}:{port}/metrics" if port else ""),
                        flush=True,
                    )
                    await gateway.wait_closed()
                    tg.cancel_scope.cancel()
        if gateway.fatal is not None:
            fatal.append(gateway.fatal)

    try:
        anyio.run(main, backend="asyncio")
    finally:
        gc.enable()
    if fatal:  # a duplicate shard: exit non-zero so the orchestrator shows why
        print(f"aiofins gateway: {fatal[0]}", file=sys.stderr)
        return 3
    return 0
