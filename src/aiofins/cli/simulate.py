"""``aiofins simulate``: run a virtual PLC on UDP/TCP/serial in the foreground.

Prints one ``listening on URL`` line per endpoint (stdout, flushed), serves until SIGINT or
SIGTERM, then prints the frame and fault counters to stderr and exits 0.
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import anyio

from ..protocol.errors import FinsError
from ..protocol.tcp import DEFAULT_PORT
from ..simulator.faults import DEFAULT_MAX_HELD, Delay, FaultPlan, FaultRule, FrameLog
from ..simulator.runner import Simulator, run_simulator
from ..simulator.serial import SerialSettings
from ..simulator.tcp import DEFAULT_MAX_CONNECTIONS
from . import report

if TYPE_CHECKING:
    from ..simulator.plant import Plant

    SubParsers = argparse._SubParsersAction[argparse.ArgumentParser]
else:
    SubParsers = Any

DEFAULT_HOST = "127.0.0.1"
MODES = ("run", "monitor", "program")


def endpoint(text: str) -> tuple[str, int]:
    """``HOST:PORT``, ``HOST`` (port 9600) or ``[V6]:PORT``."""
    host, sep, port = text.rpartition(":")
    if not sep or (host.count(":") and not host.startswith("[")):
        host, port = text, str(DEFAULT_PORT)
    host = host.strip("[]") or DEFAULT_HOST
    try:
        number = int(port)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not HOST:PORT") from None
    if not 0 <= number <= 0xFFFF:
        raise argparse.ArgumentTypeError(f"port {number} out of range 0..65535")
    return host, number


def at_span(text: str) -> tuple[str, int]:
    """``ADDRESS:WORDS`` (``D0:100``): memory AT-mapped to variables, checked as the PLC's
    areas are (:func:`aiofins.protocol.addresses.parse_span`)."""
    from ..protocol.addresses import parse_span
    from ..protocol.errors import FinsError

    address, sep, words = text.rpartition(":")
    if not sep or not words.isdigit() or int(words) < 1:
        raise argparse.ArgumentTypeError(f"{text!r} is not ADDRESS:WORDS (D0:100)")
    try:
        parse_span(address, int(words))
    except FinsError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return address, int(words)


def model_name(text: str) -> str:
    """A CPU model as CPU UNIT DATA READ carries it: 20 ASCII characters at most."""
    if not text.isascii() or not text.isprintable() or not 0 < len(text) <= 20:
        raise argparse.ArgumentTypeError(f"model {text!r}: 1..20 printable ASCII characters")
    return text


def probability(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a probability") from None
    if not 0.0 <= value <= 1.0:  # NaN fails this too
        raise argparse.ArgumentTypeError(f"probability {text} out of range 0..1")
    return value


def milliseconds(text: str) -> float:
    """A finite duration in milliseconds, 0 or more."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of milliseconds") from None
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"{text} ms: give a finite number of milliseconds >= 0")
    return value


