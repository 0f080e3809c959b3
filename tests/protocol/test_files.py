"""File-memory helpers: 8.3 names, file dates, directories, disks (manual 5-2-3, 5-3-32)."""

from __future__ import annotations

import datetime as dt

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiofins.protocol.codec import Reader
from aiofins.protocol.errors import CommandError, DecodeError
from aiofins.protocol.files import (
    CassetteOperation,
    Disk,
    FileAttribute,
    FileDate,
    FileWriteMode,
    check_directory,
    check_disk,
    check_file_name,
    coerce_enum,
    decode_file_name,
    encode_directory,
    encode_entry_name,
    encode_file_name,
    read_directory,
    read_file_name,
)

H = bytes.fromhex
NAME_CHARS = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789!#$%&'()-@^_`{}~"


@st.composite
def file_names(draw: st.DrawFn) -> str:
    base = draw(st.text(NAME_CHARS, min_size=1, max_size=8).filter(lambda b: b[:2] != "~~"))
    ext = draw(st.text(NAME_CHARS, min_size=0, max_size=3))
    return f"{base}.{ext}" if ext else base


@st.composite
def directories(draw: st.DrawFn) -> str:
    parts = draw(st.lists(file_names(), max_size=5))
    path = "".join("\\" + p for p in parts)
    return path if len(path) <= 65 else ""


# --------------------------------------------------------------------------- names


@pytest.mark.parametrize(
    ("name", "raw"),
    [
        ("ASCII.DAT", b"ASCII   .DAT"),  # the wire-format doc's example
        ("DATA", b"DATA        "),  # no extension: period and extension are spaces
        ("A.B", b"A       .B  "),
        ("AUTOEXEC.OBJ", b"AUTOEXEC.OBJ"),
        ("prog_1.c~", b"prog_1  .c~ "),
    ],
)
def test_file_name_golden(name: str, raw: bytes) -> None:
    assert encode_file_name(name) == raw
    assert decode_file_name(raw) == name
    assert encode_entry_name(name) == raw
    assert read_file_name(Reader(raw)) == name


@pytest.mark.parametrize(
    ("name", "fragment"),
    [
        ("", "1 to 8"),
        ("ABCDEFGHI", "1 to 8"),  # name too long
        ("ABCDEFGHI.TXT", "1 to 8"),
        ("A.TEXT", "1 to 3"),  # extension too long
        ("A.", "1 to 3"),
        (".TXT", "1 to 8"),
        ("A.B.C", "more than one"),
        ("A B.TXT", "invalid character"),
        ("A*.TXT", "invalid character"),
        ("DIR\\A", "invalid character"),
        ("A/B", "invalid character"),
        ("CAF\u00c9", "invalid character"),
        ("~~ABC", "~~"),
    ],
)
def test_file_name_rejects(name: str, fragment: str) -> None:
    with pytest.raises(CommandError, match=fragment) as info:
        encode_file_name(name)
    assert name in str(info.value) or repr(name) in str(info.value)
    assert isinstance(info.value, ValueError)


def test_file_name_not_a_str() -> None:
    with pytest.raises(CommandError, match="must be a str"):
        check_file_name(b"A.TXT")  # type: ignore[arg-type]


@given(file_names())
def test_file_name_round_trip(name: str) -> None:
    raw = encode_file_name(name)
    assert len(raw) == 12
    assert decode_file_name(raw) == name
    assert encode_entry_name(name) == raw


@given(st.binary(min_size=12, max_size=12))
def test_any_name_field_decodes_and_re_encodes(raw: bytes) -> None:
    name = decode_file_name(raw)
    again = encode_entry_name(name)
    assert decode_file_name(again) == name


@pytest.mark.parametrize(
    ("raw", "name"),
    [
        (b" " * 12, ""),
        (b".           ", "."),
        (b"..          ", ".."),
        (b"NO NAME     ", "NO NAME"),
        (b"ABC     .   ", "ABC"),  # period without extension: still ABC
    ],
)
def test_listing_names(raw: bytes, name: str) -> None:
    assert decode_file_name(raw) == name
    if name != "ABC":
        assert encode_entry_name(name) == raw


def test_command_name_must_be_in_layout() -> None:
    for raw in (b"AB CD   .TXT", b"ABCDEFGHXTXT", b"ABC      TXT", b" " * 12):
        with pytest.raises(DecodeError) as info:
            read_file_name(Reader(raw))
        assert info.value.end_code == 0x110C


def test_decode_file_name_wrong_size() -> None:
    with pytest.raises(DecodeError):
        decode_file_name(b"SHORT")


def test_entry_name_limits() -> None:
    with pytest.raises(CommandError, match="longer than 12"):
        encode_entry_name("ABCDEFGHIJKLM")
    with pytest.raises(CommandError, match="latin-1"):
        encode_entry_name("\u20ac")
    with pytest.raises(CommandError, match="space"):
        encode_entry_name("A ")


# --------------------------------------------------------------------------- dates


def test_file_date_golden() -> None:
    # Wire-format doc 8.4: 58 2C 63 8F = 2024-01-12 12:28:30.
    date = FileDate.decode(H("582C638F"))
    assert date == FileDate(2024, 1, 12, 12, 28, 30)
    assert date.raw == 0x582C638F
    assert date.encode() == H("582C638F")
    assert date.to_datetime() == dt.datetime(2024, 1, 12, 12, 28, 30)
    assert str(date) == "2024-01-12 12:28:30"


