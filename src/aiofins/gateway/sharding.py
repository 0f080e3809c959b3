"""Which gateway of N polls which PLC: rendezvous (highest random weight) hashing of PLC names.

Every gateway computes, for each PLC, a weight per shard from a hash of (shard, PLC name) and
keeps the PLCs whose highest weight is its own shard. No coordination is needed: N gateways
given the same configuration and ``N`` split the PLCs between them, each PLC to exactly one,
and going from N to N+1 shards moves only the PLCs the new shard wins (about 1/(N+1) of them).

The shard comes from ``--shard I/N``, else from the environment: ``AIOFINS_SHARD=I/N``, or
``AIOFINS_SHARDS=N`` with the index taken from the host name's trailing ``-<ordinal>`` (a
Kubernetes StatefulSet pod ``aiofins-gateway-3`` is shard 3).
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from ..protocol.errors import CommandError

_ORDINAL = re.compile(r"-(\d+)$")


@dataclass(frozen=True)
class Shard:
    """Shard ``index`` of ``count`` (0-based)."""

    index: int
    count: int

    def __post_init__(self) -> None:
        if self.count < 1 or not 0 <= self.index < self.count:
            raise CommandError(f"shard {self.index}/{self.count}: give I/N with 0 <= I < N")

    def owns(self, name: str) -> bool:
        """Whether this shard polls the PLC ``name``."""
        return self.count == 1 or owner(name, self.count) == self.index

    def select(self, names: Iterable[str]) -> list[str]:
        return [n for n in names if self.owns(n)]

    def __str__(self) -> str:
        return f"{self.index}/{self.count}"


def weight(shard: int, name: str) -> int:
    digest = hashlib.blake2b(f"{shard}\x00{name}".encode(), digest_size=8).digest()
    return int.from_bytes(digest, "big")


def owner(name: str, count: int) -> int:
    """The shard (of ``count``) that polls the PLC ``name``."""
    return max(range(count), key=lambda shard: weight(shard, name))


def parse_shard(text: str) -> Shard:
    """``"2/4"`` → ``Shard(2, 4)``."""
    index, sep, count = text.strip().partition("/")
    if not sep or not index.strip().isdigit() or not count.strip().isdigit():
        raise CommandError(f"shard {text!r}: give I/N, e.g. 0/2")
    return Shard(int(index), int(count))


def shard_from_env(environ: Mapping[str, str]) -> Shard | None:
    """The shard the environment names (see the module docstring), or None."""
    if environ.get("AIOFINS_SHARD"):
        return parse_shard(environ["AIOFINS_SHARD"])
    count = environ.get("AIOFINS_SHARDS")
    if not count:
        return None
    if not count.strip().isdigit():
        raise CommandError(f"AIOFINS_SHARDS={count!r}: give the number of shards")
    host = environ.get("HOSTNAME", "")
    m = _ORDINAL.search(host)
    if m is None:
        raise CommandError(
            f"AIOFINS_SHARDS={count} but HOSTNAME={host!r} has no -<ordinal> suffix "
            "(set AIOFINS_SHARD=I/N instead)"
        )
    return Shard(int(m.group(1)), int(count))
