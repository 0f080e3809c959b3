"""File memory (22xx) and serial gateway (28xx) commands: golden bytes, server-side decoding,
round trips, and arbitrary bytes that may only ever raise DecodeError."""

from __future__ import annotations

from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiofins.protocol.areas import MemoryAddress
from aiofins.protocol.commands import Request, decode_request, gateway, operation_for
from aiofins.protocol.commands import file as file_ops
from aiofins.protocol.commands.file import (
    CreateDeleteDirectory,
    FileCopy,
    FileDelete,
    FileDeleteResult,
    FileMemoryFormat,
    FileNameChange,
    FileNameRead,
    FileTransferResult,
    MemoryAreaFileTransfer,
    MemoryCassetteDataType,
    MemoryCassetteTransfer,
    ParameterAreaFileTransfer,
    ProgramAreaFileTransfer,
    ProgramAreaFileTransferResult,
    SingleFileRead,
    SingleFileReadResult,
    SingleFileWrite,
)
from aiofins.protocol.commands.gateway import (
    CompowayFResponse,
    ConvertToCompowayFCommand,
    ConvertToModbusAsciiCommand,
    ConvertToModbusRtuCommand,
    ModbusAsciiResponse,
    ModbusRtuResponse,
    serial_port_unit_address,
)
from aiofins.protocol.errors import AddressError, CommandError, DecodeError
from aiofins.protocol.files import (
    CassetteArea,
    CassetteContents,
    CassetteOperation,
    DirectoryOperation,
    Disk,
    DiskData,
    FileAttribute,
    FileDate,
    FileEntry,
    FileNameReadResult,
    FileTransferMode,
    FileWriteMode,
)

from .test_files import directories, file_names

H = bytes.fromhex
CARD, EM = Disk.MEMORY_CARD, Disk.EM_FILE_MEMORY
ASCII_DAT = b"ASCII   .DAT"
DATE = FileDate(2024, 1, 12, 12, 28, 30)  # 58 2C 63 8F

# (request, exact parameter bytes after MRC/SRC)
GOLDEN: list[tuple[Request[Any], bytes]] = [
    (FileNameRead(CARD, directory="\\DIR"), H("8000 0000 0014 0004") + b"\\DIR"),
    (FileNameRead(EM, first_file=21, count=0), H("8001 0015 0000 0000")),
    (
        SingleFileRead(EM, "ASCII.DAT", position=0x10, length=4),
        H("8001") + ASCII_DAT + H("00000010 0004 0000"),
    ),
    (
        SingleFileWrite(CARD, "A.TXT", b"\x01\x02", FileWriteMode.OVERWRITE, 5, "\\D"),
        H("8000 0003") + b"A       .TXT" + H("00000005 0002 0102 0002") + b"\\D",
    ),
    (
        SingleFileWrite(EM, "NEW", b"xyz"),
        H("8001 0000") + b"NEW         " + H("00000000 0003") + b"xyz" + H("0000"),
    ),
    (FileMemoryFormat(EM), H("8001")),
    (
        FileDelete(CARD, ("A.TXT", "B"), "\\LOG"),
        H("8000 0002") + b"A       .TXTB           " + H("0004") + b"\\LOG",
    ),
    (
        FileCopy(CARD, "A.TXT", EM, "B.TXT", "\\X"),
        H("8000") + b"A       .TXT" + H("8001") + b"B       .TXT" + H("0002") + b"\\X" + H("0000"),
    ),
    (
        FileNameChange(EM, "OLD.DAT", "NEW.DAT"),
        H("8001") + b"OLD     .DATNEW     .DAT" + H("0000"),
    ),
    (
        MemoryAreaFileTransfer(
            FileTransferMode.AREA_TO_FILE, MemoryAddress(0x82, 100), 10, CARD, "DM.IOM"
        ),
        H("0000 82006400 000A 8000") + b"DM      .IOM" + H("0000"),
    ),
    (
        ParameterAreaFileTransfer(FileTransferMode.FILE_TO_AREA, 0x8010, CARD, "SETUP.STD"),
        H("0001 8010 0000 FFFF 8000") + b"SETUP   .STD" + H("0000"),
    ),
    (
        ProgramAreaFileTransfer(FileTransferMode.COMPARE, CARD, "AUTOEXEC.OBJ", directory="\\P"),
        H("0002 FFFF 00000000 FFFFFFFF 8000") + b"AUTOEXEC.OBJ" + H("0002") + b"\\P",
    ),
    (
        CreateDeleteDirectory(CARD, DirectoryOperation.CREATE, "LOGS", "\\DATA"),
        H("8000 0000") + b"LOGS        " + H("0005") + b"\\DATA",
    ),
    (
        CreateDeleteDirectory(EM, DirectoryOperation.DELETE, "OLD"),
        H("8001 0001") + b"OLD         " + H("0000"),
    ),
    (MemoryCassetteTransfer(CassetteOperation.TO_CASSETTE), H("8003 0000 0000")),
    (
        MemoryCassetteTransfer(
            CassetteOperation.FROM_CASSETTE, CassetteArea.INDIVIDUAL | CassetteArea.DATA_MEMORY
        ),
        H("8003 0001 8040"),
    ),
    (MemoryCassetteTransfer(CassetteOperation.READ_DATA_TYPE), H("8003 8000")),
    (ConvertToCompowayFCommand.build(1, "0101", "C00000000001"), b"010000101C00000000001"),
    (ConvertToCompowayFCommand.build("XX", "0503", b"0000"), b"XX00005030000"),
    (ConvertToModbusRtuCommand.build(1, 3, H("00000002")), H("010300000002")),
    (ConvertToModbusAsciiCommand.build(0xF7, 3, H("006B0003")), b"F703006B0003"),
]


