"""Wireshark's Omron FINS dissector as an independent oracle for the frames aiofins builds.

The frames are written to a pcap file (format written here with :mod:`struct`: a global
header, then Ethernet/IPv4/UDP records to port 9600, and a FINS/TCP stream) and decoded by
``tshark -d udp.port==9600,omron``. We assert that tshark sees the command codes, SIDs, ICF
and end codes we meant, and that it reports no malformed packet and no expert warning.

Known false alarms of the 4.0 dissector: 0501 without its optional data byte ("Malformed
Packet") and error replies to commands whose response has a fixed format (it expects the data
anyway) are avoided; CS/CJ STOP with its program number FFFF (manual 5-3-14; the CV-era
dissector wants no parameter) is tolerated by matching the expected expert message. Its
0601/0C01 bit and byte orders are wrong (wire-format §9), so we do not assert on those fields.
"""

from __future__ import annotations

import shutil
import struct
import subprocess
from dataclasses import dataclass
from pathlib import Path

import pytest

from aiofins.protocol import tcp
from aiofins.protocol.endcodes import EndCode
from aiofins.protocol.header import CommandFrame, FinsAddress, ResponseFrame, build_command

TSHARK = shutil.which("tshark")
pytestmark = pytest.mark.skipif(TSHARK is None, reason="tshark is not installed")

PLC = FinsAddress(0, 0x0A, 0)
CLIENT = FinsAddress(0, 0x22, 0)
CLIENT_IP = (10, 0, 0, 34)
PLC_IP = (10, 0, 0, 10)
FINS_PORT = 9600
CLIENT_PORT = 50000


@dataclass(frozen=True)
class Exchange:
    """One command and (optionally) its response."""

    mrc: int
    src: int
    params: bytes
    end_code: int | None  # None: no response frame
    data: bytes = b""
    relay: tuple[int, int] | None = None
    #: The dissector's known false alarm on the command frame (expert message), if any.
    command_alarm: str = ""


def _words(*values: int) -> bytes:
    return b"".join(v.to_bytes(2, "big") for v in values)


# Parameters built by hand from the manual's formats (section 5-3).
EXCHANGES: list[Exchange] = [
    Exchange(0x01, 0x01, bytes.fromhex("820064 00 000A"), 0x0000, _words(*range(1, 11))),
    Exchange(0x01, 0x01, bytes.fromhex("B00010 00 0002"), 0x0040, _words(0x1234, 0x5678)),
    Exchange(0x01, 0x01, bytes.fromhex("300010 0D 0001"), 0x0080, b"\x01"),  # CIO 10.13
    Exchange(0x01, 0x02, bytes.fromhex("820064 00 0003") + _words(1, 2, 3), 0x0000),
    Exchange(0x01, 0x03, bytes.fromhex("820000 00 0064") + _words(0), 0x0000),
    Exchange(
        0x01,
        0x04,
        bytes.fromhex("820064 00  B00010 00  300010 0D"),
        0x0000,
        bytes.fromhex("82 0001  B0 1234  30 01"),
    ),
    Exchange(0x01, 0x05, bytes.fromhex("820064 00  820C80 00  000A"), 0x0000),
    Exchange(0x04, 0x01, bytes.fromhex("FFFF 04"), 0x0000),
    # CS/CJ STOP carries program number FFFF (manual 5-3-14); the CV-era dissector wants none.
    Exchange(0x04, 0x02, bytes.fromhex("FFFF"), 0x0000, command_alarm="Unexpected Length"),
    Exchange(0x05, 0x01, bytes.fromhex("00"), None),
    Exchange(0x06, 0x01, b"", None),
    Exchange(0x07, 0x01, b"", 0x0000, bytes.fromhex("26 11 25 12 30 45 03")),
    Exchange(0x07, 0x02, bytes.fromhex("26 11 25 12 30 45 03"), 0x0000),
    Exchange(0x0C, 0x01, bytes.fromhex("FFFF"), 0x0000),
    Exchange(0x0C, 0x03, bytes.fromhex("FFFF"), 0x0000),
    Exchange(0x21, 0x01, bytes.fromhex("FFFE"), 0x0000),
    Exchange(0x21, 0x03, b"", 0x0000),
    Exchange(0x23, 0x02, b"", 0x0000),
    Exchange(
        0x06, 0x20, b"\x01", 0x0000, bytes.fromhex("0000028A 000003E8 00000064")
    ),  # cycle time read
    Exchange(0x06, 0x20, b"\x00", 0x0000),  # cycle time initialise
    Exchange(
        0x02,
        0x01,
        bytes.fromhex("8010 0000 0002"),
        0x0000,
        bytes.fromhex("8010 0000 0002 1234 5678"),
    ),
    Exchange(
        0x03,
        0x06,
        bytes.fromhex("FFFF 00000000 0008"),
        0x0000,
        bytes.fromhex("FFFF 00000000 0008") + bytes(8),
    ),
    Exchange(0x09, 0x20, bytes.fromhex("0001"), 0x0000, bytes.fromhex("0001") + b"HELLO".ljust(32)),
    Exchange(
        0x21,
        0x02,
        bytes.fromhex("0000 0001"),
        0x0000,
        bytes.fromhex("0014 0001 0001 0002 4101 30 45 25 12 26 11"),
    ),
    Exchange(0x23, 0x01, bytes.fromhex("0001 0001 30 000A 03"), 0x0000),
    Exchange(0x01, 0x01, bytes.fromhex("820064 00 0001"), 0x8205, relay=(1, 5)),
    Exchange(0x06, 0x01, b"", 0x0000, bytes.fromhex("01 04 0000 0010 0000 0000") + b" " * 16),
    Exchange(
        0x05,
        0x02,
        bytes.fromhex("00 02"),
        0x0000,
        bytes.fromhex("82 00") + b"CJ2M-CPU33".ljust(20) + b"\x10" + b"CJ1W-ETN21".ljust(20),
    ),
    # Error replies without data to commands whose response is only an end code.
    Exchange(0x01, 0x02, bytes.fromhex("820064 00 0001") + _words(7), 0x2102),
    Exchange(0x04, 0x01, bytes.fromhex("FFFF 04"), 0x3001),
]


