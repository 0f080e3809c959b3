"""A plant of virtual PLCs on several FINS networks, relaying by routing tables.

Each :class:`Station` is a virtual PLC (CPU Unit) with one or more communications units,
each unit a node on one :class:`Network`. A station with routing tables is a gateway:

* **local network table**: unit address -> the network that unit is on;
* **relay network table**: destination network -> (relay network, relay node), the next
  station towards a network that is not local.

How a frame travels (manual 5-1-1/5-1-3; wire-format §1):

* DNA 0 means "the network the frame arrived on", DA1 0 "the local PLC" there. A frame
  whose DNA is one of the station's networks and whose DA1 is its node there (or 0 on the
  network it arrived on) is for the station's CPU Unit.
* A frame for a node on another of the station's networks is put on that network (local
  network table); a frame for a network that is not local goes to the relay node the relay
  network table names. Each station that forwards a frame is a gateway crossed: it takes one
  from GCT first, and a frame that must be forwarded with GCT 0 is refused with **0504**
  (too many relays). A response is forwarded the same way (it is routed to its DNA/DA1, the
  command's source: a routed request needs its source network, SNA, filled in); a response
  that cannot be forwarded is dropped and counted, as nothing answers a response.
* Refusals come from the relay point with bit 15 set and the relay's network and node in
  the two bytes after the end code (its address on the network the command arrived on):
  **0502** the station has no routing tables, **0501** its relay network table has no entry
  for DNA, **0504** GCT was 0, **0205** the next node does not answer (not on the network, or
  down), **0204** the next node is busy.
* Size limits per network type (:data:`aiofins.protocol.limits.NETWORK_LIMITS`: 2,000
  parameter bytes on Ethernet and Controller Link, 540 on SYSMAC LINK, DeviceNet and serial
  Host Link). The manual names no relay end code for a frame too long for the next network;
  **ours** is **1001** (command too long) with bit 15 and the relay's trailer for a command,
  and **110B** (response too long, no bit 15) from a destination whose response does not fit
  the network it must answer on.
* The responder starts its response with GCT 2 (what Omron units send); each crossing back
  takes one.

Ethernet units reach hosts outside the plant (a client) through their FINS address
conversion, :class:`~aiofins.simulator.ethernet.EthernetUnit` (automatic dynamic: the
address and port the node's last request came from; automatic static: the unit's subnet
with the node number as host part, FINS port 9600; IP address table; combined). With
static conversion or a table a client must bind the FINS port itself (``local_port=9600``)
and use one SID space (``max_sid_spaces=1``).

Pure routing: :meth:`Plant.receive` takes a datagram that reached a unit and returns the
datagrams to send, so the UDP servers (:mod:`.plantserver`) and in-memory tests share it.
"""

from __future__ import annotations

import logging
from collections import Counter, deque
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from enum import Enum

from ..protocol.endcodes import RELAY_ERROR_FLAG, EndCode
from ..protocol.errors import CommandError, DecodeError, FrameError
from ..protocol.header import CommandFrame, FinsAddress, Header, ResponseFrame
from ..protocol.limits import NETWORK_LIMITS, NetworkType
from .ethernet import AddressConversion, EthernetUnit
from .plc import VirtualPLC

_logger = logging.getLogger("aiofins.simulator")

#: Relay end codes (bit 15 is added on the wire).
NO_ROUTE = 0x0501  #: the relay network table has no entry for DNA
NO_ROUTING_TABLES = 0x0502  #: the station has no routing tables at all
TOO_MANY_RELAYS = 0x0504  #: GCT was 0 where the frame had to be forwarded
NODE_BUSY = 0x0204  #: the next node is busy
NO_RESPONSE = 0x0205  #: the next node does not answer
#: Ours (the manual names none): a command too long for the next network.
COMMAND_TOO_LONG = 0x1001
#: A response too long for the network the destination must answer on.
RESPONSE_TOO_LONG = 0x110B
#: The GCT a station writes into the responses it makes.
RESPONSE_GCT = 2
#: The FINS UDP port (where an Ethernet unit listens unless told).
FINS_PORT = 9600
#: Frames each network's trace keeps (the oldest dropped).
TRACE_LENGTH = 1000


class StationState(Enum):
    """Whether a station answers what reaches it."""

    #: It answers and forwards.
    UP = "up"
    #: A relay to it gets 0204 (destination node busy).
    BUSY = "busy"
    #: A relay to it gets 0205 (no response); a datagram sent to it is dropped.
    DOWN = "down"


