"""The gateway's TOML configuration: read, checked as a whole, every mistake reported at once.

:func:`load_config` reads the file and returns a :class:`GatewayConfig`, or raises one
:class:`ConfigError` whose ``problems`` name each mistake as ``FILE:LINE: message`` — before
anything connects. See docs/gateway.md for the reference of every key.
"""

from __future__ import annotations

import math
import re
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import urlencode

from ..connection import check_options
from ..endpoint import OPTIONS, option_value, parse_endpoint
from ..protocol.errors import CommandError, FinsError
from ..tagfile import TagFileError, load_tags
from ..tags import Tag, parse_tag

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib  # type: ignore[import-not-found, unused-ignore]

DEFAULT_TOPIC = "fins/{plc}/{group}"
DEFAULT_PLC_STATUS_TOPIC = "fins/{plc}/status"
DEFAULT_GATEWAY_TOPIC = "fins/_gateway/{gateway}"
#: Names of gateways, PLCs and groups: they become MQTT topic levels.
NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.-]*$")
#: Options a PLC's ``options`` table may set: the URL query options of the one option table,
#: :data:`aiofins.endpoint.OPTIONS` (each checked there, and against the URL's scheme).
PLC_OPTIONS = frozenset(name for name, option in OPTIONS.items() if option.schemes)


class ConfigError(CommandError):
    """A gateway configuration that cannot be used; ``problems`` lists each mistake as
    ``FILE:LINE: message``."""

    def __init__(self, problems: list[str]) -> None:
        self.problems = problems
        super().__init__("\n".join(problems))


@dataclass(frozen=True)
class MqttConfig:
    """Where and how the gateway publishes. Credentials come from the environment."""

    host: str = "127.0.0.1"
    port: int = 1883
    client_id: str | None = None
    #: Names of the environment variables holding the user name and password.
    username_env: str = "AIOFINS_MQTT_USERNAME"
    password_env: str = "AIOFINS_MQTT_PASSWORD"
    tls: bool = False
    ca_file: str | None = None
    cert_file: str | None = None
    key_file: str | None = None
    keepalive: int = 30
    backoff_min: float = 0.5
    backoff_max: float = 30.0
    #: Seconds a publish or subscribe may take before the link counts as broken.
    timeout: float = 10.0
    gateway_topic: str = DEFAULT_GATEWAY_TOPIC
    plc_status_topic: str = DEFAULT_PLC_STATUS_TOPIC
    #: Tasks publishing QoS 1/2 messages at once, each awaiting an acknowledgement (each
    #: keeps its topic's messages in order; QoS 0 messages need none).
    publishers: int = 8
    #: MQTT protocol version: "5" (message expiry, the broker's reason for a disconnect, a
    #: maximum packet size) or "3.1.1" for a broker without MQTT 5.
    protocol: str = "5"


@dataclass(frozen=True)
class HttpConfig:
    """``/healthz``, ``/readyz`` and ``/metrics``; ``port = 0`` picks a free port,
    ``enabled = false`` serves none."""

    enabled: bool = True
    host: str = "127.0.0.1"
    port: int = 9108
    #: Connections served at once (the rest wait in the listen queue, unaccepted).
    max_connections: int = 64
    #: Seconds a connection may take in all (an idle one is closed).
    idle_timeout: float = 5.0


@dataclass(frozen=True)
class GroupConfig:
    """A scan group: a tag list read every ``interval`` from each PLC that lists it."""

    name: str
    interval: float
    tags: Mapping[str, str]
    topic: str = DEFAULT_TOPIC
    qos: int = 0
    retain: bool = False
    changes_only: bool = False
    #: Messages kept per PLC while the broker is away (the oldest are dropped, counted).
    buffer: int = 100
    timeout: float | None = None
    #: Tags ``{topic}/set/{tag}`` may write; none by default.
    writable: frozenset[str] = frozenset()
    #: Times a failed write is tried again (0: never).
    write_retries: int = 0
    #: Seconds from the gateway's receipt of a set request until it is too old to write
    #: (refused "expired"); an MQTT 5 message expiry shortens it.
    write_max_age: float = 5.0
    parsed: Mapping[str, Tag] = field(default_factory=dict, compare=False, repr=False)