def _ipv4_checksum(header: bytes) -> int:
    total: int = sum(struct.unpack("!10H", header))
    while total >> 16:
        total = (total & 0xFFFF) + (total >> 16)
    return ~total & 0xFFFF


def _ethernet_ipv4(
    protocol: int, src_ip: tuple[int, ...], dst_ip: tuple[int, ...], l4: bytes
) -> bytes:
    ip = struct.pack(
        "!BBHHHBBH4s4s",
        0x45,
        0,
        20 + len(l4),
        0,
        0x4000,
        64,
        protocol,
        0,
        bytes(src_ip),
        bytes(dst_ip),
    )
    ip = ip[:10] + struct.pack("!H", _ipv4_checksum(ip)) + ip[12:]
    return bytes.fromhex("020000000001 020000000002 0800") + ip + l4


def udp_packet(payload: bytes, *, to_plc: bool) -> bytes:
    ports = (CLIENT_PORT, FINS_PORT) if to_plc else (FINS_PORT, CLIENT_PORT)
    ips = (CLIENT_IP, PLC_IP) if to_plc else (PLC_IP, CLIENT_IP)
    udp = struct.pack("!HHHH", ports[0], ports[1], 8 + len(payload), 0) + payload
    return _ethernet_ipv4(17, ips[0], ips[1], udp)


def tcp_packet(payload: bytes, *, to_plc: bool, seq: int, ack: int, flags: int = 0x18) -> bytes:
    ports = (CLIENT_PORT, FINS_PORT) if to_plc else (FINS_PORT, CLIENT_PORT)
    ips = (CLIENT_IP, PLC_IP) if to_plc else (PLC_IP, CLIENT_IP)
    # Checksum 0: tshark does not validate TCP checksums by default.
    segment = struct.pack("!HHIIBBHHH", ports[0], ports[1], seq, ack, 5 << 4, flags, 65535, 0, 0)
    return _ethernet_ipv4(6, ips[0], ips[1], segment + payload)


def pcap(packets: list[bytes]) -> bytes:
    """A classic little-endian pcap file, link type 1 (Ethernet), one record per packet."""
    out = struct.pack("<IHHiIII", 0xA1B2C3D4, 2, 4, 0, 0, 65535, 1)
    for i, packet in enumerate(packets):
        out += struct.pack("<IIII", 1_700_000_000 + i, 0, len(packet), len(packet)) + packet
    return out


FIELDS = [
    "frame.number",
    "omron.icf",
    "omron.sid",
    "omron.command",
    "omron.response.code",
    "omron.tcp.command",
    "omron.tcp.client_node_address",
    "omron.tcp.server_node_address",
    "_ws.malformed",
    "_ws.expert.severity",
    "_ws.expert.message",
]


def run_tshark(path: Path, *decode_as: str) -> list[dict[str, str]]:
    assert TSHARK is not None
    args = [TSHARK, "-r", str(path), "-T", "fields", "-E", "separator=\t", "-E", "occurrence=a"]
    for rule in decode_as:
        args += ["-d", rule]
    for field in FIELDS:
        args += ["-e", field]
    proc = subprocess.run(args, capture_output=True, text=True, timeout=60, check=True)
    rows = []
    for line in proc.stdout.splitlines():
        cells = line.split("\t")
        rows.append(dict(zip(FIELDS, cells + [""] * (len(FIELDS) - len(cells)), strict=True)))
    return rows


