"""Every default number of the intervention catalogue, with its unit and its source.

One table, :data:`DEFAULTS`, so that documentation, the CLI (``fieldbank whatif --defaults``)
and the code read the same values. An entry whose literature gives no number says
``assumption`` in its source; all of them are overridable per intervention.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: The only botulinum product doses are given in (BRIEF §7).
TOXIN = "onabotulinumtoxinA"
#: How a dose's unit is named wherever a dose is shown.
DOSE_UNIT = "onabotulinumtoxinA (Botox®) units"


@dataclass(frozen=True)
class Default:
    """One documented default.

    Attributes
    ----------
    value : float
    unit : str
        '' for dimensionless numbers.
    source : str
        Reference, or 'assumption: ...' with the reasoning.
    """

    value: float
    unit: str
    source: str

    def to_dict(self) -> dict[str, object]:
        return {"value": self.value, "unit": self.unit, "source": self.source}


def _lengthening_width() -> float:
    # A 3 cm-fibre muscle losing 30% of its peak force at +1 cm (Delp & Zajac 1992, soleus):
    # exp(-(0.01 / (c · 0.03))²) = 0.70  →  c = (0.01 / 0.03) / sqrt(-ln 0.70).
    return (0.01 / 0.03) / math.sqrt(-math.log(0.70))


DEFAULTS: dict[str, Default] = {
    # --- botulinum toxin A ------------------------------------------------------------------
    "botulinum.peak_week": Default(
        5.0, "week",
        "effect rises over days and peaks about 3-6 weeks after injection (Eek & Himmelmann "
        "2016; Gäverth et al. 2014; Chen et al. 2022); 5 is the centre of the window"),
    "botulinum.wearoff_week": Default(
        14.0, "week",
        "assumption: effect down to wearoff_fraction of its peak at 14 weeks, the centre of "
        "'back near baseline by 12-16 weeks' (Eek & Himmelmann 2016; Chen et al. 2022; "
        "Kaňovský et al. 2021: re-injection >= 12 weeks); the curve then leaves 21% at 12 "
        "and 4.5% at 16 weeks"),
    "botulinum.wearoff_fraction": Default(
        0.1, "", "assumption: 'worn off' read as 10% of the peak effect"),
    "botulinum.emax": Default(
        0.7, "",
        "assumption: largest fractional drop of peak muscle force (α) one injection can give; "
        "with ed50_units it yields 50% at 150 U, the single-injection peak force drop of "
        "Fortuna et al. 2011 (animal data). Repeated injections compound (1 - e) per "
        "session: 2 × 150 U -> 75%, 3 × 150 U -> 88%, 4 × 150 U -> 94%, within the 80-95% of "
        "Fortuna et al. 2011, 2015"),
    "botulinum.ed50_units": Default(
        60.0, "U",
        "assumption: onabotulinumtoxinA dose giving half of emax (Emax dose curve, BRIEF §7)"),
    "botulinum.hill": Default(1.0, "", "assumption: Emax curve without a Hill exponent"),
    "botulinum.weeks_since": Default(
        5.0, "week", "the peak week: a what-if without --weeks shows the full effect"),
    "botulinum.max_units_per_group": Default(
        600.0, "U",
        "assumption: refuse a single-group dose above 600 U, more than any labelled "
        "upper-limb session total"),
    "botulinum.session_warning_units": Default(
        400.0, "U",
        "onabotulinumtoxinA adult upper-limb spasticity label: at most 400 U per treatment "
        "session (BRIEF §7); a session above it is a warning, not a refusal"),
    "botulinum.max_weeks": Default(
        52.0, "week", "assumption: the time-course model is not meant beyond a year"),
    # --- lengthening ------------------------------------------------------------------------
    "lengthening.width_factor": Default(
        _lengthening_width(), "",
        "calibrated: a 3 cm-fibre muscle loses 30% of peak moment at +1 cm (Delp & Zajac 1992, "
        "soleus); the same width gives -76% at +2 cm (Delp & Zajac: -85%) and -3% / -12% for "
        "a 10 cm-fibre muscle at +1 / +2 cm (Delp & Zajac report iliopsoas -4% / -9%)"),
    "lengthening.fibre_length_m": Default(
        0.10, "m", "assumption: optimal fibre length of the arm groups, of the order of 10 cm"),
    "lengthening.max_delta_m": Default(
        0.04, "m", "assumption: twice the largest lengthening Delp & Zajac 1992 simulated"),
    # --- tenotomy / release -----------------------------------------------------------------
    "tenotomy.residual_fraction": Default(
        0.0, "", "OpenSim convention: paralysis or release modelled as force capacity 0"),
    # --- reflex reduction -------------------------------------------------------------------
    "rhizotomy.beta_factor": Default(
        0.5, "", "assumption: selective dorsal rhizotomy halves the stretch-reflex gain"),
    "baclofen.beta_factor": Default(
        0.6, "", "assumption: intrathecal baclofen lowers the stretch-reflex gain by 40%"),
    # --- serial casting ---------------------------------------------------------------------
    "casting.delta_m": Default(
        0.005, "m",
        "assumption: recovers 5% of a 10 cm fibre length; PredSim models contracture by "
        "scaling optimal fibre length to 0.80-0.95"),
    "casting.km_factor": Default(
        0.9, "", "assumption: sustained stretch lowers passive stiffness by 10%"),
}


def value(name: str) -> float:
    """The default value of ``name`` (a key of :data:`DEFAULTS`)."""
    return DEFAULTS[name].value
