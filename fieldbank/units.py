"""The one table of units converted to SI at the edges (lab files, command-line text).

Inside, fieldbank works in SI only (m, N, N/m, m/s); a unit named at an edge - a CSV column
``x_mm``, an HDF5 attribute ``N/mm``, a what-if option ``--lengthen bf=1cm`` - is looked up
here and multiplied by its factor. A unit not in these tables is refused, never guessed.
Keys are lower case with ``_per_`` for a slash (:func:`normalise`).
"""

from __future__ import annotations

KGF_N = 9.80665  # standard gravity, N per kilogram-force (exact by definition)
LBF_N = 4.4482216152605  # N per pound-force (exact by definition)

LENGTH = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}
FORCE = {"n": 1.0, "mn": 1e-3, "kgf": KGF_N, "lbf": LBF_N}
STIFFNESS = {"n_per_m": 1.0, "n_per_cm": 1e2, "n_per_mm": 1e3, "kgf_per_m": KGF_N,
             "kgf_per_cm": KGF_N * 1e2, "kgf_per_mm": KGF_N * 1e3}
SPEED = {"m_per_s": 1.0, "cm_per_s": 1e-2, "mm_per_s": 1e-3}


def normalise(unit: str) -> str:
    """Text unit to table key: 'N/mm' -> 'n_per_mm', 'N' -> 'n', 'm/s' -> 'm_per_s'."""
    return unit.strip().lower().replace(" ", "").replace("/", "_per_").replace("·", "")


def factor(unit: str, table: dict[str, float]) -> float | None:
    """SI factor of ``unit`` in ``table``, or None if the unit is unknown there."""
    return table.get(normalise(unit))

#: The tables by quantity, for channels of raw recordings (C3D, NWB) that name their unit.
QUANTITIES = {"length": LENGTH, "force": FORCE, "speed": SPEED}
#: Unit words some writers use (NWB's 'meters'), as table keys.
_WORDS = {"meters": "m", "meter": "m", "metres": "m", "metre": "m", "millimeters": "mm",
          "millimetres": "mm", "centimeters": "cm", "newtons": "n", "newton": "n",
          "meters_per_second": "m_per_s", "meters_per_s": "m_per_s"}


def channel_factor(unit: str, quantity: str) -> float | None:
    """SI factor of a recording channel's ``unit`` for ``quantity`` ('length', 'force',
    'speed'), or None when the unit is unknown for it."""
    key = normalise(unit)
    return QUANTITIES[quantity].get(_WORDS.get(key, key))