Expected = tuple[int, int, int, "int | None", str]


#: Wireshark's expert severities: chat 0x200000, note 0x400000, warn 0x600000, error 0x800000.
PI_WARN = 0x00600000


def _warnings(row: dict[str, str]) -> list[int]:
    """The expert infos of a row at warning level or above (TCP's SYN "chat" is fine)."""
    return [
        s for s in map(int, filter(None, row["_ws.expert.severity"].split(","))) if s >= PI_WARN
    ]


def _number(text: str) -> int:
    """A tshark field value: ``0x..`` for hex-based fields, decimal otherwise."""
    return int(text, 16) if text.startswith("0x") else int(text)


def _build() -> tuple[list[bytes], list[Expected]]:
    """FINS frames in capture order and what tshark should say.

    (ICF, SID, command code, end code or None for a command, tolerated expert message)
    """
    frames: list[bytes] = []
    expected: list[Expected] = []
    for sid, ex in enumerate(EXCHANGES, start=1):
        raw = build_command(PLC, CLIENT, sid, ex.mrc, ex.src, ex.params)
        frames.append(raw)
        code = (ex.mrc << 8) | ex.src
        expected.append((0x80, sid, code, None, ex.command_alarm))
        if ex.end_code is not None:
            reply = ResponseFrame.reply_to(
                CommandFrame.decode(raw), EndCode(ex.end_code), ex.data, ex.relay
            )
            frames.append(reply.encode())
            expected.append((0xC0, sid, code, ex.end_code, ""))
    return frames, expected


def _check(rows: list[dict[str, str]], expected: list[Expected]) -> None:
    assert len(rows) == len(expected)
    for row, (icf, sid, code, end_code, alarm) in zip(rows, expected, strict=True):
        where = f"frame {row['frame.number']} ({code:04X} SID {sid})"
        assert int(row["omron.icf"], 16) == icf, where
        assert int(row["omron.sid"], 16) == sid, where
        assert int(row["omron.command"], 16) == code, where
        if end_code is None:
            assert row["omron.response.code"] == "", where
        else:
            assert int(row["omron.response.code"], 16) == end_code, where
        if alarm:
            assert alarm in row["_ws.expert.message"], where
            continue
        assert row["_ws.malformed"] == "", f"{where}: malformed: {row['_ws.expert.message']}"
        assert not _warnings(row), f"{where}: {row['_ws.expert.message']}"


def test_udp_frames_decode_as_intended(tmp_path: Path) -> None:
    frames, expected = _build()
    packets = [udp_packet(f, to_plc=not f[0] & 0x40) for f in frames]
    path = tmp_path / "fins-udp.pcap"
    path.write_bytes(pcap(packets))
    _check(run_tshark(path, f"udp.port=={FINS_PORT},omron"), expected)


def test_pcap_writer_is_what_tshark_reads(tmp_path: Path) -> None:
    path = tmp_path / "one.pcap"
    frame = build_command(PLC, CLIENT, 0x42, 0x07, 0x01)
    path.write_bytes(pcap([udp_packet(frame, to_plc=True)]))
    assert TSHARK is not None
    out = subprocess.run(
        [
            TSHARK,
            "-r",
            str(path),
            "-T",
            "fields",
            "-e",
            "udp.dstport",
            "-e",
            "ip.checksum.status",
            "-e",
            "udp.payload",
            "-o",
            "ip.check_checksum:TRUE",
        ],
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    ).stdout.split()
    assert out[0] == "9600"
    assert out[-1].replace(":", "") == frame.hex()


def test_no_response_command_and_a_broken_frame(tmp_path: Path) -> None:
    """ICF 81 decodes as such, and the oracle does flag a frame that is really malformed."""
    no_reply = build_command(
        PLC, CLIENT, 0x77, 0x04, 0x01, b"\xff\xff\x04", response_required=False
    )
    truncated = build_command(PLC, CLIENT, 0x78, 0x01, 0x01, bytes.fromhex("8200"))
    path = tmp_path / "negative.pcap"
    path.write_bytes(pcap([udp_packet(no_reply, to_plc=True), udp_packet(truncated, to_plc=True)]))
    first, second = run_tshark(path, f"udp.port=={FINS_PORT},omron")
    assert (first["omron.icf"], first["omron.sid"], first["omron.command"]) == (
        "0x81",
        "0x77",
        "0x0401",
    )
    assert first["_ws.malformed"] == "" and not _warnings(first)
    assert second["omron.command"] == "0x0101"
    assert second["_ws.malformed"] and _warnings(second)


