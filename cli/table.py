"""Plain-text tables and messages within the terminal width every command keeps: 100 columns.

:func:`table` sizes each column to its widest cell (two spaces between columns, so no cell runs
into the next) and wraps the last column - a label, a file name, a status - under itself;
:func:`wrap` does the same for a message. Nothing is cut: a cell too long for its line is
wrapped, never shortened. ``tests/test_readme.py`` runs every list and show command on the
database the README's tours leave and measures.
"""

from __future__ import annotations

import textwrap
from collections.abc import Sequence

#: The widest line a command prints.
WIDTH = 100
#: The last column keeps at least this many columns, however wide the others.
MIN_LAST = 16
#: Where a word longer than its column (a URL, a path) may be broken.
_BREAKS = "&?/,;="


def table(header: Sequence[str], rows: Sequence[Sequence[str]], align: str = "",
          width: int = WIDTH) -> list[str]:
    """``header`` and ``rows`` as lines: ``align`` per column '<' or '>' (default '<'), the
    last column wrapped within ``width``; when the other columns leave it less than
    :data:`MIN_LAST`, the widest of them is narrowed and its cells wrapped too."""
    n = len(header)
    cells = [list(header), *([str(c) for c in r] for r in rows)]
    widths = [max(len(r[k]) for r in cells) for k in range(n)]
    ways = (align + "<" * n)[:n]

    def lead() -> int:
        return sum(widths[:-1]) + 2 * (n - 1)

    while n > 1 and lead() + MIN_LAST > width:  # narrow the widest of the other columns
        k = max(range(n - 1), key=lambda i: widths[i])
        if widths[k] <= MIN_LAST:
            break
        widths[k] = max(MIN_LAST, widths[k] - (lead() + MIN_LAST - width))
    widths[-1] = max(MIN_LAST, width - lead())
    out = []
    for r in cells:
        parts = [_wrap_cell(c, widths[k]) for k, c in enumerate(r)]
        for i in range(max(len(p) for p in parts)):
            line = "  ".join(f"{(p[i] if i < len(p) else ''):{ways[k]}{widths[k]}}"
                             for k, p in enumerate(parts))
            out.append(line.rstrip())
    return out


def _wrap_cell(text: str, room: int) -> list[str]:
    """``text`` in lines of at most ``room``: at spaces, and a longer word (a URL, a path)
    after one of its separators (``&``, ``?``, ``/`` …) rather than anywhere."""
    out = []
    for piece in textwrap.wrap(text, room, break_on_hyphens=False,
                               break_long_words=False) or [""]:
        while len(piece) > room:
            cut = max(piece.rfind(c, 1, room) for c in _BREAKS)
            cut = cut if cut > 0 else room - 1
            out.append(piece[:cut + 1])
            piece = piece[cut + 1:]
        out.append(piece)
    return out


def fit_lines(lines: Sequence[str], width: int = WIDTH) -> list[str]:
    """Every line within ``width``: a longer one wrapped, its continuation lines indented
    two columns deeper than it (a table row that fits stays as it is)."""
    out = []
    for line in lines:
        if len(line) <= width:
            out.append(line)
            continue
        lead = line[:len(line) - len(line.lstrip())]
        out += textwrap.wrap(line.strip(), width, initial_indent=lead,
                             subsequent_indent=lead + "    ", break_on_hyphens=False,
                             break_long_words=False)
    return out


def wrap(text: str, width: int = WIDTH, indent: str = "  ") -> str:
    """A message wrapped within ``width``, its continuation lines indented."""
    return "\n".join(textwrap.wrap(text, width, subsequent_indent=indent,
                                   break_on_hyphens=False, break_long_words=False) or [""])
