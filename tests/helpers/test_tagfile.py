"""Tag lists from files: plain CSV and CX-Programmer symbol tables, real files on disk."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from aiofins import TagFileError, load_tags
from aiofins.connection import connect
from aiofins.simulator import VirtualPLC, run_simulator
from aiofins.tagfile import CX_TYPES, cx_type

ROOT = Path(__file__).resolve().parents[2]


def write(tmp_path: Path, text: str, name: str = "tags.csv", encoding: str = "utf-8") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding=encoding)
    return path


def test_plain_csv_with_header_and_default_types(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        "name,address,type\n"
        "# a comment line\n"
        "temp,D100,float32\n"
        "\n"
        "count,D102,uint32:ABCD\n"
        "run,CIO 0.01,\n"
        "level,D110\n"
        "label,H10,string:8\n",
    )
    assert load_tags(path) == {
        "temp": "D100:float32",
        "count": "D102:uint32:ABCD",
        "run": "CIO 0.01",
        "level": "D110",
        "label": "H10:string:8",
    }


def test_plain_csv_without_header_semicolons_and_tabs(tmp_path: Path) -> None:
    assert load_tags(write(tmp_path, "a;D0;int16\nb;W3.02\n")) == {
        "a": "D0:int16",
        "b": "W3.02",
    }
    assert load_tags(write(tmp_path, "a\tD0\tfloat64\n", "t.txt")) == {"a": "D0:float64"}


def test_cx_programmer_symbol_table_maps_its_data_types(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.INFO, logger="aiofins.tagfile"):
        tags = load_tags(ROOT / "examples" / "line1_symbols.csv")
    assert tags == {
        "Temperature": "D100:float32",
        "PartCount": "D102:uint32",
        "Running": "0.01:bit",
        "Setpoint": "D120:int16",
        "Recipe": "D130:string:8",
    }
    assert "MaxTemp is a constant (NUMBER)" in caplog.text
    # Pasted from CX-Programmer without the header, tab-separated, with a BOM and quotes.
    path = write(
        tmp_path,
        '\ufeff"Flag"\tBOOL\tW0.00\t\tWork\t"comment, with comma"\nTotal\tLREAL\tE0_100\n'
        "Code\tUINT_BCD\tD5\nBig\tDINT\tH20\nCh\tCHANNEL\t100\n",
    )
    assert load_tags(path) == {
        "Flag": "W0.00:bit",
        "Total": "E0_100:float64",
        "Code": "D5:bcd16",
        "Big": "H20:int32",
        "Ch": "100:uint16",
    }


@pytest.mark.parametrize(("cx", "ours"), [(k, v) for k, v in CX_TYPES.items() if v])
def test_every_cx_type_names_one_of_ours(cx: str, ours: str) -> None:
    assert cx_type(cx) == ours
    assert cx_type(cx.lower()) == ours


def test_every_bad_line_is_reported_at_once_with_file_and_line(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        "name,address,type\n"
        "ok,D0,int16\n"
        "bad_address,Q100,int16\n"
        "bad_type,D1,float33\n"
        "ok,D2\n"
        ",D3\n"
        "too_far,D32767,float32\n"
        "no_string_size,D4,STRING\n"
        "bcd64,D8,ULINT_BCD\n",
    )
    with pytest.raises(TagFileError) as info:
        load_tags(path)
    problems = info.value.problems
    assert [p.split(": ", 1)[0] for p in problems] == [f"{path}:{n}" for n in (3, 4, 5, 6, 7, 8, 9)]
    assert "Q100" in problems[0]
    assert "float33" in problems[1]
    assert "defined twice (first at line 2)" in problems[2]
    assert "no name" in problems[3]
    assert "too_far" in problems[4]
    assert "STRING needs its size" in problems[5]
    assert "ULINT_BCD is not supported" in problems[6]


def test_empty_missing_and_undecodable_files(tmp_path: Path) -> None:
    with pytest.raises(TagFileError, match="no tags"):
        load_tags(write(tmp_path, "# nothing\n\n"))
    with pytest.raises(TagFileError, match="No such file"):
        load_tags(tmp_path / "missing.csv")
    path = tmp_path / "latin1.csv"
    path.write_bytes("T\xe9mp,D0\n".encode("latin-1"))
    with pytest.raises(TagFileError, match="not utf-8-sig text"):
        load_tags(path)
    assert load_tags(path, encoding="latin-1") == {"T\xe9mp": "D0"}


@pytest.mark.anyio
async def test_loaded_tags_read_from_a_virtual_plc(anyio_backend: object) -> None:
    tags = load_tags(ROOT / "examples" / "line1_symbols.csv")
    async with (
        run_simulator(VirtualPLC(), udp=("127.0.0.1", 0)) as sim,
        connect(f"udp://127.0.0.1:{sim.udp_port}") as plc,
    ):
        await plc.write_value("D100", 71.25, "float32")
        await plc.write_value("D102", 123456, "uint32")
        await plc.write("CIO 0", [0b10])
        await plc.write_value("D120", -5, "int16")
        await plc.write_value("D130", "MIX", "string:8")
        values = await plc.read_tags(tags)
    assert values == {
        "Temperature": 71.25,
        "PartCount": 123456,
        "Running": True,
        "Setpoint": -5,
        "Recipe": "MIX",
    }


def test_a_multi_line_quoted_comment_is_one_cell_and_lines_stay_right(tmp_path: Path) -> None:
    """Valid CSV that crashed the loader (each physical line was parsed on its own)."""
    path = write(
        tmp_path,
        "Name,Data Type,Address / Value,Rack Location,Usage,Comment\r\n"
        'sp,INT,D100,,Work,"the setpoint\r\n# not a comment: inside quotes\r\n\r\nends here"\r\n'
        "// a comment line\r\n"
        "temp,REAL,D102,,Work,plain\r\n"
        "bad,REAL,,,Work,\r\n",
    )
    with pytest.raises(TagFileError) as info:
        load_tags(path)
    assert info.value.problems == [f"{path}:8: tag 'bad' has no address"]
    path.write_text(path.read_text().replace("bad,REAL,,,Work,\n", ""))
    assert load_tags(path) == {"sp": "D100:int16", "temp": "D102:float32"}


def test_cells_and_type_sizes_are_bounded(tmp_path: Path) -> None:
    """A cell over 128 kB (csv's own limit) and ``STRING[5000 digits]`` raised csv.Error and
    ValueError out of load_tags; every bound is a FILE:LINE problem now."""
    path = write(
        tmp_path,
        "name,address,type\n"
        f"long,D0,STRING[{'9' * 5000}]\n"
        f"digits,D0,STRING({'9' * 3000})\n"
        f"spec,D0,int16:{'9' * 4000}\n"
        f'"{"n" * 200_000}",D0,uint16\n'
        f"{'m' * 5000},D0,uint16\n"
        "fine,D2,uint16\n",
    )
    with pytest.raises(TagFileError) as info:
        load_tags(path)
    problems = info.value.problems
    assert [p.split(": ", 1)[0] for p in problems] == [f"{path}:{n}" for n in (2, 3, 4, 5, 6)]
    assert "a cell of 5008 characters (at most 4096)" in problems[0]
    assert "STRING size of 3000 digits: at most 1998 bytes" in problems[1]
    assert "a length of 4000 digits" in problems[2]
    assert "csv's limit" in problems[3]
    assert "a cell of 5000 characters" in problems[4]
