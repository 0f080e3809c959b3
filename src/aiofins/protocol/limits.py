"""Per-network and per-command size limits, as data.

A command that crosses several networks is bound by the smallest limit along its route
(manual 5-2-2: "If more than one network is passed through to read or write data, the value
for the network with the smallest limit will apply"). :func:`limits_for` computes that
minimum; :class:`RouteLimits` fields can be overridden with :func:`dataclasses.replace` for
units whose limits differ (e.g. an older Ethernet unit, or a test that wants tiny chunks).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, fields, replace
from enum import Enum

from . import hostlink
from .commands.file import FILE_READ_OVERHEAD
from .commands.memory import MAX_MULTIPLE_READ_ELEMENTS, MAX_READ_ELEMENTS, MAX_WRITE_ELEMENTS
from .commands.parameter import MAX_PARAMETER_WORDS
from .commands.program import MAX_PROGRAM_READ_BYTES, MAX_PROGRAM_WRITE_BYTES
from .errors import CommandError
from .header import MAX_FRAME_SIZE, MAX_PARAMETER_SIZE, MAX_RESPONSE_DATA_SIZE

#: Largest FINS frame on Ethernet and Controller Link: 10-byte header + 2-byte command code +
#: 2,000 parameter bytes (W421 §7; wire-format §1.2 and §7).
MAX_FRAME = MAX_FRAME_SIZE

#: Host Link FINS frames (W342 §3-5; wire-format §4): whole command line in characters.
HOST_LINK_MAX_COMMAND_CHARS = hostlink.MAX_COMMAND_CHARS
#: Whole response line in characters.
HOST_LINK_MAX_RESPONSE_CHARS = hostlink.MAX_RESPONSE_CHARS
#: Parameter bytes after the command code of one Host Link command (1,080 characters).
HOST_LINK_MAX_PARAMETER_BYTES = hostlink.MAX_PARAMETER_BYTES
#: Data bytes after the end code of one Host Link response (1,076 characters).
HOST_LINK_MAX_RESPONSE_DATA_BYTES = hostlink.MAX_RESPONSE_DATA_BYTES


class NetworkType(Enum):
    """A network a FINS command can travel over (manual 5-2-2 and 5-3-5 name these)."""

    #: FINS/UDP or FINS/TCP over Ethernet (the default: up to 990 words a frame).
    ETHERNET = "ethernet"
    #: Controller Link.
    CONTROLLER_LINK = "controller_link"
    #: SYSMAC LINK.
    SYSMAC_LINK = "sysmac_link"
    #: DeviceNet.
    DEVICENET = "devicenet"
    #: SYSMAC WAY (Host Link through a serial communications unit).
    SYSWAY = "sysway"
    #: Host Link on the CPU Unit's own serial port (``serial://`` URLs).
    HOST_LINK = "host_link"


@dataclass(frozen=True, slots=True)
class RouteLimits:
    """How much one command may carry on a route.

    Counts are in the unit the command counts in: words for 0101/0102/0201/0202, elements
    for 0104, bytes for 0306/0307 and for the frame sizes.
    """

    #: 0101 MEMORY AREA READ, words per command.
    memory_read_words: int
    #: 0102 MEMORY AREA WRITE, words per command.
    memory_write_words: int
    #: 0104 MULTIPLE MEMORY AREA READ, elements per command.
    multiple_read_elements: int
    #: 0201 PARAMETER AREA READ, words per command.
    parameter_read_words: int = MAX_PARAMETER_WORDS
    #: 0202 PARAMETER AREA WRITE, words per command.
    parameter_write_words: int = MAX_PARAMETER_WORDS
    #: 0306 PROGRAM AREA READ, bytes per command (a multiple of 4).
    program_read_bytes: int = MAX_PROGRAM_READ_BYTES
    #: 0307 PROGRAM AREA WRITE, bytes per command (a multiple of 4).
    program_write_bytes: int = MAX_PROGRAM_WRITE_BYTES
    #: Parameter bytes after the command code of one command frame.
    max_parameter_bytes: int = MAX_PARAMETER_SIZE
    #: Data bytes after the end code of one response frame.
    max_response_data_bytes: int = MAX_RESPONSE_DATA_SIZE

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not isinstance(value, int) or value < 1:
                raise CommandError(
                    f"route limit {f.name} must be a positive integer, not {value!r}"
                )

    def tightest(self, other: RouteLimits) -> RouteLimits:
        """The field-by-field minimum of two limits (a route through both networks)."""
        return RouteLimits(
            **{f.name: min(getattr(self, f.name), getattr(other, f.name)) for f in fields(self)}
        )


# Manual 5-2-2 "Number of Elements for I/O MEMORY AREA READ (0101) and I/O MEMORY AREA WRITE
# (0102)": 999/997 words on Ethernet and Controller Link, 269/267 on SYSWAY, SYSMAC LINK and
# DeviceNet. Manual 5-3-5 (0104) Comments: 167 elements on Controller Link/Ethernet, 89 on
# SYSMAC LINK/DeviceNet. Manual 5-3-7/5-3-8: 498 words per 0201/0202 on every network.
# Manual 5-3-10/5-3-11: 992 bytes per 0306, 996 bytes per 0307.
_LARGE_FRAME = RouteLimits(
    memory_read_words=MAX_READ_ELEMENTS,
    memory_write_words=MAX_WRITE_ELEMENTS,
    multiple_read_elements=MAX_MULTIPLE_READ_ELEMENTS,
)
# SYSMAC LINK, DeviceNet (and SYSWAY, Host Link) carry 540 parameter bytes after the command
# code and 538 response data bytes (W227 p.6; wire-format §7): 269 words = 538 bytes read,
# 267 words = 534 + 6 bytes written. The 498-word and 992/996-byte program limits do not fit
# such a frame, so they are cut to what does: 0201 answers 6 bytes of header + 2n data
# (n <= 266), 0202 sends 6 + 2n (n <= 267); 0306 answers 8 + n (n <= 530, a multiple of 4:
# 528), 0307 sends 8 + n (n <= 532). These four are inferred from frame arithmetic (the
# manual states no per-network value for them); override them if a unit documents more.
_SMALL_FRAME = RouteLimits(
    memory_read_words=269,
    memory_write_words=267,
    multiple_read_elements=89,
    parameter_read_words=266,
    parameter_write_words=267,
    program_read_bytes=528,
    program_write_bytes=532,
    max_parameter_bytes=HOST_LINK_MAX_PARAMETER_BYTES,
    max_response_data_bytes=HOST_LINK_MAX_RESPONSE_DATA_BYTES,
)

#: The limits of each network type on its own.
NETWORK_LIMITS: dict[NetworkType, RouteLimits] = {
    NetworkType.ETHERNET: _LARGE_FRAME,
    NetworkType.CONTROLLER_LINK: _LARGE_FRAME,
    NetworkType.SYSMAC_LINK: _SMALL_FRAME,
    NetworkType.DEVICENET: _SMALL_FRAME,
    # SYSWAY: 269/267 per manual 5-2-2; 0104 is not listed for it in 5-3-5, we assume the
    # 540-byte networks' 89.
    NetworkType.SYSWAY: _SMALL_FRAME,
    # Host Link: 269/267 follow from its 540/538-byte limit (W342 §3-5, wire-format §4.2);
    # 0104 not listed in 5-3-5, we assume 89 like the other 540-byte networks.
    NetworkType.HOST_LINK: _SMALL_FRAME,
}


def limits_for(*network_types: NetworkType, **overrides: int) -> RouteLimits:
    """The limits of a route through ``network_types``: the smallest of each along the way.

    With no network type the route is a single Ethernet hop. Keyword arguments override single
    fields of the result, e.g. ``limits_for(NetworkType.ETHERNET, memory_read_words=500)``.
    """
    result = NETWORK_LIMITS[NetworkType.ETHERNET]
    for network in network_types:
        result = result.tightest(NETWORK_LIMITS[NetworkType(network)])
    if overrides:
        names = {f.name for f in fields(RouteLimits)}
        unknown = sorted(set(overrides) - names)
        if unknown:
            raise CommandError(f"unknown route limit(s): {', '.join(unknown)}")
        result = replace(result, **overrides)
    return result


#: Network type names in route maps (``?routes=3:sysmac_link``) and plant files; ``serial``
#: is Host Link.
NETWORK_NAMES: dict[str, NetworkType] = {
    **{t.value: t for t in NetworkType},
    "serial": NetworkType.HOST_LINK,
}

#: What a route map entry may be: limits, a network type (or its name), or several of them
#: (the networks the route crosses).
RouteSpec = (
    RouteLimits | NetworkType | str | tuple[NetworkType | str, ...] | list[NetworkType | str]
)


def _network_type(value: object) -> NetworkType:
    if isinstance(value, NetworkType):
        return value
    name = str(value).strip().lower().replace("-", "_").replace(" ", "_")
    if name not in NETWORK_NAMES:
        raise CommandError(
            f"unknown network type {value!r}; known: {', '.join(sorted(NETWORK_NAMES))}"
        )
    return NETWORK_NAMES[name]


def route_limits(spec: RouteSpec) -> RouteLimits:
    """The limits of one route map entry (see :data:`RouteSpec`)."""
    if isinstance(spec, RouteLimits):
        return spec
    if isinstance(spec, str):
        return limits_for(*(_network_type(p) for p in spec.split("+")))
    if isinstance(spec, NetworkType):
        return limits_for(spec)
    if isinstance(spec, (tuple, list)):
        return limits_for(*(_network_type(p) for p in spec))
    raise CommandError(
        f"a route is RouteLimits, a network type or a sequence of them; got {spec!r}"
    )


def parse_routes(value: object) -> dict[int, RouteLimits]:
    """A route map: destination network (1..127) -> :class:`RouteLimits`.

    From a mapping (``{3: NetworkType.SYSMAC_LINK, 2: "controller_link"}``) or from text as
    in a URL (``"3:sysmac_link,2:controller_link"``; ``+`` joins the networks of one route,
    ``3:controller_link+sysmac_link``). Each route's limits are the smallest of its networks
    and of the first hop's Ethernet (:func:`limits_for`).
    """
    items: list[tuple[object, object]] = []
    if isinstance(value, str):
        for piece in filter(None, (p.strip() for p in value.split(","))):
            number_text, sep, text = piece.partition(":")
            if not sep or not text:
                raise CommandError(f"route {piece!r}: write NETWORK:TYPE, e.g. 3:sysmac_link")
            items.append((number_text, text))
    elif isinstance(value, Mapping):
        items = list(value.items())
    else:
        raise CommandError(
            f"routes must be a mapping or text such as '3:sysmac_link'; got {value!r}"
        )
    routes: dict[int, RouteLimits] = {}
    for network, spec in items:
        try:
            number = int(str(network)) if not isinstance(network, bool) else -1
        except ValueError:
            number = -1
        if not 1 <= number <= 127:
            raise CommandError(f"route network {network!r} must be 1..127")
        if number in routes:
            raise CommandError(f"route network {number} given twice")
        routes[number] = route_limits(spec)  # type: ignore[arg-type]  # checked there
    return routes


def routes_text(value: object) -> str:
    """One spelling of a URL's ``?routes=`` (sorted by network; types as named)."""
    if not isinstance(value, str):
        raise CommandError(f"routes must be text such as '3:sysmac_link'; got {value!r}")
    parse_routes(value)  # checked
    pieces = []
    for piece in filter(None, (p.strip() for p in value.split(","))):
        network, _, spec = piece.partition(":")
        kinds = "+".join(_network_type(p).value for p in spec.split("+"))
        pieces.append((int(network), f"{int(network)}:{kinds}"))
    return ",".join(text for _, text in sorted(pieces))


