"""Text shown to people: strings from files and the command line with control characters as
visible escapes, so that a path or an attribute cannot move the cursor or reorder a line on a
terminal. Used by the CLI (:mod:`gnipy.cli.output`) and the reproduction's summary."""

from __future__ import annotations

import re

__all__ = ["safe", "user_name", "writers"]

# control characters (C0, DEL, C1), lone surrogates (undecodable bytes of a path), and the
# invisible characters that reorder or break lines on a terminal
_UNSAFE = re.compile("[\x00-\x1f\x7f-\x9f\u061c\u200e\u200f\u2028\u2029\u202a-\u202e\u2066-\u2069\ud800-\udfff]")
_NAMED_ESCAPES = {"\n": "\\n", "\t": "\\t", "\r": "\\r"}


def _escape_char(m) -> str:
    ch = m.group()
    if ch in _NAMED_ESCAPES:
        return _NAMED_ESCAPES[ch]
    o = ord(ch)
    return f"\\x{o:02x}" if o < 0x100 else f"\\u{o:04x}"


def safe(text) -> str:
    """`text` for a terminal: control characters as visible escapes (`\\x1b`, `\\n`, `\\x07`, ...).
    Print the result without markup (rich `Text`, or `markup=False`)."""
    return _UNSAFE.sub(_escape_char, str(text))


def user_name(uid: int) -> str:
    """A user id as people read it: `user NAME (uid N)`, or `uid N` where it has no name."""
    try:
        import pwd

        return f"user {pwd.getpwuid(uid).pw_name} (uid {uid})"
    except (ImportError, KeyError):
        return f"uid {uid}"


def writers(mode: int) -> str:
    """Who besides the owner may write a file of permission bits `mode`: "its group", "others"."""
    return " and ".join(name for bit, name in ((0o020, "its group"), (0o002, "others")) if mode & bit)
