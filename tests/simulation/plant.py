"""The simulated plant: Ethernet units in front of virtual PLCs, with a history of what each
PLC held when it executed each command, and the PLC-side faults of the schedule.

A :class:`Unit` is one Ethernet unit at ``10.0.0.K:9600``, FINS node ``K`` on network 0,
with its CPU (a :class:`~aiofins.simulator.VirtualPLC`) and, on some units, a relay to
network 2 where more CPUs sit (so one session talks to several destinations through one
relay, and relay errors come from the relay's address, not the destination's).

Address conversion is the simulator's model, :class:`~aiofins.simulator.EthernetUnit`
(:func:`ethernet`): automatic dynamic conversion replies to the address a request came from;
a unit with a fixed reply port (an IP address table, dynamic changes prohibited) replies to
the FINS port 9600 of its one client host, whichever socket sent the request.
"""

from __future__ import annotations

import random
import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

from aiofins.protocol.header import FinsAddress
from aiofins.simulator import AddressConversion, EthernetUnit, VirtualPLC

#: The network behind the relays, and the FINS port every unit listens on.
REMOTE_NETWORK = 2
FINS_PORT = 9600
#: Words of DM each PLC's traffic touches (D0..D63), the area code of DM words.
WINDOW = 64
DM = 0x82
#: End codes the schedule answers with: busy (manual 5-1-3), an error end code the PLC
#: answers without executing ("address range exceeded"), a relay error (bit 15).
BUSY = 0x2604
ERROR = 0x1103
RELAY_ERROR = 0x8205

Address = tuple[str, int]


def ethernet(number: int, fixed_host: str | None) -> EthernetUnit:
    """Unit ``number``'s address conversion at ``10.0.0.{number}``: automatic, dynamic;
    or (``fixed_host``) an IP address table sending every node's replies to port 9600 of
    ``fixed_host``, never changed by what arrives (unit version 1.3's "dynamic changes
    prohibited")."""
    ip = f"10.0.0.{number}"
    if fixed_host is None:
        return EthernetUnit(ip)
    return EthernetUnit(
        ip,
        conversion=AddressConversion.IP_ADDRESS_TABLE,
        ip_table={n: fixed_host for n in range(1, 255) if n != number},
        change_dynamically=False,
        node=number,
    )


class Wire(Protocol):
    """What a unit sends its replies through (the network)."""

    def reply(self, unit: Unit, to: object, frame: bytes, late: float = 0.0) -> None: ...


@dataclass(slots=True)
class History:
    """What one PLC did: each read's words at the moment it executed, each write's
    executions (by its parameter bytes, which carry unique values)."""

    index: int
    address: FinsAddress
    #: read parameters (area, address, bit, count) -> [(time, words bytes)]
    reads: dict[bytes, list[tuple[float, bytes]]] = field(default_factory=dict)
    #: DM address -> [(time, value)] as read by any executed read (for snapshots)
    seen: dict[int, list[tuple[float, int]]] = field(default_factory=dict)
    #: write parameters + data -> [time of each execution]
    writes: dict[bytes, list[float]] = field(default_factory=dict)
    #: (time, end code, the request's source node) of every error end code answered for it
    errors: list[tuple[float, int, int]] = field(default_factory=list)
    #: (time, data) of every reply sent under a wrong SID, and (time, word) of its words: a
    #: reply the PLC sends under a SID that is another request's in flight (same command)
    #: is that request's reply to the client (FINS has nothing else to match it by), so
    #: those words are the PLC's fault, not the client's.
    spoiled: list[tuple[float, bytes]] = field(default_factory=list)
    spoiled_words: list[tuple[float, int]] = field(default_factory=list)
    counter: int = WINDOW

    def next_value(self) -> int:
        """A value no other PLC holds and this one held not for a long while."""
        self.counter += 1
        return (self.index << 12) | (self.counter & 0xFFF)


class Target:
    """One CPU behind a unit: the virtual PLC and its history."""

    def __init__(self, index: int, address: FinsAddress, clock: Callable[[], float]) -> None:
        self.plc = VirtualPLC(network=address.network, node=address.node, clock=clock)
        self.history = History(index, address)
        self.clock = clock
        values = [(index << 12) | a for a in range(WINDOW)]
        self.plc.write("D0", values)

    def execute(self, frame: bytes) -> bytes | None:
        reply = self.plc.handle_frame(frame)
        if reply is None or len(reply) < 14 or reply[12:14] != b"\x00\x00":
            return reply
        now = self.clock()
        code = (frame[10] << 8) | frame[11]
        h = self.history
        if code == 0x0101 and frame[12] == DM:
            params = bytes(frame[12:18])
            data = bytes(reply[14:])
            h.reads.setdefault(params, []).append((now, data))
            start = (frame[13] << 8) | frame[14]
            seen = h.seen
            for i, (v,) in enumerate(struct.iter_unpack(">H", data)):
                seen.setdefault(start + i, []).append((now, v))
        elif code == 0x0104:  # multiple memory area read: (area, address, bit) per item
            data = reply[14:]
            seen = h.seen
            for i in range(12, len(frame) - 3, 4):
                j = (i - 12) // 4 * 3
                if frame[i] == DM and data[j : j + 1] == bytes((DM,)):
                    (v,) = struct.unpack_from(">H", data, j + 1)
                    seen.setdefault((frame[i + 1] << 8) | frame[i + 2], []).append((now, v))
        elif code == 0x0102:
            h.writes.setdefault(bytes(frame[12:]), []).append(now)
        return reply