class TcpCapture:
    """Builds the packets of one TCP connection between the client and the PLC."""

    def __init__(self) -> None:
        self.seq = {True: 1000, False: 5000}  # keyed by "to PLC"
        self.packets: list[bytes] = []
        self._segment(b"", to_plc=True, flags=0x02)  # SYN
        self._segment(b"", to_plc=False, flags=0x12)  # SYN, ACK
        self._segment(b"", to_plc=True, flags=0x10)  # ACK

    def _segment(self, payload: bytes, *, to_plc: bool, flags: int) -> None:
        ack = self.seq[not to_plc] if flags != 0x02 else 0
        self.packets.append(
            tcp_packet(payload, to_plc=to_plc, seq=self.seq[to_plc], ack=ack, flags=flags)
        )
        self.seq[to_plc] += len(payload) + (1 if flags & 0x02 else 0)

    def send(self, payload: bytes, *, to_plc: bool) -> None:
        self._segment(payload, to_plc=to_plc, flags=0x18)  # PSH, ACK


def test_fins_tcp_stream_split_and_merged(tmp_path: Path) -> None:
    """FINS/TCP: handshake, frames cut across segments and several frames in one segment."""
    client = FinsAddress(0, 0xEF, 0)
    commands: list[bytes] = []
    replies: list[bytes] = []
    expected: list[tuple[int, int, int]] = []
    end_codes: list[int] = []
    for sid, ex in enumerate(EXCHANGES[:6], start=0x40):
        assert ex.end_code is not None
        raw = build_command(PLC, client, sid, ex.mrc, ex.src, ex.params)
        reply = ResponseFrame.reply_to(CommandFrame.decode(raw), ex.end_code, ex.data)
        commands.append(tcp.encode_frame(raw))
        replies.append(tcp.encode_frame(reply.encode()))
        code = (ex.mrc << 8) | ex.src
        expected += [(0x80, sid, code)]
        end_codes.append(ex.end_code)
    capture = TcpCapture()
    capture.send(tcp.encode_node_request(0), to_plc=True)
    capture.send(tcp.encode_node_response(0xEF, 0x0A), to_plc=False)
    # Command 1 cut inside its FINS/TCP header, command 2 cut inside its FINS header.
    stream = b"".join(commands[:3])
    for start, end in ((0, 7), (7, len(commands[0]) + 20), (len(commands[0]) + 20, len(stream))):
        capture.send(stream[start:end], to_plc=True)
    capture.send(b"".join(replies[:3]), to_plc=False)  # three replies in one segment
    capture.send(b"".join(commands[3:]), to_plc=True)
    capture.send(b"".join(replies[3:]), to_plc=False)
    path = tmp_path / "fins-tcp.pcap"
    path.write_bytes(pcap(capture.packets))

    rows = run_tshark(path, f"tcp.port=={FINS_PORT},omron")

    def column(name: str) -> list[int]:
        return [_number(v) for row in rows for v in row[name].split(",") if v]

    assert column("omron.tcp.command") == [0, 1] + [2] * 12
    assert column("omron.tcp.client_node_address") == [0, 0xEF]
    assert column("omron.tcp.server_node_address") == [0x0A]
    pdus = list(zip(column("omron.icf"), column("omron.sid"), column("omron.command"), strict=True))
    replies_seen = [(icf, sid, code) for icf, sid, code in pdus if icf & 0x40]
    assert [p for p in pdus if not p[0] & 0x40] == expected
    assert replies_seen == [(0xC0, sid, code) for _, sid, code in expected]
    assert column("omron.response.code") == end_codes
    for row in rows:
        assert row["_ws.malformed"] == "", row
        assert not _warnings(row), row


def test_memory_area_read_parameters(tmp_path: Path) -> None:
    """tshark reads the area code, address and count of 0101 where we put them."""
    frames = [
        build_command(PLC, CLIENT, 1, 0x01, 0x01, bytes.fromhex("820064 00 000A")),  # D100 x 10
        build_command(PLC, CLIENT, 2, 0x01, 0x01, bytes.fromhex("B017FF 00 0001")),  # CIO 6143
    ]
    path = tmp_path / "read.pcap"
    path.write_bytes(pcap([udp_packet(f, to_plc=True) for f in frames]))
    assert TSHARK is not None
    fields = ["omron.memory.area.read", "omron.memory.address", "omron.memory.numitems"]
    args = [TSHARK, "-r", str(path), "-d", f"udp.port=={FINS_PORT},omron", "-T", "fields"]
    for field in fields:
        args += ["-e", field]
    out = subprocess.run(args, capture_output=True, text=True, timeout=60, check=True).stdout
    rows = [[_number(v) for v in line.split("\t")] for line in out.splitlines()]
    assert rows == [[0x82, 100, 10], [0xB0, 6143, 1]]
