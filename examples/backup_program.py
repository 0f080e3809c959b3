"""Back up a PLC's user program and parameter areas into a dated folder.

What a maintenance engineer does before changing anything: the program area (raw bytes) and
the parameter areas (PLC Setup, I/O table, routing tables, CPU Bus Unit setup; JSON) go into
``backups/node<N>-<date>T<time>/``, with a progress line on a terminal. Reads only: the PLC
can stay in RUN mode. ``aiofins restore URL FILE [--what parameters]`` writes them back.

    python examples/backup_program.py
    PLC_URL=udp://192.168.250.1 python examples/backup_program.py --folder /srv/plc-backups
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from datetime import datetime
from pathlib import Path

import anyio

import aiofins
from aiofins.bulk import Progress, backup_parameters, backup_program

PLC_URL = os.environ.get("PLC_URL", "udp://127.0.0.1")


def progress(what: str) -> Progress | None:
    """A progress line on a terminal (none in a log file)."""

    def show(done: int, total: int | None) -> None:
        print(f"\r{what}: {done} of {total or '?'}", end="", file=sys.stderr, flush=True)

    return show if sys.stderr.isatty() else None


async def backup(folder: Path) -> Path:
    async with aiofins.connect(PLC_URL, timeout=2.0, read_only=True) as plc:
        data = await plc.cpu_unit_data_read()
        program = await backup_program(plc, progress("\nprogram bytes"))
        parameters = await backup_parameters(plc, progress=progress("\nparameter words"))
    stamp = datetime.now().strftime("%Y-%m-%dT%H%M%S")
    target = folder / f"node{plc.dest.node}-{stamp}"
    target.mkdir(parents=True)
    (target / "program.bin").write_bytes(program)
    areas = {f"{area:04X}": list(words) for area, words in parameters.items()}
    (target / "parameters.json").write_text(json.dumps(areas))
    (target / "cpu.txt").write_text(f"{data.model} {data.internal_system_version}\n")
    print(f"{data.model}: {len(program)} program bytes, {len(parameters)} parameter areas")
    print(f"saved in {target}")
    return target


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--folder", type=Path, default=Path("backups"), help="default: backups")
    anyio.run(backup, parser.parse_args().folder)
