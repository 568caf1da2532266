"""Units that ingest converts to SI, and the grammar of unit-carrying names.

CSV columns are ``<quantity>_<unit>`` (``x_mm``, ``fx_kgf``, ``kxx_n_per_mm``), optionally
prefixed ``sd_`` for a standard deviation; HDF5 and MAT files give the unit as text (``mm``,
``kgf``, ``N/mm``). A unit not in these tables is refused, never guessed.
"""

from __future__ import annotations

KGF_N = 9.80665  # standard gravity, N per kilogram-force (exact by definition)
LBF_N = 4.4482216152605  # N per pound-force (exact by definition)

LENGTH = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}
FORCE = {"n": 1.0, "mn": 1e-3, "kgf": KGF_N, "lbf": LBF_N}
STIFFNESS = {"n_per_m": 1.0, "n_per_cm": 1e2, "n_per_mm": 1e3, "kgf_per_m": KGF_N,
             "kgf_per_cm": KGF_N * 1e2, "kgf_per_mm": KGF_N * 1e3}
SPEED = {"m_per_s": 1.0, "cm_per_s": 1e-2, "mm_per_s": 1e-3}

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


def normalise(unit: str) -> str:
    """Text unit to table key: 'N/mm' -> 'n_per_mm', 'N' -> 'n', 'm/s' -> 'm_per_s'."""
    return unit.strip().lower().replace(" ", "").replace("/", "_per_").replace("·", "")


def factor(unit: str, table: dict[str, float]) -> float | None:
    """SI factor of ``unit`` in ``table``, or None if the unit is unknown there."""
    return table.get(normalise(unit))


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
