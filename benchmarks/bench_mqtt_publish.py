"""The gateway's QoS 0 publish path alone: CPU per message of ``MqttLink.put`` into a real
Mosquitto, one message per event-loop step (as scans come), for source trees compared in one
run (rounds interleaved, each round starting with the next tree).

    git worktree add /tmp/old <commit>
    python benchmarks/bench_mqtt_publish.py --trees old=/tmp/old/src,new=src [--rounds 5]

A tree whose link hands QoS 0 messages to aiomqtt's private paho client (``_paho_client``,
before the gateway ran paho itself) is measured a second time as ``NAME-public`` with that
path off: through aiomqtt's public ``publish()``. Needs mosquitto.
"""

from __future__ import annotations

import argparse
import os
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: Run in a child process with the tree on PYTHONPATH: prints microseconds of CPU per message.
CHILD = """
import sys, time, anyio
import aiofins.gateway.mqtt as mqtt
from aiofins.gateway.config import MqttConfig

if sys.argv[3] == "public":
    mqtt._paho_client = lambda client: None

async def main(port: int, count: int) -> None:
    link = mqtt.MqttLink(MqttConfig(port=port, timeout=5.0), client_id=f"b{time.time()}",
                         status_topic="bench/status")
    box = link.outbox("bench/scan", qos=0, limit=100)
    payload = b"x" * 600  # about a 20-tag scan message
    async with anyio.create_task_group() as tg:
        tg.start_soon(link.run)
        with anyio.fail_after(20):
            await link.connected.wait()
        for _ in range(2000):  # warm-up
            link.put(box, payload)
            await anyio.sleep(0)
        start = time.process_time()
        for _ in range(count):
            link.put(box, payload)
            await anyio.sleep(0)
        print(f"{1e6 * (time.process_time() - start) / count:.3f}")
        link.close()

anyio.run(main, int(sys.argv[1]), int(sys.argv[2]), backend="asyncio")
"""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def has_private_path(src: str) -> bool:
    return "_paho_client" in (Path(src) / "aiofins/gateway/mqtt.py").read_text()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trees", required=True, help="NAME=SRC_DIR,... (a tree's src)")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--messages", type=int, default=50_000)
    args = parser.parse_args()
    if shutil.which("mosquitto") is None:
        raise SystemExit("mosquitto is needed")
    variants: list[tuple[str, str, str]] = []
    for name, _, src in (t.partition("=") for t in args.trees.split(",") if t):
        variants.append((name, src, "as is"))
        if has_private_path(src):
            variants.append((f"{name}-public", src, "public"))
    with tempfile.TemporaryDirectory(prefix="aiofins-bench-mqtt-") as tmp:
        port = free_port()
        conf = Path(tmp) / "mosquitto.conf"
        conf.write_text(f"listener {port} 127.0.0.1\nallow_anonymous true\n")
        broker = subprocess.Popen(["mosquitto", "-c", str(conf)], stderr=subprocess.DEVNULL)
        try:
            deadline = time.monotonic() + 10
            while True:
                try:
                    socket.create_connection(("127.0.0.1", port), timeout=1).close()
                    break
                except OSError:
                    if time.monotonic() > deadline:
                        raise SystemExit("mosquitto did not listen") from None
                    time.sleep(0.05)
            results: dict[str, list[float]] = {name: [] for name, _, _ in variants}
            for round_ in range(args.rounds):
                shift = round_ % len(variants)
                for name, src, mode in variants[shift:] + variants[:shift]:
                    env = {**os.environ, "PYTHONPATH": str(Path(src).resolve())}
                    out = subprocess.run(
                        [sys.executable, "-c", CHILD, str(port), str(args.messages), mode],
                        env=env,
                        capture_output=True,
                        text=True,
                        check=True,
                    ).stdout
                    value = float(out.split()[-1])
                    results[name].append(value)
                    print(
                        f"round {round_ + 1} {name}: {value:.2f} us per message; "
                        f"load average {os.getloadavg()[0]:.1f}",
                        flush=True,
                    )
        finally:
            broker.terminate()
            broker.wait(timeout=10)
    first = statistics.median(results[variants[0][0]])
    for name, values in results.items():
        median = statistics.median(values)
        print(
            f"{name}: median {median:.2f} us per message "
            f"(runs {', '.join(f'{v:.2f}' for v in values)}), {median / first:.3f} x "
            f"{variants[0][0]}"
        )


if __name__ == "__main__":
    main()
