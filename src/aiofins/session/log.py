"""What the session logs about frames: each frame at DEBUG, replies no request waits for,
CPU error flags a reply carries. (Kept out of the hot path's module: none of it runs for a
normal reply unless DEBUG logging is on.)"""

from __future__ import annotations

import logging

from ..protocol.endcodes import CPU_ERROR_FLAGS
from ..protocol.frames import MRC, SID, SRC
from .response import SessionStats
from .sids import SidSpace
from .spaces import SidSpaces

logger = logging.getLogger("aiofins.session")
_DEBUG = logging.DEBUG


def log_frame(where: str, direction: str, frame: bytes) -> None:
    """DEBUG: one frame sent or received via ``where``, with its SID, command and bytes."""
    if len(frame) < 12:
        logger.debug("%s: %s %s", where, direction, frame.hex(" "), extra={"endpoint": where})
        return
    logger.debug(
        "%s: %s SID %d command %02X%02X: %s",
        where,
        direction,
        frame[SID],
        frame[MRC],
        frame[SRC],
        frame.hex(" "),
        extra={
            "endpoint": where,
            "sid": frame[SID],
            "command": f"{frame[MRC]:02X}{frame[SRC]:02X}",
        },
    )


def cpu_flags_seen(where: str, end_code: int, logged: int) -> int:
    """A reply's end code carries CPU error flags (0040 non-fatal, 0080 fatal error): not
    an error of the call, but logged as a WARNING, once per flag and session (``logged``:
    the flags logged so far). Returns the flags logged now."""
    new = end_code & CPU_ERROR_FLAGS & ~logged
    if not new:
        return logged
    for bit, what in ((0x80, "a fatal CPU error"), (0x40, "a non-fatal CPU error")):
        if new & bit:
            logger.warning(
                "%s reports %s (end code %04X flag %04X); see the CPU's error log",
                where,
                what,
                end_code,
                bit,
                extra={"endpoint": where, "end_code": f"{end_code:04X}"},
            )
    return logged | new


def log_unmatched(
    where: str,
    stats: SessionStats,
    spaces: SidSpaces,
    sids: SidSpace,
    key: int,
    frame: bytes,
    relay_error: bool,
    logged: float,
) -> float:
    """A reply ``frame`` no request waits for (SID space ``sids``, reply key ``key``) came via
    ``where``: counted in ``stats`` (late, duplicate or unsolicited; see
    :meth:`SidSpace.unmatched`), and logged when it says something about the link (a
    duplicate that lengthens the linger, late replies at 2, 4, 8 ...). ``spaces``: the
    session's SID spaces (what a duplicate teaches holds for every socket to the peer);
    ``logged``: the linger last logged (logged again once doubled). Returns the linger
    logged now."""
    kind, lateness = sids.unmatched(stats, key, frame, relay_error)
    if kind == "duplicate":
        return log_duplicate(where, spaces, sids, key, lateness, logged)
    if kind == "late":
        _log_late(where, stats.late_replies, key)
    return logged


def log_duplicate(
    where: str, spaces: SidSpaces, sids: SidSpace, key: int, lateness: float, logged: float
) -> float:
    """SID space ``sids`` saw a duplicate under ``key`` (``lateness``: how late it came if
    it made the linger grow, else 0.0): what the peer shows holds for every socket to it
    (``spaces``); a linger at least twice the one last logged (``logged``) is logged.
    Returns the linger logged now."""
    if spaces.extra:
        spaces.share_linger(sids)
    linger = sids.linger
    if lateness and linger >= 2 * logged:
        logger.warning(
            "%s: a duplicate reply came %.3f s after its request was answered; "
            "SIDs now linger %.3f s after a reply",
            where,
            lateness,
            linger,
            extra={"endpoint": where, "sid": key & 0xFF},
        )
        return linger
    return logged


def _log_late(where: str, late: int, key: int) -> None:
    """A late reply (``late`` so far) to SID ``key & 0xFF``: a WARNING at 2, 4, 8 ...,
    else DEBUG."""
    if late >= 2 and not late & (late - 1):  # 2, 4, 8, ...: repeated, rarely logged
        logger.warning(
            "%s: %d late replies so far (each came after its request was given up "
            "on): the timeout is too short for this PLC or route",
            where,
            late,
            extra={"endpoint": where, "sid": key & 0xFF},
        )
    elif logger.isEnabledFor(_DEBUG):
        logger.debug(
            "%s: late reply for SID %d (its request was given up on)",
            where,
            key & 0xFF,
            extra={"endpoint": where, "sid": key & 0xFF},
        )
