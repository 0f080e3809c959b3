"""Print the CPU's error log (newest first) and the FAL/FALS message, as a support call asks.

ERROR LOG READ returns up to 20 records: two error codes and when each error occurred, on
the PLC's clock. ``--clear`` clears the log after printing it (ERROR LOG CLEAR), as an
engineer does once the causes are fixed.

    python examples/error_log.py
    PLC_URL=udp://192.168.250.1 python examples/error_log.py --clear
"""

from __future__ import annotations

import argparse
import os
import sys

import anyio

import aiofins

PLC_URL = os.environ.get("PLC_URL", "udp://127.0.0.1")


async def show(clear: bool) -> None:
    async with aiofins.connect(PLC_URL, timeout=2.0) as plc:
        log = await plc.error_log_read(0, 20)
        status = await plc.cpu_unit_status_read()
        print(f"{log.stored_records} of {log.max_records} error log records")
        for record in reversed(log.records):
            when = f"{record.time:%Y-%m-%d %H:%M:%S}"
            print(f"  {when}  error {record.error_code:04X} {record.error_code_2:04X}")
        if status.error_code:
            print(f"current error {status.error_code:04X}: {status.error_message.strip()!r}")
        if clear:
            await plc.error_log_clear()
            print("error log cleared")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clear", action="store_true", help="clear the log after printing it")
    try:
        anyio.run(show, parser.parse_args().clear)
    except aiofins.FinsError as exc:
        sys.exit(f"{type(exc).__name__}: {exc}")
