"""A plant network in Linux network namespaces: hosts at 192.168.250.N on one bridge.

Every name starts with a prefix unique to this run (``afp`` + 5 hex digits), so runs never
share a namespace, and :meth:`Lab.close` deletes every namespace it made (their veth ends
and the bridge go with them) and stops every process it started. Nothing is made in the
root namespace: veth pairs are created straight into their namespaces.
"""

from __future__ import annotations

import os
import secrets
import shutil
import signal
import subprocess
import sys
from pathlib import Path

SUBNET = "192.168.250"
TIMEOUT = 60
REPO = Path(__file__).parents[2]


def ip(*args: str, check: bool = True) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        ["ip", *args], capture_output=True, text=True, timeout=TIMEOUT, check=check
    )


def unavailable() -> str | None:
    """Why namespaces cannot be used here (``None``: they can)."""
    if not sys.platform.startswith("linux"):
        return "network namespaces are Linux only"
    if os.geteuid() != 0:
        return "network namespaces need root (CI runs as root)"
    if shutil.which("ip") is None or shutil.which("tc") is None:
        return "iproute2 (ip, tc) is not installed"
    name = f"afq{secrets.token_hex(3)}"
    made = ip("netns", "add", name, check=False)
    if made.returncode:
        return f"cannot create a network namespace: {made.stderr.strip()}"
    try:
        made = ip("-n", name, "link", "add", "xa", "type", "veth", "peer", "name", "xb",
                  check=False)  # fmt: skip
        if made.returncode:
            return f"cannot create a veth pair: {made.stderr.strip()}"
    finally:
        ip("netns", "del", name, check=False)
    if impairment() is None:
        return "neither tc netem (sch_netem) nor nftables can impair a link here"
    return None


_IMPAIRMENT: list[str | None] = []


def impairment() -> str | None:
    """How links are impaired here: ``"netem"`` (tc netem: loss, delay, duplication,
    reordering), ``"nft"`` (nftables on the veth's egress: random loss and duplication
    only, where the kernel has no sch_netem), or ``None``."""
    if _IMPAIRMENT:
        return _IMPAIRMENT[0]
    name = f"afq{secrets.token_hex(3)}"
    found: str | None = None
    ip("netns", "add", name)
    try:
        ip("-n", name, "link", "add", "xa", "type", "veth", "peer", "name", "xb")
        netem = ["ip", "netns", "exec", name, "tc", "qdisc", "add", "dev", "xa", "root", "netem",
                 "loss", "10%"]  # fmt: skip
        if subprocess.run(netem, capture_output=True, timeout=TIMEOUT).returncode == 0:
            found = "netem"
        elif shutil.which("nft") is not None:
            chain = _nft_chain("xa")
            probe = ["ip", "netns", "exec", name, "nft", "-f", "-"]
            if subprocess.run(probe, input=chain.encode(), capture_output=True,
                              timeout=TIMEOUT).returncode == 0:  # fmt: skip
                found = "nft"
    finally:
        ip("netns", "del", name, check=False)
    _IMPAIRMENT.append(found)
    return found


#: tc netem's impairment of each direction of a link.
NETEM = ("delay", "2ms", "1ms", "loss", "10%", "duplicate", "2%", "reorder", "10%")


def _nft_chain(dev: str) -> str:
    """nftables on ``dev``'s egress: 2 % of IP packets duplicated, 10 % dropped."""
    return (
        f"table netdev impair_{dev} {{\n"
        f"  chain egress {{ type filter hook egress device {dev} priority 0;\n"
        f"    meta protocol ip numgen random mod 50 0 dup to {dev}\n"
        f"    meta protocol ip numgen random mod 10 0 drop\n"
        f"  }}\n"
        f"}}\n"
    )


