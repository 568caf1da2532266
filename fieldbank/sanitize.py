"""Text that came from outside, made safe for where it goes: a terminal, a spreadsheet, a file
name.

Labels, file names and metadata arrive from lab files and users. Printed raw, an escape
sequence in a label can rewrite the terminal (``\\x1b]0;…``, cursor moves, a fake prompt);
written raw into a CSV, a cell such as ``=cmd|' /C calc'!A0`` runs as a formula when the file
is opened in a spreadsheet (CSV or formula injection); used raw in a path, ``../..`` leaves
the export directory. Each has one function here:

* :func:`printable` - control characters (C0, C1, DEL) and the invisible Unicode format
  characters that reorder text (bidirectional overrides) become visible ``\\xNN`` /
  ``\\u202e`` escapes; line breaks and tabs are kept only where ``multiline`` allows them;
* :func:`csv_cell` - a text cell that a spreadsheet would read as a formula (it starts with
  ``=``, ``+``, ``-``, ``@``, a tab or a carriage return, OWASP's list) gets a leading ``'``,
  unless it is a plain number such as ``-1.5``; control characters are escaped;
* :func:`csv_comment` - the text of a ``# key: value`` line: one line, and every piece a
  spreadsheet would split at a comma, semicolon or tab neutralised like a cell;
* :func:`file_component` - a label as one safe file-name component: letters, digits and
  ``-_.+``, everything else ``_``, no leading dot, never ``.`` or ``..``, at most 80 characters.
"""

from __future__ import annotations

import re
import unicodedata

_FORMULA_START = ("=", "+", "-", "@", "\t", "\r")
_NUMBER = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_UNSAFE_NAME = re.compile(r"[^A-Za-z0-9._+-]+")
#: Longest file-name component made from a label.
MAX_COMPONENT = 80


def _escape(ch: str) -> str:
    code = ord(ch)
    return f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}"


def printable(text: object, multiline: bool = False) -> str:
    """``text`` with every control or format character shown as an escape (see above)."""
    s = str(text)
    if s.isprintable():
        return s
    out = []
    for ch in s:
        if multiline and ch in "\n\t":
            out.append(ch)
        elif unicodedata.category(ch) in ("Cc", "Cf", "Zl", "Zp"):
            out.append(_escape(ch))
        else:
            out.append(ch)
    return "".join(out)


def csv_cell(value: object) -> object:
    """A value for a CSV cell: numbers as they are, text neutralised (see above)."""
    if not isinstance(value, str):
        return value
    text = printable(value)
    if text.startswith(_FORMULA_START) and not _NUMBER.fullmatch(text):
        return "'" + text
    return text


def csv_comment(text: object) -> str:
    """The text of a ``# key: value`` line, safe in a spreadsheet (see above)."""
    pieces = re.split(r"([,;\t])", printable(text))
    return "".join(p if p in (",", ";", "\t") else _neutral_piece(p) for p in pieces)


def _neutral_piece(piece: str) -> str:
    stripped = piece.lstrip(" ")
    if stripped.startswith(_FORMULA_START) and not _NUMBER.fullmatch(stripped.strip()):
        return piece[:len(piece) - len(stripped)] + "'" + stripped
    return piece


def file_component(label: object) -> str:
    """``label`` as one safe file-name component (see above); never empty."""
    name = _UNSAFE_NAME.sub("_", str(label)).lstrip(".")[:MAX_COMPONENT]
    return name if name not in ("", ".", "..") else "_"
