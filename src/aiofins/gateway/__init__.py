"""``aiofins gateway``: a polling daemon that publishes PLC tags to MQTT (``aiofins[gateway]``).

::

    from aiofins.gateway import Gateway, load_config

    async with Gateway(load_config("gateway.toml")) as gateway:
        await gateway.wait_closed()

See docs/gateway.md. The package sits above the library (Pool, Poller): nothing below
imports it. :mod:`.config` and :mod:`.sharding` need no extra packages; the rest needs
``paho-mqtt`` and ``prometheus_client`` (the ``gateway`` extra).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from .config import ConfigError, GatewayConfig, GroupConfig, MqttConfig, PlcConfig, load_config
from .sharding import Shard, parse_shard, shard_from_env

if TYPE_CHECKING:
    from .daemon import Gateway
    from .mqtt import LinkState
    from .plcs import PlcState

__all__ = [
    "ConfigError",
    "Gateway",
    "GatewayConfig",
    "GroupConfig",
    "LinkState",
    "MqttConfig",
    "PlcConfig",
    "PlcState",
    "Shard",
    "load_config",
    "parse_shard",
    "shard_from_env",
]

_LAZY = {"Gateway": ".daemon", "LinkState": ".mqtt", "PlcState": ".plcs"}


def __getattr__(name: str) -> Any:
    """The parts that need the ``gateway`` extra load on first use."""
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    import importlib

    return getattr(importlib.import_module(module, __name__), name)
