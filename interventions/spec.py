"""Plans from short text: the ``--botox ef=200U`` style of the command line.

Each kind of intervention has one text form; :func:`build_plan` turns a set of them (and an
optional plan file) into one :class:`fieldbank.interventions.plan.Plan`, the steps in a fixed
order: plan file steps, lengthening, tenotomy, serial casting, rhizotomy, baclofen, botulinum.

==============  ===========================  ============================================
kind            text                         meaning
==============  ===========================  ============================================
botulinum       ``ef=200U,ee=100``           units per group (U; ``U``, ``units`` optional)
lengthening     ``bf=1cm``                   group and Δ (m, cm or mm: the unit is required)
tenotomy        ``ee``                       group
casting         ``ef`` or ``ef=5mm``         group and Δ (default: the catalogue's)
rhizotomy       ``all``, ``ef,ee:0.4``       groups and optional β factor
baclofen        ``all``, ``ef,ee:0.5``       groups and optional β factor
==============  ===========================  ============================================

Lengths convert through the one length table, :data:`fieldbank.units.LENGTH`. Text that
does not parse raises :class:`fieldbank.interventions.errors.InterventionError` naming the
option and the text; values that parse are checked by the catalogue.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import Any

from fieldbank.interventions.catalogue import (
    Baclofen,
    Botulinum,
    Intervention,
    Lengthening,
    Rhizotomy,
    SerialCasting,
    Tenotomy,
)
from fieldbank.interventions.defaults import value
from fieldbank.interventions.errors import InterventionError
from fieldbank.interventions.plan import Plan
from fieldbank.params import GROUP_LEGEND, GROUPS
from fieldbank.units import LENGTH

_NUM = r"([-+]?[0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)"
_LENGTH_UNIT = "|".join(map(re.escape, LENGTH))


def _split_items(items: Sequence[str]) -> list[str]:
    return [p.strip() for item in items for p in item.split(",") if p.strip()]


def parse_units(items: Sequence[str]) -> dict[str, float]:
    """``('ef=200U', 'ee=100')`` → {'ef': 200.0, 'ee': 100.0}, U."""
    out: dict[str, float] = {}
    for part in _split_items(items):
        m = re.fullmatch(rf"(\w+)\s*=\s*{_NUM}\s*(?:U|u|units?)?", part)
        if not m:
            raise InterventionError(
                f"--botox {part!r}: expected GROUP=DOSE in units, e.g. ef=200U "
                f"(groups: {GROUP_LEGEND}).")
        if m.group(1) in out:
            raise InterventionError(f"--botox: muscle group {m.group(1)!r} given twice.")
        out[m.group(1)] = float(m.group(2))
    return out


def parse_length(text: str, option: str, shown: str | None = None) -> float:
    """'1cm', '10 mm', '0.01m' → metres. The unit is required: a bare '1' could be 1 m or
    1 cm (and --botox's bare numbers are units of toxin), so it is refused, not guessed.
    ``shown``: the text to quote in a message (the whole ``GROUP=LENGTH`` item)."""
    m = re.fullmatch(rf"{_NUM}\s*({_LENGTH_UNIT})?", text.strip())
    quoted = repr(text if shown is None else shown)
    if not m:
        raise InterventionError(
            f"{option} {quoted}: expected a length such as 1cm, 10mm or 0.01m.")
    if m.group(2) is None:
        raise InterventionError(
            f"{option} {quoted}: give the unit, e.g. {m.group(1)}cm or {m.group(1)}mm (a bare "
            "number is not read as metres).")
    return float(m.group(1)) * LENGTH[m.group(2)]


def parse_group_lengths(items: Sequence[str], option: str,
                        default_m: float | None = None) -> list[tuple[str, float]]:
    """``('bf=1cm', 'ef')`` → [('bf', 0.01), ('ef', default_m)], m; a bare group needs a
    default."""
    out = []
    for part in _split_items(items):
        if "=" in part:
            g, length = part.split("=", 1)
            out.append((g.strip(), parse_length(length, option, part)))
        elif default_m is not None:
            out.append((part, default_m))
        else:
            raise InterventionError(f"{option} {part!r}: expected GROUP=LENGTH, e.g. bf=1cm.")
    return out


def parse_reflex(text: str, option: str) -> tuple[tuple[str, ...], float | None]:
    """'all', 'ef,ee', 'all:0.4' → (groups, factor or None)."""
    groups_text, _, factor_text = text.partition(":")
    groups = GROUPS if groups_text.strip() in ("", "all") else tuple(
        g.strip() for g in groups_text.split(",") if g.strip())
    factor = None
    if factor_text:
        try:
            factor = float(factor_text)
        except ValueError:
            raise InterventionError(
                f"{option} {text!r}: the factor after ':' must be a number.") from None
    return groups, factor


def build_plan(*, plan_file: str | None = None, botox: Sequence[str] = (),
               weeks: float | None = None, lengthen: Sequence[str] = (),
               tenotomy: Sequence[str] = (), cast: Sequence[str] = (),
               rhizotomy: str | None = None, baclofen: str | None = None) -> Plan | None:
    """The plan the texts describe (module docstring), or None when they name no step.

    ``weeks`` (weeks since the injection) sets the new botulinum step's ``weeks_since``, or,
    without ``botox``, shows the plan file's injections that many weeks after the most recent
    one; it needs a botulinum step.
    """
    steps: list[Intervention] = []
    label = ""
    if plan_file:
        plan = Plan.from_file(plan_file)
        steps.extend(plan.steps)
        label = plan.label
    for g, d in parse_group_lengths(lengthen, "--lengthen"):
        steps.append(Lengthening(group=g, delta_m=d))
    for g in _split_items(tenotomy):
        steps.append(Tenotomy(group=g))
    for g, d in parse_group_lengths(cast, "--cast", default_m=value("casting.delta_m")):
        steps.append(SerialCasting(group=g, delta_m=d))
    for text, cls in ((rhizotomy, Rhizotomy), (baclofen, Baclofen)):
        if text is not None:
            groups, factor = parse_reflex(text, f"--{cls.kind}")
            steps.append(cls(groups=groups) if factor is None else cls(groups=groups,
                                                                      factor=factor))
    if botox:
        kw: dict[str, Any] = {} if weeks is None else {"weeks_since": weeks}
        steps.append(Botulinum(parse_units(botox), **kw))
    elif weeks is not None and not any(isinstance(s, Botulinum) for s in steps):
        raise InterventionError("--weeks needs a botulinum injection (--botox or --plan).")
    elif weeks is not None:
        steps = list(Plan(tuple(steps)).at_week(weeks).steps)
    return Plan(tuple(steps), label) if steps else None