@pytest.mark.parametrize(("request_", "params"), GOLDEN, ids=lambda v: getattr(v, "NAME", ""))
def test_golden_request(request_: Request[Any], params: bytes) -> None:
    assert request_.encode() == params
    assert type(request_).decode(params) == request_
    assert decode_request(request_.MRC, request_.SRC, params) == request_


def test_file_name_read_response_golden() -> None:
    data = (
        b"VOL         " + H("582C638F 001E0000 00100000 0003")
        + H("8002")  # 2 entries, bit 15: the last file is included
        + ASCII_DAT + H("582C638F 0000000A 0020")
        + b"SUB         " + H("00000000 00000000 0010")
    )  # fmt: skip
    result = FileNameRead(CARD).decode_response(data)
    assert result == FileNameReadResult(
        DiskData("VOL", DATE, 0x1E0000, 0x100000, 3),
        (
            FileEntry("ASCII.DAT", DATE, 10, FileAttribute.ARCHIVE),
            FileEntry("SUB", FileDate.from_raw(0), 0, FileAttribute.DIRECTORY),
        ),
        last=True,
    )
    assert result.files[1].is_directory and not result.files[0].is_directory
    assert result.encode() == data
    only_disk = FileNameRead(CARD, count=0).decode_response(data[:26] + H("0000"))
    assert only_disk.files == () and not only_disk.last