def test_file_date_zero_is_no_date() -> None:
    date = FileDate.from_raw(0)
    assert (date.year, date.month, date.day) == (1980, 0, 0)
    assert date.to_datetime() is None
    assert date.encode() == bytes(4)


def test_file_date_from_datetime_floors_odd_seconds() -> None:
    date = FileDate.from_datetime(dt.datetime(2107, 12, 31, 23, 59, 59))
    assert date == FileDate(2107, 12, 31, 23, 59, 58)
    assert date.encode() == H("FF9FBF7D")


@pytest.mark.parametrize(
    ("fields", "fragment"),
    [
        ((1979, 1, 1), "year"),
        ((2108, 1, 1), "year"),
        ((2000, 16, 1), "month"),
        ((2000, 1, 32), "day"),
        ((2000, 1, 1, 32), "hour"),
        ((2000, 1, 1, 0, 64), "minute"),
        ((2000, 1, 1, 0, 0, 63), "second"),
        ((2000, 1, 1, 0, 0, 31), "odd"),
    ],
)
def test_file_date_rejects(fields: tuple[int, ...], fragment: str) -> None:
    with pytest.raises(CommandError, match=fragment):
        FileDate(*fields)


def test_file_date_decode_wrong_size() -> None:
    with pytest.raises(DecodeError):
        FileDate.decode(b"\x00\x00")
    with pytest.raises(CommandError):
        FileDate.from_raw(1 << 32)


@given(st.integers(0, 0xFFFFFFFF))
def test_file_date_any_raw_round_trips(raw: int) -> None:
    date = FileDate.from_raw(raw)
    assert date.raw == raw
    assert FileDate.decode(date.encode()) == date


@given(st.datetimes(dt.datetime(1980, 1, 1), dt.datetime(2107, 12, 31, 23, 59, 59)))
def test_file_date_datetime_round_trip(value: dt.datetime) -> None:
    date = FileDate.from_datetime(value)
    expected = value.replace(microsecond=0, second=value.second - value.second % 2)
    assert date.to_datetime() == expected


# --------------------------------------------------------------------------- directories


@pytest.mark.parametrize(
    ("path", "raw"),
    [
        ("", H("0000")),
        ("\\", H("0000")),
        ("\\PLC", H("0004") + b"\\PLC"),
        ("\\PLC\\DATA.OLD", H("000D") + b"\\PLC\\DATA.OLD"),
        ("/PLC/DATA", H("0009") + b"\\PLC\\DATA"),  # '/' accepted, sent as '\'
    ],
)
def test_directory_golden(path: str, raw: bytes) -> None:
    assert encode_directory(path) == raw
    r = Reader(raw)
    assert read_directory(r) == check_directory(path)
    r.end()


@pytest.mark.parametrize(
    ("path", "fragment"),
    [
        ("PLC", "absolute"),
        ("\\PLC\\", "empty part"),
        ("\\\\PLC", "empty part"),
        ("\\A B", "invalid character"),
        ("\\" + "\\".join(["ABCDEFGH"] * 8), "at most 65"),
    ],
)
def test_directory_rejects(path: str, fragment: str) -> None:
    with pytest.raises(CommandError, match=fragment):
        check_directory(path)


@pytest.mark.parametrize(
    ("raw", "end_code"),
    [
        (H("0042") + b"\\" * 66, 0x110C),  # over 65 characters
        (H("0001") + b"\\", 0x110C),  # root must be length 0
        (H("0004") + b"/PLC", 0x110C),
        (H("0004") + b"PLC!", 0x110C),
        (H("0005") + b"\\PLC", 0x1002),  # shorter than its length
        (H("00"), 0x1002),
    ],
)
def test_read_directory_rejects(raw: bytes, end_code: int) -> None:
    with pytest.raises(DecodeError) as info:
        read_directory(Reader(raw))
    assert info.value.end_code == end_code


@given(directories())
def test_directory_round_trip(path: str) -> None:
    raw = encode_directory(path)
    r = Reader(raw)
    assert read_directory(r) == path
    r.end()


# --------------------------------------------------------------------------- codes


def test_disks() -> None:
    assert check_disk(0x8000) is Disk.MEMORY_CARD
    assert check_disk(0x8001) is Disk.EM_FILE_MEMORY
    with pytest.raises(CommandError, match="8000"):
        check_disk(0x8003)  # Memory Cassette: 2220 only
    with pytest.raises(CommandError, match="0x1234"):
        check_disk(0x1234)
    assert check_disk(0x8003, frozenset({Disk.MEMORY_CASSETTE})) is Disk.MEMORY_CASSETTE


def test_codes() -> None:
    assert coerce_enum(FileWriteMode, 3, "mode") is FileWriteMode.OVERWRITE
    assert coerce_enum(CassetteOperation, 0x8000, "op") is CassetteOperation.READ_DATA_TYPE
    with pytest.raises(CommandError, match="0000 \\(NEW\\)"):
        coerce_enum(FileWriteMode, 4, "mode")
    attributes = FileAttribute.DIRECTORY | FileAttribute.ARCHIVE
    assert int(attributes) == 0x30
    assert [int(a) for a in FileAttribute] == [1, 2, 4, 8, 0x10, 0x20]
