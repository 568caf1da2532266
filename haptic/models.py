"""Getting arm models for the renderer: parameter files and severity specifications.

``--severity shoulder=severe,elbow=mild`` uses :func:`fieldbank.severity.synthesize` when that
module is present. Without it, the seed's rule (BRIEF §5) is applied here: a group at "severe"
has ten times the unimpaired Km and α (MAS 4 ≈ 10× unimpaired joint stiffness) and β = 1; each
level below divides Km and α by 1 + w with the Weber fraction w = 0.6.
"""

from __future__ import annotations

import importlib
from pathlib import Path

from fieldbank.errors import ParameterError
from fieldbank.params import JOINT_GROUPS, ArmParams

LEVELS = ("unimpaired", "very mild", "mild", "moderate", "severe")
#: fallback rule (used only without fieldbank.severity): severe = 10× unimpaired, Weber 0.6
SEVERE_FACTOR = 10.0
WEBER_FRACTION = 0.6


def parse_severity(spec: str) -> dict[str, str]:
    """``"shoulder=severe,elbow=mild"`` → {'shoulder': 'severe', 'elbow': 'mild'}."""
    out: dict[str, str] = {}
    for part in filter(None, (p.strip() for p in spec.split(","))):
        if "=" not in part:
            raise ParameterError(f"severity item {part!r} must read joint_group=level, "
                                 f"e.g. shoulder=severe")
        group, level = (s.strip().lower() for s in part.split("=", 1))
        level = level.replace("_", " ").replace("-", " ")
        if group not in JOINT_GROUPS:
            raise ParameterError(f"unknown joint group {group!r} in severity {spec!r}; known: "
                                 f"{', '.join(JOINT_GROUPS)}")
        if level not in LEVELS:
            raise ParameterError(f"unknown severity level {level!r} for {group}; known: "
                                 f"{', '.join(LEVELS)}")
        out[group] = level
    return out


def from_severity(severities: dict[str, str], base: ArmParams | None = None) -> ArmParams:
    """An arm with the given severity per joint group (see the module docstring)."""
    try:
        sev = importlib.import_module("fieldbank.severity")
    except ImportError:
        sev = None
    if sev is not None and hasattr(sev, "synthesize"):
        return sev.synthesize(severities, base)
    p = base or ArmParams.from_anthropometry()
    for joint, level in severities.items():
        steps = LEVELS.index(level)
        if steps == 0:
            continue
        factor = SEVERE_FACTOR / (1.0 + WEBER_FRACTION) ** (len(LEVELS) - 1 - steps)
        for g in JOINT_GROUPS[joint]:
            p = p.with_group(g, km_n_per_m=p.group_value("km_n_per_m", g) * factor,
                             alpha_n=p.group_value("alpha_n", g) * factor,
                             beta=1.0 if level == "severe" else p.group_value("beta", g))
    return p


def load_model(path: str | Path | None, severity: str | None = None) -> ArmParams:
    """Parameters from a JSON file, or from a severity spec, or unimpaired defaults."""
    if path is not None and severity:
        raise ParameterError("give a model file or a severity, not both")
    if path is not None:
        return ArmParams.from_file(path)
    if severity:
        return from_severity(parse_severity(severity))
    return ArmParams.from_anthropometry()
