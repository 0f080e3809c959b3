"""Writes back from MQTT: ``{topic}/set/{tag}``, for the tags a group marks writable only.

Nothing is written unless the group lists the tag in ``writable``; the payload must be a value
of the tag's type (see :func:`~aiofins.gateway.payload.parse_set`). Each request is logged and
answered on ``{topic}/set/{tag}/reply``::

    {"tag": "setpoint", "id": "42", "ok": true, "end_code": "0000", "error": null}

``end_code`` is the PLC's answer (``"2108"``: cannot write in this mode, ...), ``null`` when
nothing reached the PLC (refused, bad payload, no answer). A failed write is tried again only
``write_retries`` times (0 by default).
"""

from __future__ import annotations

import json
import logging
from typing import TYPE_CHECKING, Any

from ..protocol.errors import EndCodeError, FinsError
from .payload import parse_set

if TYPE_CHECKING:
    from ..pool import Pool
    from .config import GroupConfig

log = logging.getLogger("aiofins.gateway")


def reply_topic(set_topic: str) -> str:
    return f"{set_topic}/reply"


async def handle_set(
    pool: Pool, plc: str, url: str, group: GroupConfig, tag_name: str, payload: bytes
) -> tuple[str, dict[str, Any]]:
    """Carry out one set request; (outcome, reply). Outcomes: ``written``, ``refused``,
    ``invalid``, ``failed``. Never raises for what a peer sends."""
    reply: dict[str, Any] = {
        "tag": tag_name,
        "id": None,
        "ok": False,
        "end_code": None,
        "error": None,
    }
    tag = group.parsed.get(tag_name)
    if tag is None or tag_name not in group.writable:
        why = "no such tag" if tag is None else "not writable (not in the group's writable list)"
        reply["error"] = f"{plc}/{group.name}/{tag_name}: {why}"
        log.warning("set refused: %s", reply["error"])
        return "refused", reply
    try:
        value, reply["id"] = parse_set(payload, tag)
    except FinsError as exc:
        reply["error"] = str(exc)
        log.warning("set %s/%s/%s refused: %s", plc, group.name, tag_name, exc)
        return "invalid", reply
    try:
        async with pool.client(url, timeout=group.timeout) as client:
            if tag.vtype.kind == "bit":
                await client.write(
                    tag.address,
                    [int(bool(value))],
                    timeout=group.timeout,
                    retries=group.write_retries,
                )
            else:
                await client.write_value(
                    tag.address,
                    value,
                    tag.vtype,
                    timeout=group.timeout,
                    retries=group.write_retries,
                )
    except EndCodeError as exc:
        reply["end_code"] = f"{exc.end_code.code:04X}"
        reply["error"] = str(exc)
        log.warning("set %s/%s/%s = %r failed: %s", plc, group.name, tag_name, value, exc)
        return "failed", reply
    except FinsError as exc:
        reply["error"] = f"{type(exc).__name__}: {exc}"
        log.warning(
            "set %s/%s/%s = %r failed: %s", plc, group.name, tag_name, value, reply["error"]
        )
        return "failed", reply
    reply["ok"] = True
    reply["end_code"] = "0000"
    log.info("set %s/%s/%s = %r (%s)", plc, group.name, tag_name, value, tag.text)
    return "written", reply


def encode_reply(reply: dict[str, Any]) -> bytes:
    return json.dumps(reply, separators=(",", ":")).encode()
