"""Report the pins of a lock file that are older than a fresh resolution's.

Usage: python scripts/lock_report.py CURRENT.lock FRESH.lock

Both files are ``uv pip compile`` output (``name==version ; marker``). Prints one line per
package whose pinned version differs, and exits 0: it is a report for whoever refreshes the lock
(``scripts/lock``), never a gate.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

_PIN = re.compile(r"^([A-Za-z0-9][A-Za-z0-9._-]*)==([^\s;\\]+)\s*(?:;\s*([^\\]+?))?\s*\\?$")


def pins(text: str) -> dict[tuple[str, str], str]:
    """``{(name, marker): version}`` of every pinned requirement line in a lock file's text."""
    out: dict[tuple[str, str], str] = {}
    for line in text.splitlines():
        m = _PIN.match(line.strip())
        if m:
            name = re.sub(r"[-_.]+", "-", m.group(1)).lower()
            out[(name, (m.group(3) or "").strip())] = m.group(2)
    return out


def differences(current: str, fresh: str) -> list[str]:
    """Lines ``name  old -> new  [marker]`` for pins that a fresh resolution moves."""
    old, new = pins(current), pins(fresh)
    lines = []
    for key in sorted(set(old) | set(new)):
        name, marker = key
        where = f"  [{marker}]" if marker else ""
        a, b = old.get(key), new.get(key)
        if a != b:
            lines.append(f"{name:28s} {a or '(absent)':>12s} -> {b or '(dropped)'}{where}")
    return lines


def main(argv: list[str]) -> int:
    if len(argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    current, fresh = (Path(a).read_text(encoding="utf-8") for a in argv)
    lines = differences(current, fresh)
    if not lines:
        print("lock check: every pin is the newest compatible release")
    else:
        print(f"lock check: {len(lines)} pins behind the newest compatible releases "
              "(refresh with scripts/lock, then run scripts/test):")
        print("\n".join("  " + ln for ln in lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