@pytest.mark.parametrize(
    ("request_", "data", "result"),
    [
        (
            SingleFileRead(EM, "ASCII.DAT", 16, 4),
            H("00000014 00000010 8004 DEADBEEF"),
            SingleFileReadResult(20, 16, H("DEADBEEF"), last=True),
        ),
        (
            SingleFileRead(EM, "ASCII.DAT", 0, 0),  # existence check
            H("00000014 00000000 0000"),
            SingleFileReadResult(20, 0),
        ),
        (FileDelete(CARD, ("A",)), H("0001"), FileDeleteResult(1)),
        (GOLDEN[9][0], H("000A"), FileTransferResult(10)),
        (GOLDEN[10][0], H("0200"), FileTransferResult(512)),
        (GOLDEN[11][0], H("00001000"), ProgramAreaFileTransferResult(4096)),
        (
            MemoryCassetteTransfer(CassetteOperation.READ_DATA_TYPE),
            H("0045"),
            MemoryCassetteDataType(
                CassetteContents.USER_PROGRAM
                | CassetteContents.PARAMETER_AREA
                | CassetteContents.DATA_MEMORY
            ),
        ),
        (MemoryCassetteTransfer(CassetteOperation.VERIFY), b"", None),
        (FileMemoryFormat(CARD), b"", None),
        (GOLDEN[3][0], b"", None),
        (GOLDEN[7][0], b"", None),
        (GOLDEN[8][0], b"", None),
        (GOLDEN[12][0], b"", None),
    ],
)
def test_golden_response(request_: Request[Any], data: bytes, result: Any) -> None:
    assert request_.decode_response(data) == result
    if result is not None:
        assert result.encode() == data
    else:
        with pytest.raises(DecodeError):
            request_.decode_response(b"\x00")


def test_gateway_responses_golden() -> None:
    cw = GOLDEN[17][0].decode_response(b"01000001010000001234")
    assert cw == CompowayFResponse(b"01000001010000001234")
    assert (cw.node, cw.subaddress, cw.end_code) == ("01", "00", "00")
    assert (cw.compoway_command, cw.response_code, cw.text) == ("0101", "0000", b"001234")
    bad_frame = GOLDEN[17][0].decode_response(b"010014")  # frame error: no PDU
    assert bad_frame.end_code == "14" and bad_frame.compoway_command is None
    assert bad_frame.response_code is None

    rtu = GOLDEN[19][0].decode_response(H("010304000A000B"))
    assert (rtu.slave_address, rtu.function_code, rtu.data) == (1, 3, H("04000A000B"))
    assert not rtu.is_exception and rtu.encode() == H("010304000A000B")
    assert GOLDEN[19][0].decode_response(H("018302")).is_exception

    asc = GOLDEN[20][0].decode_response(b"F70304000A000B")
    assert asc == ModbusAsciiResponse(b"F70304000A000B")
    assert (asc.slave_address, asc.function_code, asc.data) == (0xF7, 3, H("04000A000B"))
    for request_, short in ((GOLDEN[17][0], b"01000"), (GOLDEN[19][0], b"\x01"),
                            (GOLDEN[20][0], b"F70"), (GOLDEN[20][0], b"F703ZZ")):  # fmt: skip
        with pytest.raises(DecodeError):
            request_.decode_response(short)


def test_gateway_request_views() -> None:
    cw = GOLDEN[17][0]
    assert isinstance(cw, ConvertToCompowayFCommand)
    assert (cw.node, cw.subaddress, cw.sid, cw.compoway_command, cw.text) == (
        "01", "00", "0", "0101", b"C00000000001")  # fmt: skip
    rtu = ConvertToModbusRtuCommand(H("0106 0001 0003"))
    assert (rtu.slave_address, rtu.function_code, rtu.data) == (1, 6, H("00010003"))
    asc = ConvertToModbusAsciiCommand(b"0106")
    assert (asc.slave_address, asc.function_code, asc.data) == (1, 6, b"")


@pytest.mark.parametrize(
    ("port", "unit", "da2"),
    [(1, 0, 0x80), (2, 0, 0x81), (1, 1, 0x84), (2, 0xA, 0xA9), (1, 15, 0xBC), (2, 15, 0xBD),
     (1, None, 0xE4), (2, None, 0xE5)],
)  # fmt: skip
def test_serial_port_unit_address(port: int, unit: int | None, da2: int) -> None:
    assert serial_port_unit_address(port, unit) == da2


def test_serial_port_unit_address_rejects() -> None:
    with pytest.raises(CommandError, match="1 or 2"):
        serial_port_unit_address(3)
    with pytest.raises(CommandError, match=r"0\.\.15"):
        serial_port_unit_address(1, 16)
    assert (gateway.CP_SERIAL_PORT_1, gateway.CP_SERIAL_PORT_2) == (0xFD, 0xFC)