class Unit:
    """An Ethernet unit with its CPU and (``relay=True``) CPUs on network 2 behind it."""

    def __init__(
        self,
        number: int,
        targets: dict[tuple[int, int], Target],
        ethernet: EthernetUnit,
        rng: random.Random,
        clock: Callable[[], float],
        wire: Wire,
    ) -> None:
        self.number = number
        self.ip = f"10.0.0.{number}"
        self.address: Address = (self.ip, FINS_PORT)
        self.fins = FinsAddress(0, number, 0)
        #: (network, node) -> target; network 0 and the unit's own node is its CPU.
        self.targets = targets
        #: The unit's address conversion (where a UDP reply goes).
        self.ethernet = ethernet
        #: Its replies go to one fixed port (the client binds port 9600).
        self.fixed = ethernet.conversion is not AddressConversion.AUTOMATIC_DYNAMIC
        self.rng = rng
        self.clock = clock
        self.wire = wire
        #: Active fault episodes: kind -> probability (or 1.0).
        self.faults: dict[str, float] = {}
        #: Late relay errors wait this long (seconds) before they go.
        self.late_after = 1.0
        self.tcp_nodes = 0
        self.frames = 0

    def target_of(self, frame: bytes) -> Target | None:
        dna, da1 = frame[3], frame[4]
        if dna == 0 or dna == self.fins.network:
            return self.targets.get((0, da1)) if da1 == self.number else None
        return self.targets.get((dna, da1))

    def receive(self, frame: bytes, sender: object) -> None:
        """One command frame arrived from ``sender`` (an address, or a FINS/TCP
        connection): replies go back by the same way (:class:`Wire`)."""
        self.frames += 1
        faults = self.faults
        if "silence" in faults or len(frame) < 12:
            return
        target = self.target_of(frame)
        if target is None:
            return
        rng = self.rng
        to = sender
        if faults:
            remote = frame[3] == REMOTE_NETWORK
            if remote and "relay" in faults and rng.random() < faults["relay"]:
                late = self.late_after if rng.random() < 0.5 else 0.0
                target.history.errors.append((self.clock() + late, RELAY_ERROR, frame[7]))
                self.wire.reply(self, to, self._error(frame, RELAY_ERROR, relay=True), late)
                return
            for kind, code in (("busy", BUSY), ("error", ERROR)):
                if kind in faults and rng.random() < faults[kind]:
                    target.history.errors.append((self.clock(), code, frame[7]))
                    self.wire.reply(self, to, self._error(frame, code, relay=False))
                    return
        reply = target.execute(frame)
        if reply is None:
            return
        if faults:
            reply = self._spoil(reply, faults)
            if reply[9:10] != frame[9:10]:  # sent under a wrong SID
                now, data = self.clock(), bytes(reply[14:])
                h = target.history
                h.spoiled.append((now, data))
                if frame[10:12] == b"\x01\x04":  # (area, word) triples
                    words = [data[i + 1 : i + 3] for i in range(0, len(data) - 2, 3)]
                else:
                    words = [data[i : i + 2] for i in range(0, len(data) - 1, 2)]
                h.spoiled_words += [(now, int.from_bytes(w, "big")) for w in words]
        self.wire.reply(self, to, reply)

    def _spoil(self, reply: bytes, faults: dict[str, float]) -> bytes:
        rng = self.rng
        if "wrong_sid" in faults and rng.random() < faults["wrong_sid"]:
            reply = reply[:9] + bytes(((reply[9] + 1 + rng.randrange(255)) & 0xFF,)) + reply[10:]
        if "runt" in faults and rng.random() < faults["runt"]:
            return reply[:11]
        if len(reply) > 15 and reply[10:12] == b"\x01\x01":
            if "short" in faults and rng.random() < faults["short"]:
                return reply[:-2]
            if "long" in faults and rng.random() < faults["long"]:
                return reply + b"\x7f\xff"
        return reply

    def _error(self, frame: bytes, code: int, *, relay: bool) -> bytes:
        """An error reply to ``frame``: from the relay (this unit) with its trailer, or from
        the destination."""
        me = self.fins if relay else FinsAddress(frame[3], frame[4], frame[5])
        head = bytes(
            (0xC0, 0, 2, frame[6], frame[7], frame[8], me.network, me.node, me.unit, frame[9])
        )
        out = head + frame[10:12] + struct.pack(">H", code)
        return out + bytes((me.network, me.node)) if relay else out

    def assign_tcp_node(self) -> int:
        """The client node a FINS/TCP handshake hands out (never the unit's own)."""
        self.tcp_nodes = self.tcp_nodes % 200 + 1
        node = 50 + self.tcp_nodes
        return node if node != self.number else node + 1