def integer_in(low: int, high: int | None = None) -> Callable[[str], int]:
    """An argparse type: a decimal integer in ``low..high`` (no upper bound: ``None``)."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
        if value < low or (high is not None and value > high):
            span = f"{low}..{high}" if high is not None else f"at least {low}"
            raise argparse.ArgumentTypeError(f"{value} out of range {span}")
        return value

    return parse


def hex_int(text: str) -> int:
    try:
        return int(text, 16)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not hexadecimal") from None


def delay(text: str) -> Delay:
    try:
        return Delay.parse_ms(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def relay_point(text: str) -> tuple[int, int]:
    net, sep, node = text.partition(".")
    if not sep or not net.isdigit() or not node.isdigit():
        raise argparse.ArgumentTypeError(f"relay point {text!r} is not NETWORK.NODE")
    return int(net), int(node)


def command_codes(text: str) -> list[int]:
    return [hex_int(part) for part in text.split(",") if part.strip()]


def register(subparsers: SubParsers) -> None:
    p = subparsers.add_parser(
        "simulate",
        help="run a virtual PLC (FINS/UDP, FINS/TCP, Host Link serial)",
        description="Run a virtual PLC until interrupted. Without --udp/--tcp/--serial it "
        f"serves UDP and TCP on {DEFAULT_HOST}:{DEFAULT_PORT}. Port 0 picks a free port.",
    )
    where = p.add_argument_group("endpoints")
    where.add_argument("--udp", type=endpoint, metavar="HOST:PORT", help="FINS/UDP endpoint")
    where.add_argument("--tcp", type=endpoint, metavar="HOST:PORT", help="FINS/TCP endpoint")
    where.add_argument("--serial", metavar="DEVICE", help="serial device for Host Link FINS")
    where.add_argument(
        "--plant",
        metavar="FILE",
        help="serve a plant of routed networks described in a TOML file instead of one PLC "
        "(see docs/plant-networks.md)",
    )
    where.add_argument(
        "--serial-unit", type=integer_in(0, 31), default=0, metavar="N", help="Host Link unit"
    )
    where.add_argument(
        "--baudrate", type=integer_in(1), default=9600, help="serial speed (default 9600)"
    )
    where.add_argument(
        "--bytesize",
        type=int,
        choices=(7, 8),
        default=7,
        help="serial data bits (default 7: Omron's Host Link factory setting is 7E2)",
    )
    where.add_argument(
        "--parity", choices=("N", "E", "O"), default="E", help="serial parity (default E)"
    )
    where.add_argument(
        "--stopbits",
        type=int,
        choices=(1, 2),
        default=2,
        help="serial stop bits (default 2; a pty takes only 8N1: --bytesize 8 --parity N "
        "--stopbits 1)",
    )
    where.add_argument(
        "--max-connections",
        type=integer_in(1),
        default=DEFAULT_MAX_CONNECTIONS,
        metavar="N",
        help="FINS/TCP connections through the handshake at once "
        f"(default {DEFAULT_MAX_CONNECTIONS})",
    )

    plc = p.add_argument_group("PLC")
    plc.add_argument(
        "--node", type=integer_in(1, 254), default=1, help="FINS node (1-254, default 1)"
    )
    plc.add_argument(
        "--network", type=integer_in(0, 127), default=0, help="FINS network (0-127, default 0)"
    )
    plc.add_argument("--mode", choices=MODES, default="run", help="operating mode")
    plc.add_argument(
        "--model",
        type=model_name,
        default="CJ2M-CPU33",
        help="CPU model CPU UNIT DATA READ (0501) answers (default CJ2M-CPU33); an NJ/NX "
        "model (NJ501-1300) answers FINS only for its AT-mapped memory (--at), else end "
        "code 1101",
    )
    plc.add_argument(
        "--at",
        type=at_span,
        action="append",
        metavar="ADDRESS:WORDS",
        help="memory AT-mapped to variables (NJ/NX; repeatable): D0:100 is D0..D99; "
        "with --at any model answers only there",
    )

    f = p.add_argument_group("faults (probabilities 0..1 per request)")
    f.add_argument("--drop", type=probability, default=0.0, metavar="P", help="drop requests")
    f.add_argument(
        "--drop-response", type=probability, default=0.0, metavar="P", help="drop responses"
    )
    f.add_argument("--delay", type=delay, metavar="MS|MIN-MAX", help="delay every response")
    f.add_argument(
        "--duplicate", type=probability, default=0.0, metavar="P", help="send responses twice"
    )
    f.add_argument(
        "--reorder", type=probability, default=0.0, metavar="P", help="send after the next response"
    )
    f.add_argument(
        "--corrupt", type=probability, default=0.0, metavar="P", help="flip a response byte"
    )
    f.add_argument(
        "--truncate", type=probability, default=0.0, metavar="P", help="cut responses short"
    )
    f.add_argument(
        "--late",
        type=probability,
        default=0.0,
        metavar="P",
        help="answer after --late-after instead",
    )
    f.add_argument(
        "--late-after",
        type=milliseconds,
        default=10000.0,
        metavar="MS",
        help="see --late (default 10000)",
    )
    f.add_argument("--end-code", type=hex_int, metavar="HEX", help="answer this end code")
    f.add_argument(
        "--end-code-probability",
        type=probability,
        default=1.0,
        metavar="P",
        help="how often --end-code is answered (default 1)",
    )
    f.add_argument(
        "--relay",
        type=relay_point,
        default=(0, 0),
        metavar="NET.NODE",
        help="relay point for an end code with bit 15",
    )
    f.add_argument(
        "--flags",
        type=hex_int,
        default=0,
        metavar="40|80|C0",
        help="CPU error flags set in every end code",
    )
    f.add_argument(
        "--commands",
        type=command_codes,
        metavar="HEX[,HEX]",
        help="apply the faults to these command codes only, e.g. 0101,0102",
    )
    f.add_argument(
        "--max-concurrent",
        type=integer_in(1),
        metavar="N",
        help="answer 2604 above N commands in progress",
    )
    f.add_argument(
        "--max-held",
        type=integer_in(1),
        default=DEFAULT_MAX_HELD,
        metavar="N",
        help="most delayed/late answers waiting at once; more are dropped and counted "
        f"(default {DEFAULT_MAX_HELD})",
    )
    f.add_argument(
        "--tcp-refuse",
        type=hex_int,
        metavar="HEX",
        help="refuse every FINS/TCP handshake with this error code, e.g. 25",
    )
    f.add_argument("--seed", type=int, help="random seed (same seed, same faults)")
    f.add_argument("--log", metavar="FILE", help="hex log of every frame ('-' = stderr)")
    p.add_argument(
        "--backend", choices=("asyncio", "trio"), default="asyncio", help="event loop to run on"
    )
    p.set_defaults(func=run)


def build_plan(args: argparse.Namespace) -> FaultPlan:
    rule = FaultRule(
        drop_request=args.drop,
        drop_response=args.drop_response,
        delay=args.delay,
        duplicate=args.duplicate,
        reorder=args.reorder,
        corrupt=args.corrupt,
        truncate=args.truncate,
        late=args.late,
        # only with --late: a rule equal to "no fault" lets the server answer at once
        late_after=args.late_after / 1000.0 if args.late else 0.0,
        end_code=args.end_code,
        end_code_probability=args.end_code_probability,
        relay=args.relay,
        flags=args.flags,
    )
    log = None
    if args.log:
        log = FrameLog(sys.stderr if args.log == "-" else args.log)
    # With --commands the rule applies to those commands only (the rest are answered normally).
    per_command = dict.fromkeys(args.commands, rule) if args.commands else None
    return FaultPlan(
        None if per_command else rule,
        per_command=per_command,
        seed=args.seed,
        max_concurrent=args.max_concurrent,
        tcp_refusal=args.tcp_refuse,
        log=log,
        max_held=args.max_held,
    )


def run(args: argparse.Namespace) -> int:
    """The ``simulate`` handler: exit code 0 after an interrupt, 2 on bad options (most are
    refused by argparse already, as ``aiofins simulate: error: argument ...``)."""
    if args.plant is not None:
        return _run_plant(args)
    try:
        plan = build_plan(args)
    except (ValueError, OSError) as exc:
        print(f"aiofins simulate: {exc}", file=sys.stderr)
        return 2
    try:
        anyio.run(_serve, args, plan, backend=args.backend)
    except KeyboardInterrupt:
        pass
    except Exception as exc:  # cannot listen (port in use, bad host, no such serial device)
        if report("aiofins simulate", exc, (OSError, FinsError)):
            return 1
        if report("aiofins simulate", exc, (ValueError,)):  # a setting a server refused
            return 2
        raise
    finally:
        if plan.log is not None:
            plan.log.close()
    return 0


def _run_plant(args: argparse.Namespace) -> int:
    """``--plant FILE``: every Ethernet unit of the plant on its own UDP endpoint."""
    from ..simulator.plantfile import load_plant

    if args.udp is not None or args.tcp is not None or args.serial is not None:
        print("aiofins simulate: --plant takes its endpoints from the file", file=sys.stderr)
        return 2
    try:
        plant = load_plant(args.plant)
    except (FinsError, OSError) as exc:
        print(f"aiofins simulate: {exc}", file=sys.stderr)
        return 2
    try:
        anyio.run(_serve_plant, plant, backend=args.backend)
    except KeyboardInterrupt:
        pass
    except Exception as exc:  # cannot listen (port in use, bad host)
        if report("aiofins simulate", exc, (OSError, FinsError)):
            return 1
        raise
    return 0


async def _serve_plant(plant: Plant) -> None:
    from ..simulator.plantserver import serve_plant

    async with serve_plant(plant) as server:
        for station in plant.stations:
            where = ", ".join(f"network {u.network} node {u.node}" for u in station.units)
            print(f"PLC {station.name}: {where}", flush=True)
        for station in plant.stations:
            for unit in station.units:
                if unit.host is not None:
                    host = f"[{unit.host}]" if ":" in unit.host else unit.host
                    print(
                        f"listening on udp://{host}:{server.port_of(unit)} "
                        f"(PLC {station.name}, network {unit.network} node {unit.node})",
                        flush=True,
                    )
        try:
            await _wait_for_signal()
        finally:
            counts = " ".join(f"{k}={v}" for k, v in sorted(plant.counts.items()))
            print(f"stopped: {counts or 'no frames'}", file=sys.stderr, flush=True)


def endpoints(
    args: argparse.Namespace,
) -> tuple[tuple[str, int] | None, tuple[str, int] | None]:
    """``(udp, tcp)``: UDP and TCP on 127.0.0.1:9600 when no endpoint is given at all."""
    if args.udp is None and args.tcp is None and args.serial is None:
        return (DEFAULT_HOST, DEFAULT_PORT), (DEFAULT_HOST, DEFAULT_PORT)
    return args.udp, args.tcp


async def _serve(args: argparse.Namespace, plan: FaultPlan) -> None:
    from ..simulator.plc import VirtualPLC
    from ..simulator.state import Mode

    udp, tcp = endpoints(args)
    nj = args.model.strip().upper()[:2] in ("NJ", "NX")
    plc = VirtualPLC(
        network=args.network,
        node=args.node,
        mode=Mode[args.mode.upper()],
        model=args.model,
        at_mapped=args.at if args.at is not None else [] if nj else None,
    )
    settings = SerialSettings(args.baudrate, args.bytesize, args.parity, args.stopbits)
    async with run_simulator(
        plc,
        udp=udp,
        tcp=tcp,
        serial=args.serial,
        faults=plan,
        server_node=args.node,
        max_connections=args.max_connections,
        serial_unit=args.serial_unit,
        serial_settings=settings,
    ) as sim:
        print(
            f"virtual PLC: network {args.network} node {args.node} mode {args.mode.upper()}",
            flush=True,
        )
        for url in sim.urls():
            print(f"listening on {url}", flush=True)
        try:
            await _wait_for_signal()
        finally:
            _report(sim)


async def _wait_for_signal() -> None:
    try:
        with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
            async for _ in signals:
                return
    except NotImplementedError:  # pragma: no cover - Windows: Ctrl-C raises KeyboardInterrupt
        await anyio.sleep_forever()


def _report(sim: Simulator) -> None:
    counts = sim.counters.as_dict()
    if sim.tcp is not None:
        counts["tcp_accept_errors"] = sim.tcp.accept_errors
        counts["tcp_handshake_timeouts"] = sim.tcp.handshake_timeouts
        counts["tcp_pending_evictions"] = sim.tcp.pending_evictions
        counts["tcp_handshake_refusals"] = sim.tcp.handshake_refusals
        counts["tcp_error_notifications"] = sim.tcp.error_notifications
    if sim.serial is not None:
        counts["serial_ignored_lines"] = sim.serial.ignored_lines
    text = " ".join(f"{k}={v}" for k, v in counts.items() if v)
    print(f"stopped: {text or 'no frames'}", file=sys.stderr, flush=True)
