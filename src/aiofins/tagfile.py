"""Tag lists from files: a plain CSV of ``name,address,type`` or a CX-Programmer symbol table.

:func:`load_tags` returns ``{name: "ADDRESS:TYPE"}``, the mapping :meth:`Client.read_tags` and
:meth:`Poller.add_group` take. Two layouts are read, told apart by the header row (a file may
also have none):

* **plain**: columns ``name``, ``address`` and, optionally, ``type`` (any spec
  :func:`~aiofins.protocol.values.parse_value_type` reads: ``float32``, ``int32:ABCD``,
  ``string:16``; empty: ``uint16`` for a word, ``bit`` for a bit address). Without a header the
  columns are in that order.
* **CX-Programmer** symbol table (the global symbols pasted or exported as CSV/tab-separated
  text): columns ``Name``, ``Data Type``, ``Address / Value``, then any of ``Rack Location``,
  ``Usage``, ``Comment`` (ignored). Without a header a row is taken for one when its second
  column is a CX-Programmer data type. Data types map as :data:`CX_TYPES` says; ``STRING``
  needs its size in bytes (``STRING(16)``, ``STRING[16]`` or ``STRING:16``); ``NUMBER``
  symbols are constants with no memory: they are skipped (and logged). Addresses are read as
  CX-Programmer writes them (``D100``, ``W0.00``, ``H10``, ``A100.15``, ``E0_100``, ``T0000``,
  and a bare ``100`` or ``0.01`` for CIO).

The delimiter (comma, semicolon or tab) is taken from the first row. Blank lines and lines
starting with ``#`` or ``//`` are skipped. Every mistake in the file is reported at once in
one :class:`TagFileError`, each as ``FILE:LINE: message``.
"""

from __future__ import annotations

import csv
import io
import logging
import re
from collections.abc import Iterable
from pathlib import Path

from .protocol.errors import CommandError, FinsError
from .protocol.values import parse_value_type
from .tags import parse_tag

log = logging.getLogger("aiofins.tagfile")

#: CX-Programmer data types → our value types (``None``: a type we cannot read as a tag).
CX_TYPES: dict[str, str | None] = {
    "BOOL": "bit",
    "CHANNEL": "uint16",
    "WORD": "uint16",
    "UINT": "uint16",
    "INT": "int16",
    "DWORD": "uint32",
    "UDINT": "uint32",
    "DINT": "int32",
    "LWORD": "uint64",
    "ULINT": "uint64",
    "LINT": "int64",
    "REAL": "float32",
    "LREAL": "float64",
    "UINT_BCD": "bcd16",
    "UDINT_BCD": "bcd32",
    "ULINT_BCD": None,  # 16 BCD digits: no value type of ours holds it
}
_CX_STRING = re.compile(r"^STRING\s*(?:[(\[:]\s*(\d+)\s*[)\]]?)?$", re.IGNORECASE)
#: Characters a cell may hold (a name, an address, a type, a comment), at most.
MAX_CELL = 4096
_CX_CONSTANT = "NUMBER"

_NAME_COLUMNS = ("name", "symbol", "tag")
_ADDRESS_COLUMNS = ("address / value", "address/value", "address")
_TYPE_COLUMNS = ("data type", "datatype", "type")


class TagFileError(CommandError):
    """A tag file that cannot be used; ``problems`` lists each one as ``FILE:LINE: message``."""

    def __init__(self, problems: list[str]) -> None:
        self.problems = problems
        super().__init__("\n".join(problems))


def cx_type(text: str) -> str | None:
    """A CX-Programmer data type's value type spec (``"REAL"`` → ``"float32"``), or None if
    ``text`` is not one. :class:`CommandError` for a CX type we cannot read."""
    key = text.strip().upper()
    if key in CX_TYPES:
        spec = CX_TYPES[key]
        if spec is None:
            raise CommandError(f"data type {text.strip()} is not supported")
        return spec
    m = _CX_STRING.match(text.strip())
    if m:
        if not m.group(1):
            raise CommandError("STRING needs its size in bytes, e.g. STRING(16)")
        if len(m.group(1)) > 5:  # a size of thousands of digits is no size (nor a cheap int)
            raise CommandError(f"STRING size of {len(m.group(1))} digits: at most 1998 bytes")
        return f"string:{m.group(1)}"
    return None


