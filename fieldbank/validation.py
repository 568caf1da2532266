"""Bounds in one table, messages generated: the validator every frozen configuration uses.

A configuration class (``ArmParams``, an intervention, the renderer's safety limits, ...) keeps
one table ``{field name: Interval}``; :func:`check_number` and :func:`check_tuple` check a value
against its entry and raise the package's error with a message generated from the interval::

    The 'beta[2] (ef)' parameter must be a finite number in [0, 1]; got 1.5 instead.

so the allowed range is written once and every message says what was expected and what
arrived. :func:`check_fields` is what a configuration's ``__post_init__`` calls: every field
named in its table checked at once, one error listing every problem
(:func:`problems_against` collects them). An interval of whole numbers
(``Interval.whole(500, 4000, "Hz")``) also refuses fractions and floats.

:func:`bound_problem` is the short form for messages that list several problems of one object
in a line (an intervention, a plan step): it names only the bound that was broken::

    'units[ef]' must be >= 0 U; got -3
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from fieldbank.errors import ParameterError

#: Builds the exception raised for a message (the caller's package error).
ErrorFactory = Callable[[str], Exception]


@dataclass(frozen=True)
class Interval:
    """A closed or half-open numeric range with a unit, used to validate and to explain."""

    low: float | None
    high: float | None
    unit: str = ""
    low_closed: bool = True
    high_closed: bool = True
    #: only whole numbers (a Python int, never a bool or a float)
    integer: bool = False

    @classmethod
    def whole(cls, low: int | None, high: int | None, unit: str = "") -> Interval:
        """The closed interval of whole numbers from ``low`` to ``high``."""
        return cls(low, high, unit, integer=True)

    def contains(self, value: float) -> bool:
        if not math.isfinite(value):
            return False
        if self.low is not None and (
            value < self.low or (value == self.low and not self.low_closed)
        ):
            return False
        return not (
            self.high is not None
            and (value > self.high or (value == self.high and not self.high_closed))
        )

    def describe(self) -> str:
        lo = "-inf" if self.low is None else f"{self.low:g}"
        hi = "inf" if self.high is None else f"{self.high:g}"
        lb = "[" if (self.low_closed and self.low is not None) else "("
        hb = "]" if (self.high_closed and self.high is not None) else ")"
        unit = f" {self.unit}" if self.unit else ""
        return f"{lb}{lo}, {hi}{hb}{unit}"


def number_problem(label: str, value: Any, interval: Interval,
                   what: str = "parameter") -> str | None:
    """The message for ``value`` outside ``interval`` (or not a number), else None."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return (f"The '{label}' {what} must be a number in {interval.describe()}; "
                f"got {value!r} ({type(value).__name__}) instead.")
    if interval.integer and not isinstance(value, int):
        return (f"The '{label}' {what} must be a whole number (an integer) in "
                f"{interval.describe()}; got {value!r} instead.")
    if not interval.contains(float(value)):
        kind = "whole number (an integer)" if interval.integer else "finite number"
        return (f"The '{label}' {what} must be a {kind} in {interval.describe()}; "
                f"got {value!r} instead.")
    return None


def check_number(label: str, value: Any, interval: Interval, *, what: str = "parameter",
                 error: ErrorFactory = ParameterError) -> float:
    """``value`` as a float, or ``error(message)`` naming ``label`` and the interval."""
    msg = number_problem(label, value, interval, what)
    if msg is not None:
        raise error(msg)
    return float(value)


def check_tuple(name: str, value: Any, length: int, interval: Interval, *,
                labels: Sequence[str] | None = None, what: str = "parameter",
                error: ErrorFactory = ParameterError) -> tuple[float, ...]:
    """A sequence of ``length`` numbers, each checked against ``interval``.

    ``labels`` names the entries in messages (default ``name[i]``).
    """
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence):
        raise error(f"The '{name}' {what} must be a sequence of {length} numbers; "
                    f"got {value!r}.")
    if len(value) != length:
        raise error(f"The '{name}' {what} must have {length} entries; got {len(value)}.")
    names = labels if labels is not None else [f"{name}[{i}]" for i in range(length)]
    return tuple(check_number(names[i], v, interval, what=what, error=error)
                 for i, v in enumerate(value))


def check_fields(obj: object, bounds: Mapping[str, Interval], *, what: str = "parameter",
                 names: Sequence[str] | None = None,
                 error: ErrorFactory = ParameterError) -> None:
    """Check every field of ``obj`` that ``bounds`` has an interval for (or only ``names``);
    ``error`` with every problem's message, one per sentence, if any."""
    todo = bounds if names is None else {n: bounds[n] for n in names}
    problems = problems_against({n: getattr(obj, n) for n in todo}, todo, what)
    if problems:
        raise error(" ".join(problems))


def problems_against(values: Mapping[str, Any], bounds: Mapping[str, Interval],
                     what: str = "parameter") -> list[str]:
    """Every message for the entries of ``values`` that ``bounds`` has an interval for."""
    out = []
    for name, interval in bounds.items():
        if name in values:
            msg = number_problem(name, values[name], interval, what)
            if msg is not None:
                out.append(msg)
    return out


def _broken_bound(value: float, interval: Interval) -> str | None:
    lo, hi = interval.low, interval.high
    if lo is not None and (value < lo or (value == lo and not interval.low_closed)):
        return f"{'>=' if interval.low_closed else '>'} {lo:g}"
    if hi is not None and (value > hi or (value == hi and not interval.high_closed)):
        return f"{'<=' if interval.high_closed else '<'} {hi:g}"
    return None


def bound_problem(label: str, value: Any, interval: Interval) -> str | None:
    """The short message for ``value`` outside ``interval`` (or not a number), else None.

    Names the one bound that was broken, with its unit: ``'delta_m' must be > 0 m; got -0.01``.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return f"'{label}' must be a finite number; got {value!r}"
    bound = _broken_bound(float(value), interval)
    if bound is None:
        return None
    unit = f" {interval.unit}" if interval.unit else ""
    return f"'{label}' must be {bound}{unit}; got {value:g}"