@dataclass(frozen=True)
class PlcConfig:
    """A PLC: its name (a topic level), URL and the groups it is scanned with."""

    name: str
    url: str
    groups: tuple[str, ...]


@dataclass(frozen=True)
class GatewayConfig:
    name: str
    mqtt: MqttConfig
    http: HttpConfig
    plcs: tuple[PlcConfig, ...]
    groups: Mapping[str, GroupConfig]
    #: Options for every connection (:func:`aiofins.connect` keywords: timeout, retries, ...).
    connect: Mapping[str, Any] = field(default_factory=dict)
    source: str = "<config>"
    #: Set requests waiting per PLC, at most (a full queue refuses, it does not delay).
    write_queue: int = 100
    #: Bytes a set payload may have (a larger one is refused unread).
    max_payload: int = 65536


def load_config(path: str | Path) -> GatewayConfig:
    """Read and check a gateway configuration file (:class:`ConfigError` lists every mistake)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError([f"{path}: {exc.strerror or exc}"]) from None
    return parse_config(text, str(path), base=path.parent)


def parse_config(text: str, source: str = "<config>", *, base: Path | None = None) -> GatewayConfig:
    """:func:`load_config` on text already read; tag files are found relative to ``base``."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        m = re.search(r"line (\d+)", str(exc))
        return _raise([f"{source}:{m.group(1) if m else 1}: TOML syntax: {exc}"])
    return _Reader(data, _Lines(text, source), base or Path.cwd()).read()


def _raise(problems: list[str]) -> GatewayConfig:
    raise ConfigError(problems)


class _Lines:
    """Where keys are in the text (tomllib gives no positions): good enough for messages."""

    _HEADER = re.compile(r"^\s*\[(\[?)\s*([A-Za-z0-9_.\"' -]+?)\s*\]\]?\s*(#.*)?$")

    def __init__(self, text: str, source: str) -> None:
        self.source = source
        self.lines = text.splitlines()
        #: (table path, index of the array entry or -1) → (first line, last line), 1-based.
        self.tables: dict[tuple[str, int], tuple[int, int]] = {}
        counts: dict[str, int] = {}
        starts: list[tuple[tuple[str, int], int]] = [(("", -1), 1)]
        for number, line in enumerate(self.lines, start=1):
            m = self._HEADER.match(line)
            if not m:
                continue
            name = m.group(2).replace(" ", "")
            if m.group(1):
                index = counts.get(name, -1) + 1
                counts[name] = index
                starts.append(((name, index), number))
            else:
                starts.append(((name, -1), number))
        for i, (key, first) in enumerate(starts):
            last = starts[i + 1][1] - 1 if i + 1 < len(starts) else len(self.lines)
            self.tables.setdefault(key, (first, last))

    def at(self, table: str, index: int = -1, key: str | None = None) -> str:
        """``FILE:LINE`` of ``key`` in a table (or of the table's header)."""
        first, last = self.tables.get((table, index), (1, max(1, len(self.lines))))
        if key is not None:
            pattern = re.compile(
                rf"^\s*[\"']?{re.escape(key)}[\"']?\s*=|[{{,]\s*{re.escape(key)}\s*="
            )
            for number in range(first, last + 1):
                if pattern.search(self.lines[number - 1]):
                    return f"{self.source}:{number}"
        return f"{self.source}:{first}"


