"""The shipped synthetic sample set, with the catalogue's botulinum toxin between the sessions.

:func:`fieldbank.sampledata.write_samples` writes the files; the treatment between a patient's
two sessions comes from here, so the later session follows what this program predicts:

* the plan given (:func:`sample_plan`) is botulinum toxin A, :data:`UNITS_PER_GROUP`
  onabotulinumtoxinA units into each hypertonic group, on the day of the first session, seen
  ``post_weeks`` later at the second;
* the truth at the second session is the catalogue's :class:`Botulinum` applied to the truth at
  the first (``Plan.apply``), at those weeks - the same code a what-if runs;
* for a patient whose ``response`` is below 1 (SYN-003), the effect is that fraction of the
  catalogue's: the same injection with its maximal effect ``emax`` scaled (the effect is
  proportional to it), a patient for whom the plan's prediction is wrong, as
  ``fieldbank validate`` must say.

The manifest records the plan document, the day it was given and the response, so the demo
stores the plan as given (``whatif --save --given-on``) and ``validate`` can check it.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from fieldbank.interventions.catalogue import Botulinum
from fieldbank.interventions.plan import Plan
from fieldbank.params import ArmParams
from fieldbank.sampledata import Given, SyntheticPatient
from fieldbank.sampledata import write_samples as write_files

#: Dose into each hypertonic group, onabotulinumtoxinA (Botox®) units.
UNITS_PER_GROUP = 150.0
DEFAULT_SEED = 20240601


def sample_plan(patient: SyntheticPatient, weeks: float) -> Plan:
    """The plan a sample patient was given: botulinum into each hypertonic group."""
    groups = [g for g, _ in patient.hypertonic]
    return Plan.of(Botulinum({g: UNITS_PER_GROUP for g in groups}, weeks_since=weeks),
                   label=f"botulinum {UNITS_PER_GROUP:g} U into " + ", ".join(groups))


def botulinum_treatment(patient: SyntheticPatient, truth: ArmParams, weeks: float) -> Given:
    """The sample plan given to ``patient``; the truth ``weeks`` later (see module docstring)."""
    plan = sample_plan(patient, weeks)
    if patient.response == 1.0:
        return Given(plan.to_dict(), plan.apply(truth), "as the catalogue predicts")
    weak = Plan(tuple(dataclasses.replace(s, emax=s.emax * patient.response)
                      if isinstance(s, Botulinum) else s for s in plan.steps), plan.label)
    return Given(plan.to_dict(), weak.apply(truth),
                 f"{100 * patient.response:g}% of the effect the catalogue predicts")


def write_samples(root: str | Path, seed: int = DEFAULT_SEED) -> dict[str, Any]:
    """Write the shipped sample set under ``root``; returns the manifest."""
    return write_files(root, treatment=botulinum_treatment, seed=seed)
