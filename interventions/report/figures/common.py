"""What every figure of a case shares: the page width, the colour of a check that held, and
the small texts of changes and angles."""

from __future__ import annotations

WIDTH = 1080.0
#: Colour of a check that held.
ACCENT_OK = "#009E73"

def pct(before: float, after: float) -> str:
    """Relative change as text ('−24%'); '' when the value before is 0."""
    if abs(before) < 1e-12:
        return "" if abs(after) < 1e-12 else "new"
    v = 100.0 * (after - before) / before
    return ("±0%" if abs(v) < 0.05 else f"{v:+.0f}%" if abs(v) >= 9.5 else f"{v:+.1f}%"
            ).replace("-", "−")


def angle_text(deg: float | None) -> str:
    if deg is None:
        return "—"
    text = f"{deg:.0f}"
    return f"{'0' if text == '-0' else text}°"
