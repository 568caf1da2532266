"""The grammar of unit-carrying names in lab files; the units themselves are
:mod:`fieldbank.units` (one table for every edge).

CSV columns are ``<quantity>_<unit>`` (``x_mm``, ``fx_kgf``, ``kxx_n_per_mm``), optionally
prefixed ``sd_`` for a standard deviation; HDF5 and MAT files give the unit as text (``mm``,
``kgf``, ``N/mm``). A unit not in the tables is refused, never guessed.
"""

from __future__ import annotations

from fieldbank.units import FORCE, LENGTH, STIFFNESS

#: quantity -> (dimension name, unit table)
QUANTITIES: dict[str, tuple[str, dict[str, float]]] = {
    "x": ("length", LENGTH),
    "y": ("length", LENGTH),
    "fx": ("force", FORCE),
    "fy": ("force", FORCE),
    "kxx": ("stiffness", STIFFNESS),
    "kxy": ("stiffness", STIFFNESS),
    "kyx": ("stiffness", STIFFNESS),
    "kyy": ("stiffness", STIFFNESS),
}


def split_column(name: str) -> tuple[str, bool, str] | None:
    """``'sd_fx_kgf'`` -> ('fx', True, 'kgf'); None when the quantity is not known."""
    n = name.strip().lower()
    is_sd = n.startswith("sd_")
    if is_sd:
        n = n[3:]
    q, sep, unit = n.partition("_")
    if not sep or q not in QUANTITIES:
        return None
    return q, is_sd, unit


__all__ = ["QUANTITIES", "split_column"]