def test_operation_metadata() -> None:
    ops = file_ops.OPERATIONS + gateway.OPERATIONS
    assert [op.command_code() for op in ops] == [
        0x2201, 0x2202, 0x2203, 0x2204, 0x2205, 0x2207, 0x2208, 0x220A, 0x220B, 0x220C,
        0x2215, 0x2220, 0x2803, 0x2804, 0x2805]  # fmt: skip
    assert {op for op in ops if op.IDEMPOTENT} == {FileNameRead, SingleFileRead}
    for op in ops:
        assert operation_for(op.MRC, op.SRC, b"") is op


# --------------------------------------------------------------------------- validation


@pytest.mark.parametrize(
    ("build", "error", "fragment"),
    [
        (lambda: FileNameRead(0x1234), CommandError, "disk number"),  # type: ignore[arg-type]
        (lambda: FileNameRead(Disk.MEMORY_CASSETTE), CommandError, "disk number"),
        (lambda: FileNameRead(CARD, count=21), CommandError, "0..20"),
        (lambda: FileNameRead(CARD, directory="DIR"), CommandError, "absolute"),
        (lambda: SingleFileRead(CARD, "TOOLONGNAME.TXT"), CommandError, "1 to 8"),
        (lambda: SingleFileRead(CARD, "A", length=1989), CommandError, "0..1988"),
        (lambda: SingleFileRead(CARD, "A", position=-1), CommandError, "file position"),
        (lambda: SingleFileWrite(CARD, "A", b"x", 7), CommandError, "0003 \\(OVERWRITE\\)"),  # type: ignore[arg-type]
        (lambda: SingleFileWrite(CARD, "A", b"x", position=1), CommandError, "only OVERWRITE"),
        (lambda: SingleFileWrite(CARD, "A", bytes(1977)), CommandError, "at most 1976"),
        (lambda: SingleFileWrite(CARD, "A", bytes(1970), directory="\\ABCDEFGH"), CommandError,
         "at most 1967"),
        (lambda: FileDelete(CARD, ()), CommandError, "1..166"),
        (lambda: FileDelete(CARD, ("A",) * 167), CommandError, "1..166"),
        (lambda: FileDelete(CARD, "A.TXT"), CommandError, "not one str"),  # type: ignore[arg-type]
        (lambda: FileDelete(CARD, ("A", "B C")), CommandError, "invalid character"),
        (lambda: FileCopy(CARD, "A", 0x8002, "B"), CommandError, "destination disk"),  # type: ignore[arg-type]
        (lambda: FileCopy(CARD, "A", EM, "B", destination_directory="\\A\\"), CommandError,
         "destination directory"),
        (lambda: FileNameChange(CARD, "OLD", "NEW?"), CommandError, "new file name"),
        (lambda: MemoryAreaFileTransfer(FileTransferMode.AREA_TO_FILE, MemoryAddress(0x30, 0, 1),
                                        1, CARD, "A"), AddressError, "cannot be transferred"),
        (lambda: MemoryAreaFileTransfer(FileTransferMode.AREA_TO_FILE, MemoryAddress(0x82, 0, 1),
                                        1, CARD, "A"), AddressError, "must be 0"),
        (lambda: MemoryAreaFileTransfer(FileTransferMode.COMPARE, MemoryAddress(0x82, 0), 0,
                                        CARD, "A"), CommandError, "1..65535"),
        (lambda: MemoryAreaFileTransfer(3, MemoryAddress(0x82, 0), 1, CARD, "A"),  # type: ignore[arg-type]
         CommandError, "transfer parameter code"),
        (lambda: ParameterAreaFileTransfer(FileTransferMode.COMPARE, 0x8011, CARD, "A"),
         CommandError, "8010"),
        (lambda: ProgramAreaFileTransfer(FileTransferMode.COMPARE, CARD, "A", program_number=0),
         CommandError, "FFFF"),
        (lambda: ParameterAreaFileTransfer(FileTransferMode.COMPARE, 0x8010, CARD, "A", begin=1),
         CommandError, "beginning word 1 must be 0"),
        (lambda: ParameterAreaFileTransfer(FileTransferMode.COMPARE, 0x8010, CARD, "A", count=512),
         CommandError, "number of items 512 must be FFFF"),
        (lambda: ProgramAreaFileTransfer(FileTransferMode.COMPARE, CARD, "A", begin_word=4),
         CommandError, "beginning word 4 must be 0"),
        (lambda: ProgramAreaFileTransfer(FileTransferMode.COMPARE, CARD, "A", byte_count=1024),
         CommandError, "must be FFFFFFFF"),
        (lambda: CreateDeleteDirectory(CARD, 2, "D"), CommandError, "directory parameter"),  # type: ignore[arg-type]
        (lambda: CreateDeleteDirectory(CARD, DirectoryOperation.CREATE, "D.IR.X"), CommandError,
         "directory name"),
        (lambda: MemoryCassetteTransfer(CassetteOperation.VERIFY, disk=CARD), CommandError,
         "8003"),
        (lambda: MemoryCassetteTransfer(CassetteOperation.VERIFY, CassetteArea.DATA_MEMORY),
         CommandError, "INDIVIDUAL"),
        (lambda: MemoryCassetteTransfer(CassetteOperation.VERIFY, CassetteArea.INDIVIDUAL),
         CommandError, "INDIVIDUAL"),
        (lambda: MemoryCassetteTransfer(CassetteOperation.VERIFY, CassetteArea(0x8002)),
         CommandError, "reserved"),
        (lambda: MemoryCassetteTransfer(
            CassetteOperation.READ_DATA_TYPE, CassetteArea.INDIVIDUAL | CassetteArea.COMMENTS),
         CommandError, "READ_DATA_TYPE"),
        (lambda: MemoryCassetteTransfer(4), CommandError, "memory cassette parameter"),  # type: ignore[arg-type]
        (lambda: ConvertToCompowayFCommand(b"0100001"), CommandError, "9..2000"),
        (lambda: ConvertToCompowayFCommand(b"1A0000101"), CommandError, "00..99 or XX"),
        (lambda: ConvertToCompowayFCommand(b"01000010G"), CommandError, "4 hex digits"),
        (lambda: ConvertToCompowayFCommand(b"010000101\x03"), CommandError, "printable"),
        (lambda: ConvertToCompowayFCommand.build(100, "0101"), CommandError, "0..99"),
        (lambda: ConvertToCompowayFCommand.build(1, "010"), CommandError, "command code 4"),
        (lambda: ConvertToModbusRtuCommand(H("01")), CommandError, "2..254"),
        (lambda: ConvertToModbusRtuCommand(bytes(255)), CommandError, "2..254"),
        (lambda: ConvertToModbusRtuCommand(H("0003")), CommandError, "1..247"),
        (lambda: ConvertToModbusRtuCommand(H("F803")), CommandError, "1..247"),
        (lambda: ConvertToModbusRtuCommand(H("0100")), CommandError, "1..255"),
        (lambda: ConvertToModbusRtuCommand.build(1, 256), CommandError, "not bytes"),
        (lambda: ConvertToModbusAsciiCommand(b"010"), CommandError, "4..508"),
        (lambda: ConvertToModbusAsciiCommand(b"01030"), CommandError, "pairs of hex"),
        (lambda: ConvertToModbusAsciiCommand(b"0103ab"), CommandError, "pairs of hex"),
        (lambda: ConvertToModbusAsciiCommand(b"F803"), CommandError, "01..F7"),
        (lambda: ConvertToModbusAsciiCommand(b"0100"), CommandError, "01..FF"),
    ],
)  # fmt: skip
def test_builders_validate(build: Any, error: type[Exception], fragment: str) -> None:
    with pytest.raises(error, match=fragment):
        build()