@dataclass(frozen=True, slots=True)
class Network:
    """One FINS network of the plant: its number (1..127) and type."""

    number: int
    type: NetworkType

    def __post_init__(self) -> None:
        if not 1 <= self.number <= 127:
            raise CommandError(f"network number {self.number} out of range 1..127")


@dataclass(slots=True)
class Unit:
    """A communications unit of a station: its unit address, network and node; an Ethernet
    unit served on UDP also has its IPv4 ``host``, the ``port`` it is bound to (0: any free
    port) and its address conversion (:attr:`ethernet`)."""

    address: int
    network: int
    node: int
    host: str | None = None
    port: int = FINS_PORT
    conversion: AddressConversion = AddressConversion.AUTOMATIC_DYNAMIC
    #: The IP address table (node -> IP address), for the table and combined methods.
    ip_table: dict[int, str] = field(default_factory=dict)
    #: The FINS UDP port that static conversion and the IP address table send to (9600 in a
    #: plant; tests on loopback pick a free one).
    fins_port: int = FINS_PORT
    #: The address conversion of a unit served on UDP (``None`` without ``host``).
    ethernet: EthernetUnit | None = field(default=None, init=False)

    def __post_init__(self) -> None:
        if not 0 <= self.address <= 0xFF:
            raise CommandError(f"unit address {self.address} out of range 0..255")
        if not 1 <= self.node <= 254:
            raise CommandError(f"node {self.node} out of range 1..254")
        self.conversion = AddressConversion(self.conversion)
        if self.host is not None:
            try:
                self.ethernet = EthernetUnit(
                    self.host,
                    conversion=self.conversion,
                    ip_table=self.ip_table,
                    fins_port=self.fins_port,
                    node=self.node,
                )
            except ValueError as exc:
                raise CommandError(f"unit {self.address:#04x} at {self.host}: {exc}") from None

    def peer_of(self, node: int) -> tuple[str, int] | None:
        """Where this unit sends a frame for ``node`` outside the plant (``None``: nowhere)."""
        return None if self.ethernet is None else self.ethernet.address_of(node)


@dataclass(frozen=True, slots=True)
class RoutingTables:
    """A station's routing tables (manual 5-1-1)."""

    #: Local network table: unit address -> network number.
    local: Mapping[int, int]
    #: Relay network table: destination network -> (relay network, relay node).
    relay: Mapping[int, tuple[int, int]] = field(default_factory=dict)


@dataclass(slots=True)
class Station:
    """A PLC of the plant: its CPU Unit, communications units and routing tables."""

    name: str
    plc: VirtualPLC
    units: list[Unit]
    tables: RoutingTables | None = None
    state: StationState = StationState.UP

    def unit_on(self, network: int) -> Unit | None:
        return next((u for u in self.units if u.network == network), None)

    def networks(self) -> set[int]:
        return {u.network for u in self.units}


@dataclass(frozen=True, slots=True)
class Datagram:
    """A frame to send from ``unit``'s socket to ``host``:``port``."""

    unit: Unit
    frame: bytes
    host: str
    port: int


@dataclass(frozen=True, slots=True)
class Hop:
    """One frame as it travelled on one network (a trace entry)."""

    network: int
    frame: bytes