class Lab:
    """Namespaces on one bridge (``<prefix>-sw``), each host with one veth port."""

    def __init__(self) -> None:
        self.prefix = f"afp{secrets.token_hex(3)[:5]}"
        self.namespaces: list[str] = []
        self.processes: list[subprocess.Popen[str]] = []
        self.switch = self._namespace("sw")
        ip("-n", self.switch, "link", "add", "br0", "type", "bridge")
        ip("-n", self.switch, "link", "set", "br0", "up")

    def _namespace(self, role: str) -> str:
        name = f"{self.prefix}-{role}"
        ip("netns", "add", name)
        self.namespaces.append(name)
        ip("-n", name, "link", "set", "lo", "up")
        return name

    def host(self, role: str, octet: int, impaired: bool = True) -> str:
        """A namespace with 192.168.250.``octet``/24 on a port of the bridge; ``impaired``:
        both directions of its link lose 10 % of packets and duplicate some (tc netem also
        delays and reorders them; see :func:`impairment`)."""
        ns = self._namespace(role)
        inside, port = f"{self.prefix}h{octet}", f"{self.prefix}s{octet}"
        ip("link", "add", inside, "netns", ns, "type", "veth", "peer", "name", port,
           "netns", self.switch)  # fmt: skip
        ip("-n", ns, "addr", "add", f"{SUBNET}.{octet}/24", "dev", inside)
        ip("-n", ns, "link", "set", inside, "up")
        ip("-n", self.switch, "link", "set", port, "master", "br0")
        ip("-n", self.switch, "link", "set", port, "up")
        if impaired:
            for where, dev in ((ns, inside), (self.switch, port)):
                self.impair(where, dev)
        return ns

    def impair(self, ns: str, dev: str) -> None:
        if impairment() == "netem":
            self.exec(ns, "tc", "qdisc", "add", "dev", dev, "root", "netem", *NETEM)
        else:
            subprocess.run(
                ["ip", "netns", "exec", ns, "nft", "-f", "-"],
                input=_nft_chain(dev), capture_output=True, text=True, timeout=TIMEOUT,
                check=True,
            )  # fmt: skip

    def device(self, octet: int) -> str:
        """The host-side interface of ``octet``'s link."""
        return f"{self.prefix}h{octet}"

    def exec(self, ns: str, *command: str) -> subprocess.CompletedProcess[str]:
        done = subprocess.run(
            ["ip", "netns", "exec", ns, *command],
            capture_output=True, text=True, timeout=TIMEOUT, cwd=REPO,
        )  # fmt: skip
        if done.returncode:
            raise AssertionError(
                f"{' '.join(command)} in {ns} exited {done.returncode}:\n{done.stderr[-3000:]}"
            )
        return done

    def start(self, ns: str, *command: str, ready: str) -> subprocess.Popen[str]:
        """Start ``command`` in ``ns`` and wait for a line of stdout that starts with
        ``ready`` (a server announcing it listens)."""
        proc = subprocess.Popen(
            ["ip", "netns", "exec", ns, *command],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO,
        )  # fmt: skip
        self.processes.append(proc)
        assert proc.stdout is not None
        while True:
            line = proc.stdout.readline()
            if not line:
                _, err = proc.communicate(timeout=TIMEOUT)
                raise RuntimeError(f"{' '.join(command)} exited in {ns}: {err}")
            if line.startswith(ready):
                return proc

    def capture(self, ns: str, dev: str, path: Path) -> subprocess.Popen[str]:
        """dumpcap on ``dev`` in ``ns`` writing FINS/UDP (port 9600) to ``path``, once it
        says it captures; stop it with :meth:`stop`."""
        proc = subprocess.Popen(
            ["ip", "netns", "exec", ns, "dumpcap", "-i", dev, "-f", "udp port 9600", "-w",
             str(path)],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        self.processes.append(proc)
        assert proc.stderr is not None
        for line in proc.stderr:
            if line.startswith("Capturing on"):
                return proc
        raise RuntimeError(f"dumpcap did not start in {ns}: {proc.communicate(timeout=TIMEOUT)}")

    @staticmethod
    def stop(proc: subprocess.Popen[str]) -> None:
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=TIMEOUT)

    def close(self) -> None:
        for proc in self.processes:
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
            try:
                proc.communicate(timeout=TIMEOUT)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.communicate()
        for ns in reversed(self.namespaces):
            ip("netns", "del", ns, check=False)
        self.namespaces.clear()
