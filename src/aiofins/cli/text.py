"""Text from a PLC, made safe to print on a terminal.

File names, FAL/FALS messages, model strings, string values read from memory and error
messages that quote them are the PLC's bytes: an ``ESC [`` sequence among them would reach the
operator's terminal as a command (move the cursor, rewrite the screen, set the window title).
Every human-readable line the command line prints passes such text through :func:`escape`;
``--json`` output is escaped by the JSON encoder already.
"""

from __future__ import annotations


def _escaped(char: str) -> str:
    code = ord(char)
    if code < 0x100:
        return f"\\x{code:02x}"
    if code < 0x10000:
        return f"\\u{code:04x}"
    return f"\\U{code:08x}"


def escape(text: object) -> str:
    """``str(text)`` with every character that is not printable (C0 and C1 controls such as
    ESC, CR and LF, DEL, bidirectional and other format characters) shown as a visible
    escape in Python's spelling: ``\\x1b``, ``\\x9b``, ``\\u202e``. Printable text, including
    non-ASCII letters, is returned as it is."""
    out = str(text)
    if out.isprintable():
        return out
    return "".join(c if c.isprintable() else _escaped(c) for c in out)
