"""Exceptions raised by fieldbank.interventions.

The package's subtree of :class:`fieldbank.errors.FieldbankError`::

    FieldbankError(Exception)                          fieldbank.errors
    └── InterventionError(FieldbankError, ValueError)  an intervention, plan or what-if request
        │                                              that is invalid
        └── SelectionError(InterventionError)          a report selection that matches no stored
                                                       plan, or a case without the data it needs

Messages name the intervention (or plan step), the field and the reason; a plan adds the step
number, a plan file its path.
"""

from __future__ import annotations

from fieldbank.errors import FieldbankError


class InterventionError(FieldbankError, ValueError):
    """An intervention or plan with an invalid part, or a what-if that cannot run."""


class SelectionError(InterventionError):
    """The report selection is empty, or data a report needs is missing."""


__all__ = ["InterventionError", "SelectionError"]