@pytest.mark.parametrize(
    ("op", "params", "end_code"),
    [
        (FileNameRead, H("8000 0000 0014"), 0x1002),
        (FileNameRead, H("8000 0000 0014 0000 00"), 0x1001),
        (FileNameRead, H("8002 0000 0014 0000"), 0x110C),  # no such disk
        (FileNameRead, H("8000 0000 0015 0000"), 0x110C),  # 21 names
        (SingleFileRead, H("8000") + b"A B     .TXT" + H("00000000 0001 0000"), 0x110C),
        (SingleFileWrite, H("8000 0004") + b"A           " + H("00000000 0000 0000"), 0x110C),
        (SingleFileWrite, H("8000 0000") + b"A           " + H("00000000 0005 0102"), 0x1002),
        (SingleFileWrite, H("8000 0000") + b"A           " + H("00000001 0000 0000"), 0x110C),
        (FileDelete, H("8000 0002") + b"A           " + H("0000"), 0x1002),
        (FileDelete, H("8000 0000 0000"), 0x110C),
        (MemoryAreaFileTransfer, H("0000 30000001 0001 8000") + b"A" + b" " * 11 + H("0000"),
         0x1101),
        (MemoryAreaFileTransfer, H("0000 82000001 0001 8000") + b"A" + b" " * 11 + H("0000"),
         0x1103),
        (MemoryAreaFileTransfer, H("0003 82000000 0001 8000") + b"A" + b" " * 11 + H("0000"),
         0x110C),
        (ParameterAreaFileTransfer, H("0000 8011 0000 FFFF 8000") + b"A" + b" " * 11 + H("0000"),
         0x1101),
        (ProgramAreaFileTransfer, H("0000 0000 00000000 FFFFFFFF 8000") + b"A" + b" " * 11
         + H("0000"), 0x1106),
        (CreateDeleteDirectory, H("8000 0002") + b"D" + b" " * 11 + H("0000"), 0x110C),
        (MemoryCassetteTransfer, H("8000 0000 0000"), 0x110C),
        (MemoryCassetteTransfer, H("8003 0000 0040"), 0x110C),
        (MemoryCassetteTransfer, H("8003 8000 0000"), 0x1001),
        (MemoryCassetteTransfer, H("8003 0000"), 0x1002),
        (ConvertToCompowayFCommand, b"0100001", 0x1002),
        (ConvertToCompowayFCommand, b"AA0000101", 0x110C),
        (ConvertToModbusRtuCommand, H("01"), 0x1002),
        (ConvertToModbusRtuCommand, H("0001"), 0x110C),
        (ConvertToModbusAsciiCommand, b"01", 0x1002),
        (ConvertToModbusAsciiCommand, b"01G3", 0x110C),
    ],
)  # fmt: skip
def test_server_decode_end_codes(op: type[Request[Any]], params: bytes, end_code: int) -> None:
    with pytest.raises(DecodeError) as info:
        op.decode(params)
    assert info.value.end_code == end_code