class Plant:
    """Networks and stations; :meth:`receive` routes what reaches an Ethernet unit."""

    def __init__(self, networks: Iterable[Network], stations: Iterable[Station]) -> None:
        self.networks = {n.number: n for n in networks}
        self.stations = list(stations)
        self._nodes: dict[tuple[int, int], Station] = {}
        for station in self.stations:
            for unit in station.units:
                if unit.network not in self.networks:
                    raise CommandError(
                        f"station {station.name!r}: unit {unit.address:#04x} is on network "
                        f"{unit.network}, which the plant does not have"
                    )
                key = (unit.network, unit.node)
                if key in self._nodes:
                    raise CommandError(
                        f"node {unit.node} on network {unit.network} is both "
                        f"{self._nodes[key].name!r} and {station.name!r}"
                    )
                self._nodes[key] = station
            self._check_tables(station)
        #: Frames put on each network (command and response), newest last.
        self.trace: deque[Hop] = deque(maxlen=TRACE_LENGTH)
        #: What happened to frames: ``relayed``, ``delivered``, ``refused:0501``, ...
        self.counts: Counter[str] = Counter()

    def _check_tables(self, station: Station) -> None:
        tables = station.tables
        if tables is None:
            return
        units = {u.address: u for u in station.units}
        for unit_address, network in tables.local.items():
            unit = units.get(unit_address)
            if unit is None or unit.network != network:
                raise CommandError(
                    f"station {station.name!r}: local network table names unit "
                    f"{unit_address:#04x} on network {network}, which it does not have"
                )
        local = set(tables.local.values())
        for dest, (via, node) in tables.relay.items():
            if dest in local:
                raise CommandError(
                    f"station {station.name!r}: network {dest} is local; it takes no relay entry"
                )
            if via not in local:
                raise CommandError(
                    f"station {station.name!r}: relay to network {dest} via network {via}, "
                    "which is not in its local network table"
                )
            if not 1 <= node <= 254:
                raise CommandError(f"station {station.name!r}: relay node {node} out of range")

    def station(self, name: str) -> Station:
        for station in self.stations:
            if station.name == name:
                return station
        raise KeyError(name)

    # ---- the way in -----------------------------------------------------------------------

    def receive(self, unit: Unit, frame: bytes, host: str, port: int) -> list[Datagram]:
        """A datagram from ``host``:``port`` reached ``unit``: the datagrams to send."""
        station = self._owner(unit)
        out: list[Datagram] = []
        if station.state is StationState.DOWN:
            self.counts["dropped:down"] += 1
            return out
        try:
            header = Header.decode(frame)
        except (DecodeError, FrameError):
            self.counts["dropped:malformed"] += 1
            return out
        if unit.ethernet is not None and not header.is_response:
            unit.ethernet.received(frame, (host, port))
        self.trace.append(Hop(unit.network, bytes(frame)))
        self._at(station, unit.network, frame, header, out)
        return out

    def _owner(self, unit: Unit) -> Station:
        station = self._nodes.get((unit.network, unit.node))
        if station is None or unit not in station.units:
            raise CommandError(f"unit {unit.address:#04x} is not part of this plant")
        return station

    # ---- routing --------------------------------------------------------------------------

    def _at(
        self, station: Station, arrived: int, frame: bytes, header: Header, out: list[Datagram]
    ) -> None:
        """``frame`` reached ``station`` on network ``arrived``: answer, forward or refuse."""
        dest = header.destination
        dna = dest.network or arrived
        local = station.networks()
        if dna in local:
            node = station.unit_on(dna)
            assert node is not None
            if dest.node == node.node or (dest.node == 0 and dna == arrived):
                self._execute(station, arrived, frame, header, out)
                return
            if dna == arrived:  # for another node of the network it came on: not ours
                self.counts["dropped:not-ours"] += 1
                return
            if station.tables is None:
                self._refuse(station, arrived, frame, header, NO_ROUTING_TABLES, out)
                return
            self._forward(station, arrived, dna, dest.node, frame, header, out)
            return
        tables = station.tables
        if tables is None:
            self._refuse(station, arrived, frame, header, NO_ROUTING_TABLES, out)
            return
        hop = tables.relay.get(dna)
        if hop is None:
            self._refuse(station, arrived, frame, header, NO_ROUTE, out)
            return
        self._forward(station, arrived, hop[0], hop[1], frame, header, out)

    def _forward(
        self,
        station: Station,
        arrived: int,
        network: int,
        node: int,
        frame: bytes,
        header: Header,
        out: list[Datagram],
    ) -> None:
        """Cross ``station`` towards ``node`` on ``network`` (GCT -1)."""
        if header.gct == 0:
            self._refuse(station, arrived, frame, header, TOO_MANY_RELAYS, out)
            return
        limits = NETWORK_LIMITS[self.networks[network].type]
        if header.is_response:
            if len(frame) - 14 > limits.max_response_data_bytes:
                self.counts["dropped:response-too-long"] += 1
                return
        elif len(frame) - 12 > limits.max_parameter_bytes:
            self._refuse(station, arrived, frame, header, COMMAND_TOO_LONG, out)
            return
        frame = frame[:2] + bytes((header.gct - 1,)) + frame[3:]
        header = Header.decode(frame)
        self.counts["relayed"] += 1
        self._put(station, network, node, frame, header, out, relay_from=arrived)

    def _put(
        self,
        station: Station,
        network: int,
        node: int,
        frame: bytes,
        header: Header,
        out: list[Datagram],
        *,
        relay_from: int | None,
    ) -> None:
        """Send ``frame`` from ``station`` on ``network`` to ``node``."""
        unit = station.unit_on(network)
        assert unit is not None
        target = self._nodes.get((network, node))
        if target is None:
            peer = unit.peer_of(node)
            if peer is not None:
                self.trace.append(Hop(network, frame))
                out.append(Datagram(unit, frame, *peer))
                return
            self._no_answer(station, relay_from, frame, header, NO_RESPONSE, out)
            return
        if target.state is not StationState.UP:
            code = NODE_BUSY if target.state is StationState.BUSY else NO_RESPONSE
            self._no_answer(station, relay_from, frame, header, code, out)
            return
        self.trace.append(Hop(network, frame))
        self._at(target, network, frame, header, out)

    def _no_answer(
        self,
        station: Station,
        relay_from: int | None,
        frame: bytes,
        header: Header,
        code: int,
        out: list[Datagram],
    ) -> None:
        if relay_from is None or header.is_response:
            self.counts[f"dropped:{code:04x}"] += 1
            return
        self._refuse(station, relay_from, frame, header, code, out)

    def _refuse(
        self,
        station: Station,
        arrived: int,
        frame: bytes,
        header: Header,
        code: int,
        out: list[Datagram],
    ) -> None:
        """Answer a relay error from ``station`` (its address on ``arrived`` in the trailer)."""
        if header.is_response or not header.response_required:
            self.counts[f"dropped:{code:04x}"] += 1
            return
        self.counts[f"refused:{code:04x}"] += 1
        unit = station.unit_on(arrived)
        assert unit is not None
        me = FinsAddress(arrived, unit.node, 0)
        reply = ResponseFrame(
            Header(header.source, me, sid=header.sid, icf=0xC0, rsv=header.rsv, gct=RESPONSE_GCT),
            frame[10] if len(frame) > 10 else 0,
            frame[11] if len(frame) > 11 else 0,
            EndCode(RELAY_ERROR_FLAG | code),
            b"",
            (arrived, unit.node),
        ).encode()
        self._reply(station, arrived, reply, out)

    def _execute(
        self, station: Station, arrived: int, frame: bytes, header: Header, out: list[Datagram]
    ) -> None:
        """``frame`` is for ``station``'s CPU Unit: a command is answered, a response kept."""
        if header.is_response:
            self.counts["dropped:response-for-a-plc"] += 1
            return
        try:
            command = CommandFrame.decode(frame)
        except (DecodeError, FrameError):
            self.counts["dropped:malformed"] += 1
            return
        self.counts["delivered"] += 1
        response = station.plc.answer(command)
        if response is None:
            return
        unit = station.unit_on(header.destination.network or arrived)
        assert unit is not None
        dest = header.destination
        reply = ResponseFrame(
            Header(
                header.source,
                FinsAddress(dest.network, unit.node, dest.unit),
                sid=header.sid,
                icf=0xC0,
                rsv=header.rsv,
                gct=RESPONSE_GCT,
            ),
            response.mrc,
            response.src,
            response.end_code,
            response.data,
        )
        encoded = reply.encode()
        back = self._back_network(station, arrived, header.source.network)
        limit = NETWORK_LIMITS[self.networks[back].type].max_response_data_bytes
        if len(response.data) > limit:
            encoded = ResponseFrame(
                reply.header, reply.mrc, reply.src, EndCode(RESPONSE_TOO_LONG)
            ).encode()
        self._reply(station, arrived, encoded, out)

    def _back_network(self, station: Station, arrived: int, sna: int) -> int:
        """The network a response to ``sna`` leaves ``station`` on."""
        if sna == 0 or sna in station.networks():
            return arrived if sna == 0 else sna
        tables = station.tables
        hop = None if tables is None else tables.relay.get(sna)
        return arrived if hop is None else hop[0]

    def _reply(self, station: Station, arrived: int, frame: bytes, out: list[Datagram]) -> None:
        """Route a response ``station`` made for a command that arrived on ``arrived``."""
        header = Header.decode(frame)
        dest = header.destination
        dna = dest.network or arrived
        if dna in station.networks():
            self._put(station, dna, dest.node, frame, header, out, relay_from=None)
            return
        tables = station.tables
        hop = None if tables is None else tables.relay.get(dna)
        if hop is None:
            self.counts["dropped:no-route-back"] += 1
            return
        self._put(station, hop[0], hop[1], frame, header, out, relay_from=None)
