"""``aiofins backup|restore URL FILE`` and ``aiofins files URL ...``, with a progress bar.

* ``backup URL FILE [--what program|parameters]``: the program area as raw bytes, or the
  parameter areas as JSON (``{"8010": [words...], ...}``).
* ``restore URL FILE [--what program|parameters] [--stop]``: the program needs PROGRAM mode;
  ``--stop`` switches to it first.
* ``files URL list|get|put|delete``: file memory (``--disk card|em``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import anyio

from ..bulk import (
    backup_parameters,
    backup_program,
    check_parameter_backup,
    check_program_image,
    download_file,
    list_files,
    restore_parameters,
    restore_program,
    upload_file,
)
from ..client import Client
from ..protocol.commands.parameter import ParameterAreaWrite
from ..protocol.commands.program import ProgramAreaWrite
from ..protocol.commands.status import CpuMode
from ..protocol.errors import CommandError
from ..protocol.files import Disk
from .options import URL_HELP, add_read_only, add_timeout, add_yes, confirm, refuse
from .plc import with_client
from .text import escape


class ProgressBar:
    """A one-line progress bar on stderr (silent when stderr is not a terminal)."""

    def __init__(self, label: str, unit: str = "bytes") -> None:
        self.label = label
        self.unit = unit
        self.live = sys.stderr.isatty()

    def __call__(self, done: int, total: int | None) -> None:
        if not self.live:
            return
        if total:
            filled = int(30 * done / total)
            bar = "#" * filled + "." * (30 - filled)
            text = f"\r{self.label} [{bar}] {100 * done // total:3d}% {done}/{total} {self.unit}"
        else:
            text = f"\r{self.label} {done} {self.unit}"
        sys.stderr.write(text)
        sys.stderr.flush()

    def close(self) -> None:
        if self.live:
            sys.stderr.write("\n")


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("url", help=URL_HELP)
    p.add_argument("--dest", help="destination FINS address NET.NODE.UNIT")
    p.add_argument("--src", help="source FINS address NET.NODE.UNIT")
    add_timeout(p, 5.0, "seconds per frame (default 5)")
    add_read_only(p)


#: Help of ``--what``.
WHAT = "the program area (default) or the parameter areas"


def add_parsers(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser("backup", help="back up the program area or the parameter areas")
    _common(p)
    p.add_argument("file", type=Path, help="file to write (program: raw bytes; parameters: JSON)")
    p.add_argument("--what", choices=("program", "parameters"), default="program", help=WHAT)
    p.set_defaults(func=_sync(_backup))

    p = sub.add_parser("restore", help="restore a program or parameter backup")
    _common(p)
    p.add_argument("file", type=Path, help="a file made by 'aiofins backup'")
    p.add_argument("--what", choices=("program", "parameters"), default="program", help=WHAT)
    p.add_argument("--stop", action="store_true", help="switch to PROGRAM mode first")
    add_yes(p)
    p.set_defaults(func=_sync(_restore, _ask_restore))

    p = sub.add_parser("files", help="file memory: list, get, put, delete")
    _common(p)
    p.add_argument("action", choices=("list", "get", "put", "delete"), help="what to do")
    p.add_argument("name", nargs="?", help="file name (8.3) on the PLC")
    p.add_argument("local", nargs="?", type=Path, help="local file for get/put")
    p.add_argument(
        "--disk", choices=("card", "em"), default="card", help="memory card or EM file memory"
    )
    p.add_argument("--directory", default="", help="directory on the PLC (\\ separated)")
    p.add_argument("--json", action="store_true", help="print one JSON document (list, delete)")
    add_yes(p)
    p.set_defaults(func=_sync(_files, _ask_files))


def _ask_restore(args: argparse.Namespace) -> str | None:
    if not args.stop:
        return None
    return f"stop {args.url} (switch it to PROGRAM mode) and restore its {args.what}?"


def _ask_files(args: argparse.Namespace) -> str | None:
    if args.action != "delete" or not args.name:
        return None
    return f"delete {args.name} from the file memory of {args.url}?"


def _sync(handler: Any, question: Any = None) -> Any:
    def run(args: argparse.Namespace) -> int:
        text = question(args) if question is not None and not args.read_only else None
        if text is not None and not confirm(args, text):
            return refuse(args.command)
        return int(anyio.run(with_client, handler, args))

    return run


async def _backup(plc: Client, args: argparse.Namespace) -> int:
    bar = ProgressBar(f"backup {args.what}", "bytes" if args.what == "program" else "words")
    try:
        if args.what == "program":
            image = await backup_program(plc, progress=bar)
            args.file.write_bytes(image)
            size = len(image)
        else:
            areas = await backup_parameters(plc, progress=bar)
            args.file.write_text(json.dumps({f"{k:04X}": list(v) for k, v in areas.items()}))
            size = sum(len(v) for v in areas.values())
    finally:
        bar.close()
    print(f"{args.what}: {size} {bar.unit} written to {args.file}")
    return 0


async def _restore(plc: Client, args: argparse.Namespace) -> int:
    # Read and check the file before anything is sent: a bad file must not stop the PLC.
    image = b""
    backup: dict[int, tuple[int, ...]] = {}
    if args.what == "program":
        image = args.file.read_bytes()
        check_program_image(image)
        size = len(image)
    else:
        backup = _parameter_backup(args.file)
        check_parameter_backup(backup)
        size = sum(len(v) for v in backup.values())
    plc.guard(ProgramAreaWrite if args.what == "program" else ParameterAreaWrite)
    if not args.stop:  # say what to do in the command line's words, not the API's
        mode = (await plc.cpu_unit_status_read()).mode
        if mode is not CpuMode.PROGRAM:
            raise CommandError(
                f"the PLC is in {mode.name} mode; restoring needs PROGRAM mode: add --stop to "
                "switch to it first (or run 'aiofins stop URL')"
            )
    bar = ProgressBar(f"restore {args.what}", "bytes" if args.what == "program" else "words")
    try:
        if args.stop:
            await plc.stop()
        if args.what == "program":
            await restore_program(plc, image, progress=bar)
        else:
            await restore_parameters(plc, backup, progress=bar)
    finally:
        bar.close()
    print(f"{args.what}: {size} {bar.unit} restored from {args.file}")
    return 0


def _parameter_backup(path: Path) -> dict[int, tuple[int, ...]]:
    """A parameter backup file (``{"8010": [words...], ...}``) as words by area code."""
    try:
        raw = json.loads(path.read_text())
        if not isinstance(raw, dict):
            raise ValueError("not a JSON object")
        return {int(k, 16): tuple(int(w) for w in v) for k, v in raw.items()}
    except (ValueError, TypeError) as exc:
        raise CommandError(
            f'{path} is not a parameter backup ({{"8010": [words...], ...}}): {exc}'
        ) from None


async def _files(plc: Client, args: argparse.Namespace) -> int:
    disk = Disk.MEMORY_CARD if args.disk == "card" else Disk.EM_FILE_MEMORY
    if args.action == "list":
        entries = await list_files(plc, disk, args.directory)
        if args.json:
            print(
                json.dumps(
                    [
                        {
                            "name": e.name,
                            "size": e.size,
                            "date": str(e.date.to_datetime()),
                            "attributes": int(e.attributes),
                        }
                        for e in entries
                    ]
                )
            )
        else:
            for e in entries:
                print(f"{escape(e.name):<12} {e.size:>10}  {e.date.to_datetime()}")
        return 0
    if not args.name:
        print("aiofins: files get/put/delete need a file name", file=sys.stderr)
        return 2
    if args.action == "delete":
        result = await plc.file_delete(disk, (args.name,), args.directory)
        if not result.deleted:  # the PLC skips a name that does not exist
            print(f"aiofins: {args.name}: no such file, nothing deleted", file=sys.stderr)
            return 1
        print(json.dumps({"deleted": result.deleted}) if args.json else f"{args.name}: deleted")
        return 0
    local: Path = args.local or Path(args.name)
    bar = ProgressBar(f"{args.action} {args.name}")
    try:
        if args.action == "get":
            local.write_bytes(await download_file(plc, disk, args.name, args.directory, bar))
        else:
            await upload_file(plc, disk, args.name, local.read_bytes(), args.directory, bar)
    finally:
        bar.close()
    return 0