def test_response_length_mismatch() -> None:
    with pytest.raises(DecodeError):
        SingleFileRead(CARD, "A").decode_response(H("00000014 00000000 0004 DEAD"))
    with pytest.raises(DecodeError):
        SingleFileRead(CARD, "A").decode_response(H("00000014 00000000 0001 DEAD"))
    with pytest.raises(DecodeError):
        FileNameRead(CARD).decode_response(bytes(26) + H("0001"))
    with pytest.raises(DecodeError):
        FileDelete(CARD, ("A",)).decode_response(H("000100"))


# --------------------------------------------------------------------------- round trips

disks = st.sampled_from([CARD, EM])
u16 = st.integers(0, 0xFFFF)
u32 = st.integers(0, 0xFFFFFFFF)
transfer_modes = st.sampled_from(list(FileTransferMode))
word_addresses = st.builds(
    MemoryAddress,
    st.sampled_from(sorted(file_ops.FILE_TRANSFER_AREA_CODES)),
    u16,
)
cassette_areas = st.one_of(
    st.just(CassetteArea(0)),
    st.integers(1, 0xFF)
    .map(lambda b: b & 0xFD)
    .filter(bool)
    .map(lambda b: CassetteArea(0x8000 | b)),
)


@st.composite
def single_file_writes(draw: st.DrawFn) -> SingleFileWrite:
    mode = draw(st.sampled_from(list(FileWriteMode)))
    position = draw(u32) if mode is FileWriteMode.OVERWRITE else 0
    directory = draw(directories())
    data = draw(st.binary(max_size=1976 - len(directory)))
    return SingleFileWrite(draw(disks), draw(file_names()), data, mode, position, directory)