class _Reader:
    def __init__(self, data: dict[str, Any], lines: _Lines, base: Path) -> None:
        self.data = data
        self.lines = lines
        self.base = base
        self.problems: list[str] = []

    def problem(self, where: str, message: str) -> None:
        self.problems.append(f"{where}: {message}")

    def read(self) -> GatewayConfig:
        known = {"gateway", "mqtt", "http", "connect", "plcs", "groups"}
        for key in self.data:
            if key not in known:
                header = (key, -1) in self.lines.tables
                where = self.lines.at(key) if header else self.lines.at("", -1, key)
                self.problem(where, f"unknown section {key!r}")
        gateway = self.table("gateway")
        name = self.take(gateway, "gateway", "name", str, "aiofins")
        if not NAME.match(name):
            self.problem(
                self.lines.at("gateway", -1, "name"), f"gateway name {name!r}: {_NAME_RULE}"
            )
        write_queue = self.take(gateway, "gateway", "write_queue", int, 100, check=_positive)
        max_payload = self.take(gateway, "gateway", "max_payload", int, 65536, check=_payload_size)
        self.unknown(gateway, "gateway", {"name", "write_queue", "max_payload"})
        mqtt = self.mqtt()
        http = self.http()
        connect = self.table("connect")
        try:
            check_options({k: v for k, v in connect.items() if k not in _CONNECT_NAMED})
        except FinsError as exc:
            self.problem(self.lines.at("connect"), str(exc))
        groups = self.groups()
        plcs = self.plcs(groups)
        self.topics(name, mqtt, plcs, groups)
        if self.problems:
            raise ConfigError(self.problems)
        return GatewayConfig(
            name,
            mqtt,
            http,
            plcs,
            groups,
            connect,
            self.lines.source,
            write_queue=write_queue,
            max_payload=max_payload,
        )

    # -- helpers ------------------------------------------------------------------------

    def table(self, key: str) -> dict[str, Any]:
        value = self.data.get(key, {})
        if not isinstance(value, dict):
            self.problem(self.lines.at("", -1, key), f"[{key}] must be a table")
            return {}
        return value

    def take(
        self,
        table: Mapping[str, Any],
        path: str,
        key: str,
        kind: type | tuple[type, ...],
        default: Any,
        index: int = -1,
        check: Callable[[Any], str | None] | None = None,
    ) -> Any:
        if key not in table:
            return default
        value = table[key]
        kinds = kind if isinstance(kind, tuple) else (kind,)
        ok = isinstance(value, kinds) and not (isinstance(value, bool) and bool not in kinds)
        where = self.lines.at(path, index, key)
        if not ok:
            names = " or ".join(_KIND_NAMES.get(k, k.__name__) for k in kinds)
            self.problem(where, f"{key} must be {names}, got {_shown(value)}")
            return default
        if check is not None:
            message = check(value)
            if message:
                self.problem(where, f"{key} {message}, got {_shown(value)}")
                return default
        return value

    def unknown(
        self, table: Mapping[str, Any], path: str, known: set[str], index: int = -1
    ) -> None:
        for key in table:
            if key not in known:
                self.problem(
                    self.lines.at(path, index, key),
                    f"unknown key {key!r} (known: {', '.join(sorted(known))})",
                )

    # -- sections -----------------------------------------------------------------------

    def mqtt(self) -> MqttConfig:
        t = self.table("mqtt")
        d = MqttConfig()

        def get(
            key: str,
            kind: type | tuple[type, ...],
            check: Callable[[Any], str | None] | None = None,
        ) -> Any:
            return self.take(t, "mqtt", key, kind, getattr(d, key), check=check)

        backoff_min = get("backoff_min", (int, float), _positive)
        config = MqttConfig(
            host=get("host", str),
            port=get("port", int, _port),
            client_id=get("client_id", str, _client_id),
            username_env=get("username_env", str),
            password_env=get("password_env", str),
            tls=get("tls", bool),
            ca_file=get("ca_file", str),
            cert_file=get("cert_file", str),
            key_file=get("key_file", str),
            keepalive=get("keepalive", int, _keepalive),
            backoff_min=float(backoff_min),
            backoff_max=float(get("backoff_max", (int, float), _positive)),
            timeout=float(get("timeout", (int, float), _positive)),
            gateway_topic=get("gateway_topic", str, _topic({"gateway"})),
            plc_status_topic=get("plc_status_topic", str, _topic({"plc", "gateway"})),
            publishers=get("publishers", int, _positive),
            protocol=get(
                "protocol", str, lambda v: None if v in ("5", "3.1.1") else 'must be "5" or "3.1.1"'
            ),
        )
        if config.backoff_max < config.backoff_min:
            self.problem(
                self.lines.at("mqtt", -1, "backoff_max"), "backoff_max is below backoff_min"
            )
        if (config.cert_file is None) != (config.key_file is None):
            self.problem(self.lines.at("mqtt"), "cert_file and key_file go together")
        self.unknown(t, "mqtt", set(MqttConfig.__dataclass_fields__))
        return config

    def http(self) -> HttpConfig:
        t = self.table("http")
        d = HttpConfig()
        config = HttpConfig(
            enabled=self.take(t, "http", "enabled", bool, d.enabled),
            host=self.take(t, "http", "host", str, d.host),
            port=self.take(t, "http", "port", int, d.port, check=_port_or_zero),
            max_connections=self.take(
                t, "http", "max_connections", int, d.max_connections, check=_positive
            ),
            idle_timeout=float(
                self.take(t, "http", "idle_timeout", (int, float), d.idle_timeout, check=_positive)
            ),
        )
        self.unknown(t, "http", set(HttpConfig.__dataclass_fields__))
        return config

    def groups(self) -> dict[str, GroupConfig]:
        entries = self.data.get("groups", [])
        if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
            self.problem(self.lines.at("", -1, "groups"), "groups must be [[groups]] tables")
            return {}
        if not entries:
            self.problem(f"{self.lines.source}:1", "no [[groups]]: give at least one scan group")
        groups: dict[str, GroupConfig] = {}
        for i, t in enumerate(entries):
            group = self.group(i, t)
            if group is None:
                continue
            if group.name in groups:
                self.problem(
                    self.lines.at("groups", i, "name"), f"group {group.name!r} is defined twice"
                )
                continue
            groups[group.name] = group
        return groups

    def group(self, i: int, t: dict[str, Any]) -> GroupConfig | None:
        at = self.lines.at
        name = self.take(t, "groups", "name", str, None, i)
        if name is None:
            self.problem(at("groups", i), "a group needs a name")
            return None
        if not NAME.match(name):
            self.problem(at("groups", i, "name"), f"group name {name!r}: {_NAME_RULE}")
        interval = self.take(t, "groups", "interval", (int, float), 1.0, i, _positive)
        tags = self.group_tags(i, t, name)
        topic = self.take(
            t, "groups", "topic", str, DEFAULT_TOPIC, i, _topic({"plc", "group", "gateway"})
        )
        qos = self.take(
            t, "groups", "qos", int, 0, i, lambda q: None if q in (0, 1, 2) else "must be 0, 1 or 2"
        )
        retain = self.take(t, "groups", "retain", bool, False, i)
        changes_only = self.take(t, "groups", "changes_only", bool, False, i)
        buffer = self.take(t, "groups", "buffer", int, 100, i, _positive)
        timeout = self.take(t, "groups", "timeout", (int, float), None, i, _positive)
        write_retries = self.take(
            t,
            "groups",
            "write_retries",
            int,
            0,
            i,
            lambda n: None if n >= 0 else "must not be negative",
        )
        write_max_age = self.take(t, "groups", "write_max_age", (int, float), 5.0, i, _positive)
        writable_list = self.take(t, "groups", "writable", list, [], i)
        writable: set[str] = set()
        for tag in writable_list:
            if not isinstance(tag, str) or tag not in tags:
                self.problem(
                    at("groups", i, "writable"),
                    f"writable tag {tag!r} is not a tag of group {name!r}",
                )
            elif not _TOPIC_LEVEL.match(tag):
                self.problem(
                    at("groups", i, "writable"),
                    f"writable tag {tag!r} cannot be a topic level (no '/', '+', '#' or spaces)",
                )
            else:
                writable.add(tag)
        self.unknown(
            t,
            "groups",
            {
                "name",
                "interval",
                "tags",
                "tags_file",
                "topic",
                "qos",
                "retain",
                "changes_only",
                "buffer",
                "timeout",
                "writable",
                "write_retries",
                "write_max_age",
            },
            i,
        )
        parsed: dict[str, Tag] = {}
        for tag_name, spec in tags.items():
            try:
                parsed[tag_name] = parse_tag(tag_name, spec)
            except FinsError as exc:
                self.problem(
                    at("groups", i, "tags") if "tags" in t else at("groups", i, "tags_file"),
                    tag_message(tag_name, spec, exc),
                )
        return GroupConfig(
            name=name,
            interval=float(interval),
            tags=tags,
            topic=topic,
            qos=qos,
            retain=retain,
            changes_only=changes_only,
            buffer=buffer,
            timeout=None if timeout is None else float(timeout),
            writable=frozenset(writable),
            write_retries=write_retries,
            write_max_age=float(write_max_age),
            parsed=parsed,
        )

    def group_tags(self, i: int, t: dict[str, Any], name: str) -> dict[str, str]:
        at = self.lines.at
        tags: dict[str, str] = {}
        inline = t.get("tags")
        if inline is not None:
            if not isinstance(inline, dict) or not all(isinstance(v, str) for v in inline.values()):
                self.problem(
                    at("groups", i, "tags"), 'tags must be a table of name = "ADDRESS[:TYPE]"'
                )
            else:
                tags.update(inline)
        files = t.get("tags_file")
        if files is not None:
            paths = [files] if isinstance(files, str) else files
            if not isinstance(paths, list) or not all(isinstance(p, str) for p in paths):
                self.problem(
                    at("groups", i, "tags_file"), "tags_file must be a path or a list of paths"
                )
                paths = []
            for p in paths:
                try:
                    loaded = load_tags(self.base / p)
                except TagFileError as exc:
                    self.problems.extend(
                        f"{at('groups', i, 'tags_file')}: {line}" for line in exc.problems
                    )
                    continue
                for tag_name, spec in loaded.items():
                    if tag_name in tags:
                        self.problem(
                            at("groups", i, "tags_file"), f"tag {tag_name!r} is given twice ({p})"
                        )
                    tags[tag_name] = spec
        if inline is None and files is None:
            self.problem(
                at("groups", i), f"group {name!r} has no tags (tags = {{...}} or tags_file)"
            )
        elif not tags and not self.problems:
            self.problem(at("groups", i), f"group {name!r} has no tags")
        return tags

    def plcs(self, groups: Mapping[str, GroupConfig]) -> tuple[PlcConfig, ...]:
        at = self.lines.at
        entries = self.data.get("plcs", [])
        if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
            self.problem(at("", -1, "plcs"), "plcs must be [[plcs]] tables")
            return ()
        if not entries:
            self.problem(f"{self.lines.source}:1", "no [[plcs]]: give at least one PLC")
        out: list[PlcConfig] = []
        seen: set[str] = set()
        for i, t in enumerate(entries):
            name = self.take(t, "plcs", "name", str, None, i)
            url = self.take(t, "plcs", "url", str, None, i)
            if name is None or url is None:
                self.problem(at("plcs", i), "a PLC needs a name and a url")
                continue
            if not NAME.match(name):
                self.problem(at("plcs", i, "name"), f"PLC name {name!r}: {_NAME_RULE}")
            if name in seen:
                self.problem(at("plcs", i, "name"), f"PLC {name!r} is defined twice")
            seen.add(name)
            options = self.take(t, "plcs", "options", dict, {}, i)
            given: dict[str, object] = {}
            for key, value in options.items():
                if key not in PLC_OPTIONS:
                    self.problem(
                        at("plcs", i, "options"),
                        f"option {key!r} is not a per-PLC option "
                        f"(known: {', '.join(sorted(PLC_OPTIONS))})",
                    )
                    continue
                try:  # TOML's own types too: breaker_cooldown = [0.1, 5], read_only = true
                    given[key] = option_value(key, value)
                except FinsError as exc:
                    self.problem(at("plcs", i, "options"), str(exc))
            url = _with_options(url, given)
            try:
                parse_endpoint(url)
            except FinsError as exc:
                self.problem(at("plcs", i, "url"), str(exc))
            names = self.take(t, "plcs", "groups", list, list(groups), i)
            for g in names:
                if g not in groups:
                    self.problem(at("plcs", i, "groups"), f"no group named {g!r}")
            self.unknown(t, "plcs", {"name", "url", "options", "groups"}, i)
            out.append(PlcConfig(name, url, tuple(g for g in names if g in groups)))
        return tuple(out)

    def topics(
        self,
        gateway: str,
        mqtt: MqttConfig,
        plcs: tuple[PlcConfig, ...],
        groups: Mapping[str, GroupConfig],
    ) -> None:
        """Every PLC and group publishes on a topic of its own, each a valid MQTT topic."""
        if "{plc}" not in mqtt.plc_status_topic:
            self.problem(
                self.lines.at("mqtt", -1, "plc_status_topic"), "plc_status_topic needs {plc}"
            )
        client_id = mqtt.client_id or f"aiofins-gateway-{gateway}-000"
        if len(client_id.encode()) > MAX_MQTT_STRING:
            self.problem(
                self.lines.at("gateway", -1, "name"),
                f"the MQTT client id made of the gateway name has {len(client_id.encode())} "
                f"bytes (at most {MAX_MQTT_STRING})",
            )
        bad = _topic_problem(render(mqtt.gateway_topic, gateway=gateway))
        if bad:
            self.problem(self.lines.at("mqtt", -1, "gateway_topic"), f"gateway_topic {bad}")
        owner: dict[str, str] = {}
        plcs = tuple({plc.name: plc for plc in reversed(plcs)}.values())[::-1]  # first of a name
        for plc in plcs:
            status = render(mqtt.plc_status_topic, gateway=gateway, plc=plc.name)
            owner[status] = f"the status of PLC {plc.name!r}"
            bad = _topic_problem(status)
            if bad:
                self.problem(
                    self.lines.at("mqtt", -1, "plc_status_topic"),
                    f"plc_status_topic for PLC {plc.name!r} {bad}",
                )
        for i, plc in enumerate(plcs):
            for g in plc.groups:
                group = groups[g]
                topic = render(group.topic, gateway=gateway, plc=plc.name, group=g)
                what = f"PLC {plc.name!r} group {g!r}"
                longest = max((len(t) for t in group.writable), default=0)
                bad = _topic_problem(f"{topic}/set/{'x' * longest}/reply" if longest else topic)
                if bad:
                    self.problem(self.lines.at("plcs", i, "name"), f"{what}'s topic {bad}")
                if topic in owner:
                    self.problem(
                        self.lines.at("plcs", i, "name"),
                        f"{what} publishes on {topic!r}, the topic of {owner[topic]} "
                        "(give the groups' topic templates {plc} and {group})",
                    )
                owner[topic] = what


