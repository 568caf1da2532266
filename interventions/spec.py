"""Plans from short text: the ``--botox ef=200U`` style of the command line.

Each kind of intervention has one text form; :func:`build_plan` turns a set of them (and an
optional plan file) into one :class:`fieldbank.interventions.plan.Plan`, the steps in a fixed
order: plan file steps, lengthening, tenotomy, serial casting, rhizotomy, baclofen, botulinum.

==============  ===========================  ============================================
kind            text                         meaning
==============  ===========================  ============================================
botulinum       ``ef=200U,ee=100``           units per group (U; ``U``, ``unit(s)`` optional)
lengthening     ``bf=1cm``                   group and Δ (m, cm or mm: the unit is required)
tenotomy        ``ee``                       group
casting         ``ef`` or ``ef=5mm``         group and Δ (default: the catalogue's)
rhizotomy       ``all``, ``ef,ee:0.4``       groups and optional β factor
baclofen        ``all``, ``ef,ee:0.5``       groups and optional β factor
==============  ===========================  ============================================

Lengths convert through the one length table, :data:`fieldbank.units.LENGTH`. Text that
does not parse raises :class:`fieldbank.interventions.errors.InterventionError` naming the
option and the text; values outside the catalogue's ranges (its ``BOUNDS`` tables, the one
place they are written) are refused here in the command line's words - "the dose into one
group", "a lengthening" - never the catalogue's field names.
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
from fieldbank.interventions.defaults import TOXIN, value
from fieldbank.interventions.errors import InterventionError
from fieldbank.interventions.plan import Plan
from fieldbank.params import GROUP_LEGEND, GROUPS
from fieldbank.units import LENGTH
from fieldbank.validation import Interval

_NUM = r"([-+]?[0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)"
_LENGTH_UNIT = "|".join(map(re.escape, LENGTH))
#: How a dose may be written after its number (none: units of toxin).
DOSE_SUFFIXES = ("U", "u", "unit", "units")


def _split_items(items: Sequence[str]) -> list[str]:
    return [p.strip() for item in items for p in item.split(",") if p.strip()]


def _range_words(interval: Interval, scale: float = 1.0, unit: str | None = None) -> str:
    """'from 0 to 600 U', 'more than 0 and at most 4 cm': an interval in words, its ends
    multiplied by ``scale`` and written in ``unit`` (default the interval's)."""
    u = f" {interval.unit if unit is None else unit}".rstrip()
    lo = None if interval.low is None else interval.low * scale
    hi = None if interval.high is None else interval.high * scale
    if lo is not None and hi is not None and interval.low_closed and interval.high_closed:
        return f"from {lo:g} to {hi:g}{u}"
    parts = []
    if lo is not None:
        parts.append(f"{'at least' if interval.low_closed else 'more than'} {lo:g}")
    if hi is not None:
        parts.append(f"{'at most' if interval.high_closed else 'less than'} {hi:g}")
    return " and ".join(parts) + u


def _check(option: str, shown: str, what: str, value: float, interval: Interval,
           scale: float = 1.0, unit: str | None = None) -> None:
    """Refuse ``value`` outside the catalogue's ``interval`` in the command line's words:
    ``--botox 'ef=5000U': the dose into one group runs from 0 to 600 U; got 5000 U``."""
    if interval.contains(value):
        return
    u = f" {interval.unit if unit is None else unit}".rstrip()
    raise InterventionError(f"{option} {shown!r}: {what} must be "
                            f"{_range_words(interval, scale, unit)}; got {value * scale:g}{u}.")


def _check_group(option: str, shown: str, group: str) -> None:
    if group not in GROUPS:
        raise InterventionError(f"{option} {shown!r}: {group!r} is not a muscle group "
                                f"(groups: {GROUP_LEGEND}).")


def parse_units(items: Sequence[str]) -> dict[str, float]:
    """``('ef=200U', 'ee=100')`` → {'ef': 200.0, 'ee': 100.0}, U; each dose within the
    catalogue's range per group."""
    out: dict[str, float] = {}
    accepted = "200, 200U or 200 units"
    for part in _split_items(items):
        m = re.fullmatch(rf"(\w+)\s*=\s*{_NUM}\s*(\S*)", part)
        if not m or m.group(3) not in ("", *DOSE_SUFFIXES):
            unit = f" ({m.group(3)!r} is not a unit of toxin)" if m else ""
            raise InterventionError(
                f"--botox {part!r}: expected GROUP=DOSE in units of {TOXIN} (Botox®){unit}; "
                f"a dose is written {accepted} (e.g. ef=200U; groups: {GROUP_LEGEND}).")
        group, dose = m.group(1), float(m.group(2))
        _check_group("--botox", part, group)
        if group in out:
            raise InterventionError(f"--botox: muscle group {group!r} given twice.")
        _check("--botox", part, "the dose into one group", dose, Botulinum.BOUNDS["units"])
        out[group] = dose
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
        _check_group(option, part, out[-1][0])
    return out


def _check_length(option: str, shown: str, what: str, delta_m: float,
                  interval: Interval) -> None:
    _check(option, shown, what, delta_m, interval, scale=100.0, unit="cm")


def parse_reflex(text: str, option: str) -> tuple[tuple[str, ...], float | None]:
    """'all', 'ef,ee', 'all:0.4' → (groups, factor or None)."""
    groups_text, _, factor_text = text.partition(":")
    groups = GROUPS if groups_text.strip() in ("", "all") else tuple(
        g.strip() for g in groups_text.split(",") if g.strip())
    for g in groups:
        _check_group(option, text, g)
    factor = None
    if factor_text:
        try:
            factor = float(factor_text)
        except ValueError:
            raise InterventionError(
                f"{option} {text!r}: the factor after ':' must be a number.") from None
        interval = Rhizotomy.BOUNDS["factor"]
        _check(option, text, "the factor the reflex gain β is multiplied by", factor,
               interval)
        if factor == Rhizotomy.NO_CHANGE["factor"]:
            raise InterventionError(f"{option} {text!r}: a factor of {factor:g} would change "
                                    f"nothing; give one below {factor:g}.")
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
        _check_length("--lengthen", f"{g}={d * 100:g}cm", "a lengthening", d,
                      Lengthening.BOUNDS["delta_m"])
        steps.append(Lengthening(group=g, delta_m=d))
    for g in _split_items(tenotomy):
        _check_group("--tenotomy", g, g)
        steps.append(Tenotomy(group=g))
    for g, d in parse_group_lengths(cast, "--cast", default_m=value("casting.delta_m")):
        _check_length("--cast", f"{g}={d * 100:g}cm", "a cast's lengthening", d,
                      SerialCasting.BOUNDS["delta_m"])
        steps.append(SerialCasting(group=g, delta_m=d))
    for text, cls in ((rhizotomy, Rhizotomy), (baclofen, Baclofen)):
        if text is not None:
            groups, factor = parse_reflex(text, f"--{cls.kind}")
            steps.append(cls(groups=groups) if factor is None else cls(groups=groups,
                                                                      factor=factor))
    if weeks is not None:
        _check("--weeks", f"{weeks:g}", "the weeks since the injection", weeks,
               Botulinum.BOUNDS["weeks_since"])
    if botox:
        kw: dict[str, Any] = {} if weeks is None else {"weeks_since": weeks}
        steps.append(Botulinum(parse_units(botox), **kw))
    elif weeks is not None and not any(isinstance(s, Botulinum) for s in steps):
        raise InterventionError("--weeks needs a botulinum injection (--botox or --plan).")
    elif weeks is not None:
        steps = list(Plan(tuple(steps)).at_week(weeks).steps)
    return Plan(tuple(steps), label) if steps else None
