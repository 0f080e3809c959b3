"""Check a CPU: model, operating mode, cycle time and current errors; exit 1 on a fatal error.

The first look at a PLC, and a health check for a monitoring system (Nagios-style exit code:
0 fine, 1 a fatal error, 2 a non-fatal one). CPU UNIT DATA READ gives the model, CPU UNIT
STATUS READ the mode and error flags, CYCLE TIME READ the scan times.

    python examples/cpu_status.py
    PLC_URL=udp://192.168.250.1 python examples/cpu_status.py
"""

from __future__ import annotations

import argparse
import enum
import os
import sys

import anyio

import aiofins

PLC_URL = os.environ.get("PLC_URL", "udp://127.0.0.1")


def _names(flags: enum.IntFlag) -> list[str]:
    """The names of the bits set (``FatalError``, ``NonFatalError``: one name per bit)."""
    return [str(bit.name) for bit in type(flags) if bit & flags]


async def check() -> int:
    async with aiofins.connect(PLC_URL, timeout=2.0, read_only=True) as plc:
        data = await plc.cpu_unit_data_read()
        status = await plc.cpu_unit_status_read()
        cycle = await plc.cycle_time_read()
    print(f"model        {data.model} (version {data.internal_system_version})")
    print(f"mode         {status.mode.name}")  # PROGRAM, MONITOR or RUN
    if cycle is not None:
        print(f"cycle time   {cycle.average_ms:.1f} ms average, {cycle.maximum_ms:.1f} ms max")
    if status.error_code:
        print(f"error        {status.error_code:04X} {status.error_message.strip()}")
    for name in _names(status.fatal_errors) + _names(status.non_fatal_errors):
        print(f"  flag       {name}")
    if status.fatal_errors:
        return 1
    return 2 if status.non_fatal_errors else 0


if __name__ == "__main__":
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args()  # --help
    try:
        sys.exit(anyio.run(check))
    except aiofins.FinsError as exc:
        sys.exit(f"{type(exc).__name__}: {exc}")