def _shown(value: object, limit: int = 60) -> str:
    """``repr(value)``, cut short: a 70,000-character value is not echoed whole."""
    text = repr(value)
    return text if len(text) <= limit else f"{text[:limit]}... ({len(text)} characters)"


def tag_message(name: str, spec: str, exc: Exception) -> str:
    """``exc`` about the tag ``name`` (``spec``), naming it if the message does not."""
    text = str(exc)
    return text if f"tag {name!r}" in text else f"tag {name!r} ({spec}): {text}"


def render(template: str, **fields: str) -> str:
    """A topic template with its fields filled in (the fields it names)."""
    return template.format_map(_Fields(fields))


class _Fields(dict[str, str]):
    def __missing__(self, key: str) -> str:
        return "{" + key + "}"


_NAME_RULE = "use letters, digits, '_', '-' and '.' (it becomes an MQTT topic level)"
_TOPIC_LEVEL = re.compile(r"^[^/+#\s]+$")
_KIND_NAMES: dict[type, str] = {
    str: "a string",
    int: "a whole number",
    float: "a number",
    bool: "true or false",
    list: "a list",
    dict: "a table",
}
#: ``connect`` keywords that are named parameters of :func:`aiofins.connect`.
_CONNECT_NAMED = frozenset(
    {
        "dest",
        "src",
        "timeout",
        "retries",
        "max_in_flight",
        "gct",
        "networks",
        "limits",
        "word_order",
    }
)


