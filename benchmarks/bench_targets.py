"""Every benchmark row of issue #25 in one run: medians of interleaved rounds, with the spread.

Each round runs every case once, one after another (so all see the same machine), and each
row's ratio is taken within the round; the table gives the median ratio over the rounds and
its range (min-max). Cases (the C responder of ../shared/tools/perf answers; word i of its
DM holds i), with ``bench_api.py``'s functions:

* sequential ``plc.read("D100", 1)``, client and responder on one core (``--pin``): against
  the bare uvloop ``DatagramProtocol`` client (≥ 1.0), the bare stock asyncio client (stock
  asyncio ≥ 1.2) and PyPI ``fins`` (synchronous, no checks; ≥ 1.0); ``aiofins.sync``'s
  ``plc.read`` against PyPI ``fins`` (≥ 1.0);
* 50 tasks x ``plc.read`` on one client, client and responder on a core each: against the
  bare uvloop client with 50 in flight (≥ 0.8);
* ``plc.read("D0", 32768)`` and ``plc.read_array("D0", 32768)`` (33 frames, 5 in flight) in
  1-word round trips of the same client (≤ 20);
* the Poller over 100 C responders x 20 tags at 50 ms: missed scans (= 0), CPU per scan
  against ``bench_api.hand_written_daemon`` over the same responders (≤ 1.0);
* once, after the rounds (``--skip poll1000`` leaves it out): the Poller over 1,000 C
  responders at 100 ms: missed scans (= 0), share of one core (≤ 50 %).

    python benchmarks/bench_targets.py [--rounds 5] [--seconds 1] [--pin 0]
        [--skip calls,poll100,poll1000]

Wall clock: read the ratios, and the load average the script prints before and after.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import anyio

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_api import (
    api_sequential,
    api_tasks,
    bare,
    full_dm,
    hand_written_daemon,
    poll,
    responders,
    uvloop_options,
)
from bench_session import free_port, start_responder

import aiofins.sync

UVLOOP = uvloop_options("uvloop")
#: Row name -> one value per round.
SAMPLES: dict[str, list[float]] = {}
#: Row name -> (target text, test of the median).
TARGETS: dict[str, tuple[str, Callable[[float], bool]]] = {}


def sample(
    name: str, value: float, target: str = "", met: Callable[[float], bool] | None = None
) -> None:
    SAMPLES.setdefault(name, []).append(value)
    if met is not None:
        TARGETS[name] = (target, met)


def rate(seconds: float, call: Callable[[], object], batch: int = 100) -> float:
    """Calls per second of ``call`` one after another (after 500 untimed)."""
    for _ in range(500):
        call()
    n = 0
    start = time.perf_counter()
    end = start + seconds
    while True:
        for _ in range(batch):
            call()
        n += batch
        now = time.perf_counter()
        if now >= end:
            return n / (now - start)


def pypi_fins_sequential(port: int, seconds: float) -> float:
    """PyPI ``fins``' UDP client: ``memory_area_read`` of D100, 1 word, and the word decoded
    from its reply (``int.from_bytes``: what a user of it writes)."""
    import fins.udp  # type: ignore[import-untyped]  # PyPI fins has no type hints

    conn = fins.udp.UDPFinsConnection()
    conn.connect("127.0.0.1", port=port, bind_port=0)
    conn.dest_node_add, conn.srce_node_add = 1, 2
    area = fins.udp.FinsPLCMemoryAreas().DATA_MEMORY_WORD
    read = conn.memory_area_read
    start = b"\x00\x64\x00"
    assert int.from_bytes(read(area, start, 1)[-2:], "big") == 100
    try:
        return rate(seconds, lambda: int.from_bytes(read(area, start, 1)[-2:], "big"))
    finally:
        conn.fins_socket.close()


def sync_sequential(port: int, seconds: float) -> float:
    """``aiofins.sync``: ``plc.read("D100", 1)`` run in this thread on a blocking socket."""
    with aiofins.sync.connect(f"udp://127.0.0.1:{port}?node=1") as plc:
        read = plc.read
        assert read("D100", 1) == [100]
        return rate(seconds, lambda: read("D100", 1))


def sequential_round(port: int, seconds: float) -> None:
    b_uv = bare(port, seconds, "uvloop", "seq")
    a_uv = anyio.run(api_sequential, port, seconds, backend_options=UVLOOP)
    b_st = bare(port, seconds, "asyncio", "seq")
    a_st = anyio.run(api_sequential, port, seconds)
    peer = pypi_fins_sequential(port, seconds)
    blocking = sync_sequential(port, seconds)
    sample("seq: bare uvloop client (k/s)", b_uv / 1e3)
    sample("seq: plc.read, uvloop (k/s)", a_uv / 1e3)
    sample("seq: PyPI fins (k/s)", peer / 1e3)
    sample("seq: aiofins.sync plc.read (k/s)", blocking / 1e3)
    sample("seq: plc.read uvloop / bare uvloop", a_uv / b_uv, "≥ 1.0", lambda r: r >= 1.0)
    sample("seq: plc.read uvloop / PyPI fins", a_uv / peer, "≥ 1.0", lambda r: r >= 1.0)
    sample("seq: plc.read stock / bare stock", a_st / b_st, "≥ 1.2", lambda r: r >= 1.2)
    sample("seq: aiofins.sync / PyPI fins", blocking / peer, "≥ 1.0", lambda r: r >= 1.0)


def tasks_round(port: int, seconds: float) -> None:
    b = bare(port, seconds, "uvloop", "inflight")
    a = anyio.run(api_tasks, port, seconds, backend_options=UVLOOP)
    sample("50 tasks: plc.read uvloop (k/s)", a / 1e3)
    sample("50 tasks: plc.read / bare uvloop 50 in flight", a / b, "≥ 0.8", lambda r: r >= 0.8)


def dm_round(port: int) -> None:
    url = f"udp://127.0.0.1:{port}?node=1"
    listed = anyio.run(full_dm, url, 5, 4, "read", backend_options=UVLOOP)
    arrayed = anyio.run(full_dm, url, 5, 4, "read_array", backend_options=UVLOOP)
    sample("full DM: plc.read (ms)", listed["plain"] * 1e3)
    sample("full DM: plc.read_array (ms)", arrayed["plain"] * 1e3)
    sample("full DM: frames", listed["frames"], "= 33", lambda f: f == 33)
    sample("full DM plc.read, in 1-word round trips", listed["plain"] / listed["trip"],
           "≤ 20", lambda r: r <= 20)  # fmt: skip
    sample("full DM plc.read_array, in 1-word round trips",
           arrayed["plain"] / arrayed["trip"], "≤ 20", lambda r: r <= 20)  # fmt: skip


def poll100_round(ports: list[int], seconds: float) -> None:
    daemon = anyio.run(hand_written_daemon, ports, 0.05, seconds, backend_options=UVLOOP)
    done, missed, used = anyio.run(poll, ports, 0.05, seconds, backend_options=UVLOOP)
    per_scan = used / max(done, 1)
    sample("Poller 100x20 at 50 ms: missed scans", missed, "= 0", lambda m: m == 0)
    sample("Poller 100x20 at 50 ms: CPU per scan (µs)", per_scan * 1e6)
    sample("hand-written daemon: CPU per scan (µs)", daemon * 1e6)
    sample("Poller CPU per scan / hand-written daemon", per_scan / daemon, "≤ 1.0",
           lambda r: r <= 1.0)  # fmt: skip


def show(rounds: int) -> None:
    print(f"\n{'row':<50} {'median':>9} {'min-max':>17}  target   ({rounds} rounds)")
    for name, values in SAMPLES.items():
        median = statistics.median(values)
        target, met = TARGETS.get(name, ("", None))
        verdict = "" if met is None else ("met" if met(median) else "NOT met")
        spread = f"{min(values):.2f}-{max(values):.2f}"
        print(f"{name:<50} {median:9.2f} {spread:>17}  {target:<8} {verdict}")


def load() -> str:
    return " ".join(f"{x:.1f}" for x in os.getloadavg())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--seconds", type=float, default=1.0, help="seconds per timed case")
    parser.add_argument("--pin", type=int, default=0, help="the core of the one-core rows")
    parser.add_argument(
        "--skip",
        default="",
        help="comma list of: calls (sequential, 50 tasks, DM), poll100, poll1000",
    )
    args = parser.parse_args()
    skip = set(args.skip.split(","))
    affinity = os.sched_getaffinity(0)
    other = (args.pin + 1) % (os.cpu_count() or 2)
    print(f"load average at the start: {load()}", flush=True)
    ports = [free_port(), free_port()]
    near = start_responder(ports[0], args.pin)  # on the client's core
    far = start_responder(ports[1], other)  # a core of its own
    try:
        with responders(0 if "poll100" in skip else 100) as many:
            for i in range(args.rounds):
                print(f"round {i + 1} of {args.rounds} (load {load()})", flush=True)
                if "calls" not in skip:
                    os.sched_setaffinity(0, {args.pin})
                    try:
                        sequential_round(ports[0], args.seconds)
                        tasks_round(ports[1], args.seconds)
                        dm_round(ports[0])
                    finally:
                        os.sched_setaffinity(0, affinity)
                if many:
                    poll100_round(many, 2 * args.seconds)
    finally:
        for proc in (near, far):
            proc.terminate()
            proc.wait()
    print(f"load average at the end of the rounds: {load()}")
    show(args.rounds)
    if "poll1000" not in skip:
        SAMPLES.clear()
        print(f"\nPoller over 1,000 PLCs at 100 ms, once (load {load()})", flush=True)
        with responders(1000) as thousand:
            try:
                # the pool's timeout at 5 s: opening 1,000 sessions on a loaded machine
                done, missed, used = anyio.run(
                    poll, thousand, 0.1, 3.0, 5.0, backend_options=UVLOOP
                )
            except BaseException as exc:  # a failed scan (poll raises it): the row's result
                print(f"the Poller's 1,000-PLC run failed: {exc!r}")
                return
        sample("Poller 1,000 at 100 ms: missed scans", missed, "= 0", lambda m: m == 0)
        sample("Poller 1,000 at 100 ms: % of one core", 100 * used / 3.0, "≤ 50",
               lambda p: p <= 50)  # fmt: skip
        sample("Poller 1,000 at 100 ms: CPU per scan (µs)", used / max(done, 1) * 1e6)
        print(f"load average at the end: {load()}")
        show(1)


if __name__ == "__main__":
    main()