def load_tags(path: str | Path, *, encoding: str = "utf-8-sig") -> dict[str, str]:
    """The tags of a plain or CX-Programmer CSV file: ``{name: "ADDRESS:TYPE"}``.

    Raises :class:`TagFileError` naming every bad line, or if the file has no tags.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding=encoding)
    except UnicodeDecodeError as exc:
        raise TagFileError(
            [f"{path}: not {encoding} text ({exc.reason} at byte {exc.start}); pass encoding="]
        ) from None
    except OSError as exc:
        raise TagFileError([f"{path}: {exc.strerror or exc}"]) from None
    return parse_tags_text(text, str(path))


def parse_tags_text(text: str, source: str = "<tags>") -> dict[str, str]:
    """:func:`load_tags` on text already read (``source`` names it in messages)."""
    problems: list[str] = []
    rows = _rows(text, source, problems)
    if not rows:
        if problems:
            raise TagFileError(problems)
        raise TagFileError([f"{source}: no tags"])
    columns = _header(rows[0][1])
    if columns is not None:
        rows = rows[1:]
    tags: dict[str, str] = {}
    first_line: dict[str, int] = {}
    for number, cells in rows:
        where = f"{source}:{number}"
        try:
            entry = _entry(cells, columns)
        except FinsError as exc:
            problems.append(f"{where}: {exc}")
            continue
        if entry is None:
            log.info("%s: %s is a constant (NUMBER), not PLC memory: skipped", where, cells[0])
            continue
        name, spec = entry
        if name in tags:
            problems.append(
                f"{where}: tag {name!r} is defined twice (first at line {first_line[name]})"
            )
            continue
        try:
            parse_tag(name, spec)
        except FinsError as exc:
            text = str(exc)
            named = text if f"tag {name!r}" in text else f"tag {name!r} ({spec}): {text}"
            problems.append(f"{where}: {named}")
            continue
        tags[name] = spec
        first_line[name] = number
    if not tags and not problems:
        problems.append(f"{source}: no tags")
    if problems:
        raise TagFileError(sorted(problems, key=lambda p: _line_of(p, source)))
    return tags


def _line_of(problem: str, source: str) -> int:
    number = problem[len(source) + 1 :].partition(":")[0]
    return int(number) if number.isdigit() else 0


def _rows(text: str, source: str, problems: list[str]) -> list[tuple[int, list[str]]]:
    """The rows of a tag file with the line each starts on: blank rows and rows starting
    with ``#`` or ``//`` skipped, quoted cells spanning lines (a CX-Programmer comment)
    kept whole. A row with a cell over :data:`MAX_CELL` characters is a problem."""
    first = next(
        (
            line
            for line in text.splitlines()
            if line.strip() and not line.lstrip().startswith(("#", "//"))
        ),
        None,
    )
    if first is None:
        return []
    reader = csv.reader(io.StringIO(text, newline=""), delimiter=_delimiter(first[:MAX_CELL]))
    rows: list[tuple[int, list[str]]] = []
    start = 1
    while True:
        try:
            row = next(reader)
        except StopIteration:
            break
        except csv.Error as exc:  # a cell over csv's own limit (128 kB), a stray NUL, ...
            problems.append(f"{source}:{start}: {_cell_problem(exc)}")
            start = reader.line_num + 1
            continue
        number, start = start, reader.line_num + 1
        if not row or not "".join(row).strip():
            continue
        if row[0].lstrip().startswith(("#", "//")):
            continue
        long = next((cell for cell in row if len(cell) > MAX_CELL), None)
        if long is not None:
            problems.append(
                f"{source}:{number}: a cell of {len(long)} characters "
                f"(at most {MAX_CELL}): {long[:40]!r}..."
            )
            continue
        rows.append((number, [cell.strip() for cell in row]))
    return rows


def _cell_problem(exc: csv.Error) -> str:
    text = str(exc)
    if "field limit" in text:
        return f"a cell longer than csv's limit ({csv.field_size_limit()} characters)"
    return f"not CSV: {text}"


def _delimiter(first: str) -> str:
    if "\t" in first:
        return "\t"
    if ";" in first and "," not in first:
        return ";"
    return ","


def _find(cells: list[str], names: Iterable[str]) -> int | None:
    lowered = [c.lower() for c in cells]
    for name in names:
        if name in lowered:
            return lowered.index(name)
    return None


def _header(cells: list[str]) -> tuple[int, int, int | None] | None:
    """(name, address, type) column indexes if ``cells`` is a header row."""
    name = _find(cells, _NAME_COLUMNS)
    address = _find(cells, _ADDRESS_COLUMNS)
    if name is None or address is None:
        return None
    return name, address, _find(cells, _TYPE_COLUMNS)


def _entry(cells: list[str], columns: tuple[int, int, int | None] | None) -> tuple[str, str] | None:
    """(name, spec) of one row; None for a constant to skip."""
    if columns is None:
        if len(cells) < 2:
            raise CommandError("expected name,address[,type] or a CX-Programmer symbol row")
        # A CX-Programmer row without its header: name, data type, address, ...
        if len(cells) >= 3 and (cells[1].upper() == _CX_CONSTANT or _is_cx_type(cells[1])):
            columns = (0, 2, 1)
        else:
            columns = (0, 1, 2 if len(cells) >= 3 else None)
    name_at, address_at, type_at = columns
    last = max(i for i in columns if i is not None)
    if len(cells) <= last and not (type_at == last and len(cells) == last):
        raise CommandError(f"expected {last + 1} columns, got {len(cells)}")
    name = cells[name_at]
    address = cells[address_at]
    type_text = cells[type_at] if type_at is not None and type_at < len(cells) else ""
    if not name:
        raise CommandError("the tag has no name")
    if type_text.upper() == _CX_CONSTANT:
        return None
    if not address:
        raise CommandError(f"tag {name!r} has no address")
    if not type_text:
        return name, address
    spec = cx_type(type_text)
    if spec is None:
        spec = type_text
        parse_value_type(spec)  # a clear error for a type neither list knows
    return name, f"{address}:{spec}"


def _is_cx_type(text: str) -> bool:
    try:
        return cx_type(text) is not None
    except CommandError:
        return True