def _positive(value: float) -> str | None:
    return None if value > 0 and math.isfinite(value) else "must be a positive number"


#: Bytes an MQTT string (a topic, the client id) may have: its length is two bytes.
MAX_MQTT_STRING = 65535
#: Seconds of keep-alive MQTT can carry (two bytes).
MAX_KEEPALIVE = 65535


def _keepalive(value: int) -> str | None:
    if 1 <= value <= MAX_KEEPALIVE:
        return None
    return f"must be 1..{MAX_KEEPALIVE} seconds (MQTT carries it in two bytes)"


def _client_id(value: str) -> str | None:
    size = len(value.encode())
    if not value:
        return "must not be empty (leave it out for aiofins-gateway-NAME)"
    if size > MAX_MQTT_STRING:
        return f"has {size} bytes, at most {MAX_MQTT_STRING} (an MQTT string)"
    if any(ord(c) < 0x20 or ord(c) == 0x7F for c in value):
        return "must not contain control characters"
    return None


def _topic_problem(topic: str) -> str | None:
    """Why ``topic`` (rendered) is not a topic the gateway can publish on, or None."""
    size = len(topic.encode())
    if size > MAX_MQTT_STRING:
        return f"has {size} bytes, at most {MAX_MQTT_STRING} (an MQTT string)"
    if not topic or "\x00" in topic:
        return "must not be empty or contain NUL"
    if topic.startswith("$"):
        return f"{topic[:40]!r} starts with '$' (reserved for the broker)"
    if "+" in topic or "#" in topic:
        return f"{topic[:40]!r} contains an MQTT wildcard"
    return None