@st.composite
def memory_cassette_transfers(draw: st.DrawFn) -> MemoryCassetteTransfer:
    operation = draw(st.sampled_from(list(CassetteOperation)))
    if operation is CassetteOperation.READ_DATA_TYPE:
        return MemoryCassetteTransfer(operation)
    return MemoryCassetteTransfer(operation, draw(cassette_areas))


requests = st.one_of(
    st.builds(FileNameRead, disks, u16, st.integers(0, 20), directories()),
    st.builds(SingleFileRead, disks, file_names(), u32, st.integers(0, 1988), directories()),
    single_file_writes(),
    st.builds(FileMemoryFormat, disks),
    st.builds(
        FileDelete, disks, st.lists(file_names(), min_size=1, max_size=30).map(tuple),
        directories(),
    ),
    st.builds(FileCopy, disks, file_names(), disks, file_names(), directories(), directories()),
    st.builds(FileNameChange, disks, file_names(), file_names(), directories()),
    st.builds(
        MemoryAreaFileTransfer, transfer_modes, word_addresses, st.integers(1, 0xFFFF), disks,
        file_names(), directories(),
    ),
    st.builds(
        ParameterAreaFileTransfer, transfer_modes,
        st.sampled_from(sorted(file_ops.FILE_TRANSFER_PARAMETER_AREAS)), disks, file_names(),
        st.just(0), st.just(0xFFFF), directories(),
    ),
    st.builds(
        ProgramAreaFileTransfer, transfer_modes, disks, file_names(), st.just(0xFFFF), st.just(0),
        st.just(0xFFFFFFFF),
        directories(),
    ),
    st.builds(
        CreateDeleteDirectory, disks, st.sampled_from(list(DirectoryOperation)), file_names(),
        directories(),
    ),
    memory_cassette_transfers(),
    st.builds(
        ConvertToCompowayFCommand.build,
        st.one_of(st.integers(0, 99), st.just("XX")),
        st.text("0123456789ABCDEF", min_size=4, max_size=4),
        st.binary(max_size=60).map(lambda b: b.hex().upper().encode()),
    ),
    st.builds(
        ConvertToModbusRtuCommand.build, st.integers(1, 247), st.integers(1, 255),
        st.binary(max_size=252),
    ),
    st.builds(
        ConvertToModbusAsciiCommand.build, st.integers(1, 247), st.integers(1, 255),
        st.binary(max_size=252),
    ),
)  # fmt: skip


@given(requests)
def test_request_round_trip(request_: Request[Any]) -> None:
    params = request_.encode()
    assert len(params) <= 2000
    op = operation_for(request_.MRC, request_.SRC, params)
    assert op is type(request_)
    assert op.decode(params) == request_


file_dates = st.integers(0, 0xFFFFFFFF).map(FileDate.from_raw)
entry_names = st.one_of(file_names(), st.sampled_from(["", ".", ".."]))
file_entries = st.builds(
    FileEntry, entry_names, file_dates, u32, st.integers(0, 0xFFFF).map(FileAttribute)
)
disk_data = st.builds(DiskData, entry_names, file_dates, u32, u32, u16)

