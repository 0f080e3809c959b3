"""An Ethernet Unit's FINS address conversion: which FINS node an IP address is, and where a
FINS message (a reply above all) to a node is sent.

A CS/CJ Ethernet Unit keeps an internal table: for each remote FINS node (1..254) an IP
address and a UDP port. It is made when the unit starts, by one of four methods
(:class:`AddressConversion`, the unit's setup), and the dynamic ones change it as FINS
commands arrive:

========================  ===================================================  ===========
method                    the table at start                                   learns
========================  ===================================================  ===========
automatic, dynamic        node ``n``: network part of the unit's IP + ``n``,   every node
                          the FINS UDP port (9600 unless set)
automatic, static         the same                                             nothing
IP address table          a node in the table: its IP, the FINS UDP port;      nodes not
                          any other: 0.0.0.0 (nowhere)                         in the table
combined                  a node in the table: its IP, the FINS UDP port;      nodes not
                          any other: as automatic                              in the table
========================  ===================================================  ===========

"Learns" means: a command from source node ``SA1`` arriving from ``ip:port`` sets the
entry of ``SA1`` to ``ip:port`` (unless dynamic changes are prohibited,
``change_dynamically=False``, unit version 1.3 and later). So a unit with dynamic conversion
replies to the port the command came from (the last one seen for that node: two sockets
sharing a source node steal each other's replies), while static conversion and an IP
address table reply to the FINS port (9600) of the derived or listed address: a client that
does not bind that port gets no reply at all, and a client whose address is not the one
derived from its source node sends its replies to another host.

With automatic conversion the unit's own FINS node is its IP address's host number
(``192.168.250.1`` with mask ``255.255.255.0``: node 1); a node set otherwise is a setting
error (the unit's ERH indicator flashes: :class:`ValueError` here). With a table or the
combined method the node is set freely.

Only the standard library and the protocol's header layout are used: the simulator's UDP
server (:class:`~aiofins.simulator.udp.UdpServer`, ``ethernet=``) and other models of a plant
(routing, a diagnostic of a client's settings) share it.
"""

from __future__ import annotations

import enum
import ipaddress
from collections.abc import Mapping

from ..protocol.frames import DA1, SA1
from ..protocol.header import HEADER_SIZE

__all__ = ["FINS_UDP_PORT", "AddressConversion", "EthernetUnit", "node_of"]

#: The FINS UDP port an Ethernet Unit uses unless set otherwise.
FINS_UDP_PORT = 9600

Address = tuple[str, int]


class AddressConversion(enum.Enum):
    """How an Ethernet Unit pairs FINS nodes with IP addresses (its setup)."""

    #: Node ``n`` is the network part of the unit's IP + ``n``, port 9600; changed by every
    #: command received (the reply goes to where the command came from).
    AUTOMATIC_DYNAMIC = "automatic-dynamic"
    #: The same at start, never changed (the reply goes to port 9600 of the derived address).
    AUTOMATIC_STATIC = "automatic-static"
    #: Listed nodes: the table's IP, port 9600, never changed; others: nowhere until a
    #: command from them is received (then as dynamic).
    IP_ADDRESS_TABLE = "table"
    #: Listed nodes as the table; others as automatic, dynamic.
    COMBINED = "combined"


def node_of(ip: str, subnet_mask: str = "255.255.255.0") -> int:
    """The FINS node of ``ip`` under automatic conversion: its host number under
    ``subnet_mask`` (the last octet with a /24 mask)."""
    address = int(ipaddress.IPv4Address(ip))
    mask = int(ipaddress.IPv4Address(subnet_mask))
    return address & ~mask & 0xFFFFFFFF