def _payload_size(value: int) -> str | None:
    return None if 16 <= value <= 16 * 1024 * 1024 else "must be 16..16777216 bytes"


def _port(value: int) -> str | None:
    return None if 1 <= value <= 65535 else "must be a port number 1..65535"


def _port_or_zero(value: int) -> str | None:
    return None if 0 <= value <= 65535 else "must be a port number 0..65535 (0: any free port)"


def _topic(fields: set[str]) -> Callable[[str], str | None]:
    def check(template: str) -> str | None:
        names = set(re.findall(r"{(\w*)}", template))
        unknown = names - fields
        if unknown:
            return (
                f"names unknown field(s) {', '.join(sorted(unknown))} "
                f"(known: {', '.join(sorted(fields))})"
            )
        if "+" in template or "#" in template:
            return "must not contain MQTT wildcards"
        if template.startswith("$") or "\x00" in template or not template:
            return "must not be empty, start with '$' or contain NUL"
        try:
            template.format(**{f: "x" for f in fields})
        except (ValueError, IndexError, KeyError) as exc:
            return f"is not a valid template ({exc})"
        return None

    return check


def _with_options(url: str, options: Mapping[str, Any]) -> str:
    """``url`` with ``options`` added to its query, the rest of it as written (a round trip
    through ``urlsplit`` turned ``serial:///dev/ttyUSB0`` into ``serial:/dev/ttyUSB0``)."""
    if not options:
        return url
    base, _, query = url.partition("?")
    added = urlencode({k: str(v) for k, v in options.items()}, safe=",")
    return f"{base}?{query}&{added}" if query else f"{base}?{added}"