# (request whose decode_response parses it, strategy of results)
RESULTS: list[tuple[Request[Any], st.SearchStrategy[Any]]] = [
    (
        FileNameRead(CARD),
        st.builds(
            FileNameReadResult, disk_data, st.lists(file_entries, max_size=20).map(tuple),
            st.booleans(),
        ),
    ),
    (
        SingleFileRead(CARD, "A"),
        st.builds(SingleFileReadResult, u32, u32, st.binary(max_size=1988), st.booleans()),
    ),
    (FileDelete(CARD, ("A",)), st.builds(FileDeleteResult, u16)),
    (GOLDEN[9][0], st.builds(FileTransferResult, u16)),
    (GOLDEN[10][0], st.builds(FileTransferResult, u16)),
    (GOLDEN[11][0], st.builds(ProgramAreaFileTransferResult, u32)),
    (
        MemoryCassetteTransfer(CassetteOperation.READ_DATA_TYPE),
        st.builds(MemoryCassetteDataType, st.integers(0, 0xFFFF).map(CassetteContents)),
    ),
    (GOLDEN[17][0], st.binary(min_size=6, max_size=200).map(CompowayFResponse)),
    (GOLDEN[19][0], st.binary(min_size=2, max_size=254).map(ModbusRtuResponse)),
    (
        GOLDEN[20][0],
        st.binary(min_size=2, max_size=254).map(lambda b: ModbusAsciiResponse(b.hex().encode())),
    ),
]  # fmt: skip


@pytest.mark.parametrize(("request_", "results"), RESULTS, ids=lambda v: getattr(v, "NAME", ""))
@given(data=st.data())
def test_result_round_trip(
    request_: Request[Any], results: st.SearchStrategy[Any], data: st.DataObject
) -> None:
    result = data.draw(results)
    assert request_.decode_response(result.encode()) == result


# --------------------------------------------------------------------------- fuzzing

ALL_OPS = file_ops.OPERATIONS + gateway.OPERATIONS
SAMPLE_REQUESTS = [r for r, _ in GOLDEN]


@pytest.mark.parametrize("op", ALL_OPS, ids=lambda op: op.NAME)
@given(params=st.binary(max_size=120))
def test_arbitrary_params_only_decode_error(op: type[Request[Any]], params: bytes) -> None:
    try:
        request_ = op.decode(params)
    except DecodeError as exc:
        assert exc.end_code is not None
        return
    assert request_.encode() == params  # what decodes is canonical


@pytest.mark.parametrize("request_", SAMPLE_REQUESTS, ids=lambda r: r.NAME)
@given(data=st.binary(max_size=120))
def test_arbitrary_response_only_decode_error(request_: Request[Any], data: bytes) -> None:
    try:
        result = request_.decode_response(data)
    except DecodeError:
        return
    if result is not None:
        assert request_.decode_response(result.encode()) == result


@given(
    st.binary(min_size=26, max_size=26),
    st.lists(st.binary(min_size=22, max_size=22), max_size=5),
    st.booleans(),
)
def test_arbitrary_listing_decodes(disk: bytes, entries: list[bytes], last: bool) -> None:
    count = len(entries) | (0x8000 if last else 0)
    data = disk + count.to_bytes(2, "big") + b"".join(entries)
    result = FileNameRead(CARD).decode_response(data)
    assert len(result.files) == len(entries) and result.last is last
    assert FileNameRead(CARD).decode_response(result.encode()) == result


@given(
    st.sampled_from(GOLDEN),
    st.lists(st.tuples(st.integers(0, 200), st.integers(0, 255)), max_size=3),
    st.integers(0, 200),
)
def test_mutated_params_only_decode_error(
    golden: tuple[Request[Any], bytes], edits: list[tuple[int, int]], cut: int
) -> None:
    request_, params = golden
    raw = bytearray(params)
    for position, value in edits:
        if raw:
            raw[position % len(raw)] = value
    mutated = bytes(raw[: max(cut, len(raw) - 3)])
    try:
        decoded = type(request_).decode(mutated)
    except DecodeError as exc:
        assert exc.end_code is not None
        return
    assert decoded.encode() == mutated