def _count(params: bytes, at: int) -> int:
    return int.from_bytes(params[at : at + 2], "big") & 0x7FFF if len(params) >= at + 2 else 0


#: Per command code: (the limit's field name, what the command carries of it, its unit).
_COMMAND_SIZES: dict[int, tuple[str, Callable[[bytes], int], str]] = {
    0x0101: ("memory_read_words", lambda p: _count(p, 4), "words"),
    0x0102: ("memory_write_words", lambda p: _count(p, 4), "words"),
    0x0104: ("multiple_read_elements", lambda p: len(p) // 4, "elements"),
    0x0201: ("parameter_read_words", lambda p: _count(p, 4), "words"),
    0x0202: ("parameter_write_words", lambda p: _count(p, 4), "words"),
    0x0306: ("program_read_bytes", lambda p: _count(p, 6), "bytes"),
    0x0307: ("program_write_bytes", lambda p: len(p) - 8, "bytes"),
}


#: Per command code: the response data bytes its parameters ask for (2202: the file bytes
#: after 10 bytes of capacity, position and length).
_RESPONSE_SIZES: dict[int, Callable[[bytes], int]] = {
    0x2202: lambda p: FILE_READ_OVERHEAD + int.from_bytes(p[18:20], "big"),
}


def check_command(limits: RouteLimits, mrc: int, src: int, params: bytes) -> None:
    """Refuse a command that the route does not carry, with :class:`CommandError` naming
    the limit (before anything is sent): its parameter bytes, per command its words,
    elements or bytes (0101, 0102, 0104, 0201, 0202, 0306, 0307), and the response a
    2202 SINGLE FILE READ asks for."""
    code = (mrc << 8) | src
    response = _RESPONSE_SIZES.get(code)
    if response is not None and len(params) >= 20:
        asked = response(params)
        if asked > limits.max_response_data_bytes:
            raise CommandError(
                f"command {code:04X} asks for a response of {asked} data bytes; this route "
                f"carries {limits.max_response_data_bytes} (max_response_data_bytes)"
            )
    if len(params) > limits.max_parameter_bytes:
        raise CommandError(
            f"command {mrc:02X}{src:02X} carries {len(params)} parameter bytes; this route "
            f"carries {limits.max_parameter_bytes}"
        )
    size = _COMMAND_SIZES.get(code)
    if size is None:
        return
    name, measure, unit = size
    amount, limit = measure(params), getattr(limits, name)
    if amount > limit:
        raise CommandError(
            f"command {mrc:02X}{src:02X} carries {amount} {unit}; this route carries "
            f"{limit} ({name}, manual 5-2-2/5-3-5): split it or check the route map"
        )
