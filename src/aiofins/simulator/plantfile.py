"""A plant described in TOML (``aiofins simulate --plant plant.toml``).

::

    [[network]]
    number = 1
    type = "ethernet"          # ethernet, controller_link, sysmac_link, devicenet, serial

    [[plc]]
    name = "gateway"
    mode = "run"               # run, monitor, program
    memory = { D0 = [1, 2] }   # words (or 0/1 bits) stored before serving
    state = "up"               # up, busy (relays to it get 0204), down (0205)
    routing = true             # routing tables (default: true when it has relay entries or
                               # more than one unit); local network table from its units
    relay = [[3, 2, 20]]       # relay network table: [destination network, relay network,
                               #                       relay node], one entry per network

    [[plc.unit]]
    address = 0x10             # unit address (CPU Bus Unit 0 = 0x10)
    network = 1
    node = 10
    udp = "127.0.0.1:9600"     # Ethernet units only: where it listens (port 0: any)
    conversion = "dynamic"     # dynamic, static, table, combined
    ip_table = { 1 = "192.168.250.1" }   # node -> IP address, for conversion = "table"

Every mistake is a :class:`~aiofins.protocol.errors.CommandError` naming the entry.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping
from typing import Any

from ..protocol.errors import CommandError
from ..protocol.limits import NetworkType
from .ethernet import AddressConversion
from .plant import (
    Network,
    Plant,
    RoutingTables,
    Station,
    StationState,
    Unit,
)
from .plc import VirtualPLC
from .state import Mode

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib  # type: ignore[import-not-found, unused-ignore]

#: Network type names in a plant file (``serial`` is Host Link).
NETWORK_TYPES = {
    "ethernet": NetworkType.ETHERNET,
    "controller_link": NetworkType.CONTROLLER_LINK,
    "sysmac_link": NetworkType.SYSMAC_LINK,
    "devicenet": NetworkType.DEVICENET,
    "serial": NetworkType.HOST_LINK,
}


#: Address conversion names in a plant file.
CONVERSIONS = {
    "dynamic": AddressConversion.AUTOMATIC_DYNAMIC,
    "static": AddressConversion.AUTOMATIC_STATIC,
    "table": AddressConversion.IP_ADDRESS_TABLE,
    "combined": AddressConversion.COMBINED,
}


def load_plant(path: str) -> Plant:
    """Read a plant file."""
    try:
        with open(path, "rb") as f:
            data = tomllib.load(f)
    except tomllib.TOMLDecodeError as exc:
        raise CommandError(f"{path}: {exc}") from None
    try:
        return plant_from(data)
    except CommandError as exc:
        raise CommandError(f"{path}: {exc}") from None


def plant_from(data: Mapping[str, Any]) -> Plant:
    """A plant from a parsed plant file."""
    _keys("plant", data, {"network", "plc"})
    networks = [_network(i, n) for i, n in enumerate(_list(data, "network", "plant"))]
    stations = [_station(i, p) for i, p in enumerate(_list(data, "plc", "plant"))]
    if not networks or not stations:
        raise CommandError("a plant needs at least one [[network]] and one [[plc]]")
    return Plant(networks, stations)


def _list(data: Mapping[str, Any], key: str, where: str) -> list[Any]:
    value = data.get(key, [])
    if not isinstance(value, list):
        raise CommandError(f"{where}: {key} must be a list ([[{key}]] tables)")
    return value


def _keys(where: str, data: Mapping[str, Any], known: set[str]) -> None:
    if not isinstance(data, Mapping):
        raise CommandError(f"{where}: expected a table")
    unknown = sorted(set(data) - known)
    if unknown:
        raise CommandError(
            f"{where}: unknown key(s) {', '.join(unknown)}; known: {', '.join(sorted(known))}"
        )


def _int(where: str, value: object, low: int, high: int) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or not low <= value <= high:
        raise CommandError(f"{where}: expected an integer {low}..{high}, got {value!r}")
    return value


def _choice(where: str, value: object, choices: Mapping[str, Any] | list[str]) -> str:
    if not isinstance(value, str) or value not in choices:
        raise CommandError(f"{where}: expected one of {', '.join(choices)}, got {value!r}")
    return value


def _network(index: int, data: Mapping[str, Any]) -> Network:
    where = f"network #{index + 1}"
    _keys(where, data, {"number", "type"})
    number = _int(f"{where} number", data.get("number"), 1, 127)
    kind = _choice(f"{where} type", data.get("type"), NETWORK_TYPES)
    return Network(number, NETWORK_TYPES[kind])


def _station(index: int, data: Mapping[str, Any]) -> Station:
    name = data.get("name", f"plc{index + 1}") if isinstance(data, Mapping) else ""
    where = f"plc {name!r}"
    _keys(where, data, {"name", "mode", "memory", "state", "routing", "relay", "unit"})
    units = [_unit(f"{where} unit #{i + 1}", u) for i, u in enumerate(_list(data, "unit", where))]
    if not units:
        raise CommandError(f"{where}: needs at least one [[plc.unit]]")
    mode = _choice(f"{where} mode", data.get("mode", "run"), ["run", "monitor", "program"])
    state = _choice(f"{where} state", data.get("state", "up"), [s.value for s in StationState])
    relay: dict[int, tuple[int, int]] = {}
    for entry in _list(data, "relay", where):
        if not isinstance(entry, list) or len(entry) != 3:
            raise CommandError(f"{where} relay: each entry is [network, relay network, relay node]")
        dest = _int(f"{where} relay network", entry[0], 1, 127)
        if dest in relay:
            raise CommandError(f"{where} relay: network {dest} listed twice")
        relay[dest] = (
            _int(f"{where} relay network", entry[1], 1, 127),
            _int(f"{where} relay node", entry[2], 1, 254),
        )
    routing = data.get("routing", bool(relay) or len(units) > 1)
    if not isinstance(routing, bool):
        raise CommandError(f"{where} routing: expected true or false")
    if relay and not routing:
        raise CommandError(f"{where}: relay entries need routing = true")
    tables = RoutingTables({u.address: u.network for u in units}, relay) if routing else None
    first = units[0]
    plc = VirtualPLC(network=first.network, node=first.node, mode=Mode[mode.upper()])
    memory = data.get("memory", {})
    if not isinstance(memory, Mapping):
        raise CommandError(f"{where} memory: expected a table of address = [values]")
    for address, values in memory.items():
        if not isinstance(values, list):
            values = [values]
        plc.write(str(address), values)
    return Station(str(name), plc, units, tables, StationState(state))


def _unit(where: str, data: Mapping[str, Any]) -> Unit:
    _keys(where, data, {"address", "network", "node", "udp", "conversion", "ip_table"})
    host: str | None = None
    port = 9600
    udp = data.get("udp")
    if udp is not None:
        if not isinstance(udp, str):
            raise CommandError(f"{where} udp: expected 'HOST:PORT'")
        host, sep, text = udp.rpartition(":")
        if not sep:
            host, text = udp, "9600"
        port = _int(f"{where} udp port", int(text) if text.isdigit() else -1, 0, 65535)
        host = host.strip("[]")
    conversion = _choice(f"{where} conversion", data.get("conversion", "dynamic"), CONVERSIONS)
    table = data.get("ip_table", {})
    if not isinstance(table, Mapping):
        raise CommandError(f"{where} ip_table: expected a table of node = 'IP address'")
    ip_table = {
        _int(f"{where} ip_table node", int(k) if str(k).isdigit() else -1, 1, 254): str(v)
        for k, v in table.items()
    }
    return Unit(
        address=_int(f"{where} address", data.get("address"), 0, 255),
        network=_int(f"{where} network", data.get("network"), 1, 127),
        node=_int(f"{where} node", data.get("node"), 1, 254),
        host=host,
        port=port,
        conversion=CONVERSIONS[conversion],
        ip_table=ip_table,
    )