class EthernetUnit:
    """The address conversion of one Ethernet Unit at ``ip`` (see the module's docstring).

    ``ip_table`` maps FINS nodes to IP addresses (the IP address table and combined
    methods); ``fins_port`` is the unit's FINS UDP port; ``node`` its own FINS node (with
    automatic conversion: the IP's host number, which is also the default).
    """

    def __init__(
        self,
        ip: str,
        *,
        subnet_mask: str = "255.255.255.0",
        conversion: AddressConversion = AddressConversion.AUTOMATIC_DYNAMIC,
        ip_table: Mapping[int, str] | None = None,
        fins_port: int = FINS_UDP_PORT,
        change_dynamically: bool = True,
        node: int | None = None,
    ) -> None:
        self.ip = str(ipaddress.IPv4Address(ip))
        self.subnet_mask = str(ipaddress.IPv4Address(subnet_mask))
        self.conversion = AddressConversion(conversion)
        if not 1 <= fins_port <= 65535:
            raise ValueError(f"FINS UDP port {fins_port} out of range 1..65535")
        self.fins_port = fins_port
        self.change_dynamically = change_dynamically
        table = dict(ip_table or {})
        for n, address in table.items():
            if not 1 <= n <= 254:
                raise ValueError(f"IP address table: node {n} out of range 1..254")
            table[n] = str(ipaddress.IPv4Address(address))
        self.ip_table: dict[int, str] = table
        host = node_of(self.ip, self.subnet_mask)
        automatic = self.conversion in (
            AddressConversion.AUTOMATIC_DYNAMIC,
            AddressConversion.AUTOMATIC_STATIC,
        )
        if automatic:
            if not 1 <= host <= 254:
                raise ValueError(
                    f"automatic address conversion: {self.ip} (mask {self.subnet_mask}) has "
                    f"host number {host}, not a FINS node (1..254)"
                )
            if node is not None and node != host:
                raise ValueError(
                    f"automatic address conversion: the FINS node must be the IP address's "
                    f"host number ({host} for {self.ip}), not {node} (setting error)"
                )
            node = host
        elif node is None:
            raise ValueError(f"{self.conversion.value} address conversion: name the unit's node")
        if not 1 <= node <= 254:
            raise ValueError(f"FINS node {node} out of range 1..254")
        #: The unit's own FINS node.
        self.node = node
        #: Replies that had nowhere to go (a node at 0.0.0.0 in the internal table).
        self.unaddressed = 0
        self._network = int(ipaddress.IPv4Address(self.ip)) & int(
            ipaddress.IPv4Address(self.subnet_mask)
        )
        self.table: dict[int, Address | None] = {}
        self.restart()

    def __repr__(self) -> str:
        return f"<EthernetUnit {self.ip} node {self.node} {self.conversion.value}>"

    # -- the internal table -------------------------------------------------------------------

    def restart(self) -> None:
        """Make the internal table as the unit does when it starts (what it learnt is gone)."""
        self.table = {n: self._initial(n) for n in range(1, 255)}

    def _initial(self, node: int) -> Address | None:
        listed = self.ip_table.get(node)
        if listed is not None and self.conversion in (
            AddressConversion.IP_ADDRESS_TABLE,
            AddressConversion.COMBINED,
        ):
            return listed, self.fins_port
        if self.conversion is AddressConversion.IP_ADDRESS_TABLE:
            return None  # 0.0.0.0: nowhere, until a command from it is received
        return self.automatic_address(node)

    def automatic_address(self, node: int) -> Address:
        """Where automatic conversion sends node ``node``'s messages: the network part of the
        unit's IP + ``node``, at the FINS port."""
        ip = ipaddress.IPv4Address(self._network | node)
        return str(ip), self.fins_port

    def learns(self, node: int) -> bool:
        """Whether a command from ``node`` changes its entry (see the module's docstring)."""
        if not self.change_dynamically or not 1 <= node <= 254:
            return False
        conversion = self.conversion
        if conversion is AddressConversion.AUTOMATIC_DYNAMIC:
            return True
        if conversion is AddressConversion.AUTOMATIC_STATIC:
            return False
        return node not in self.ip_table

    # -- messages ----------------------------------------------------------------------------

    def received(self, frame: bytes, source: Address) -> int | None:
        """A FINS command ``frame`` arrived from ``source`` (IP, UDP port): the entry of its
        source node (SA1) learns that address if it may. Returns SA1 (``None``: no header)."""
        if len(frame) < HEADER_SIZE:
            return None
        node = frame[SA1]
        if self.learns(node):
            self.table[node] = (source[0], int(source[1]))
        return node

    def address_of(self, node: int) -> Address | None:
        """Where a message to FINS node ``node`` goes (``None``: nowhere, 0.0.0.0)."""
        return self.table.get(node)

    def destination(self, frame: bytes) -> Address | None:
        """Where the unit sends FINS message ``frame`` (a reply: to its DA1, the command's
        SA1). ``None`` (counted in :attr:`unaddressed`) if the table has no address for it."""
        if len(frame) < HEADER_SIZE:
            self.unaddressed += 1
            return None
        to = self.table.get(frame[DA1])
        if to is None:
            self.unaddressed += 1
        return to
