"""Reports of field changes: one patient, one plan, or a batch chosen by query.

Reports sit above the model with the rest of the what-if: they read stored plans
(:mod:`fieldbank.storage`), evaluate compiled arms (:mod:`fieldbank.evaluate`) and follow
botulinum plans week by week (:mod:`fieldbank.interventions.course`).

* :mod:`.select` - which stored plans a report covers (:class:`Selection` → :class:`CaseSpec`);
* :mod:`.compute` - one case: before/after metrics, time course, probing profiles, figures;
* :mod:`.figures` - the figures, as deterministic PNG bytes;
* :mod:`.html` - the self-contained HTML page (images embedded as data URIs);
* :mod:`.build` - :func:`build_report`: select, compute (over processes), write HTML, CSV, JSON.

A case is one stored plan: its base model ("before") and its result model ("after"). Output
bytes depend only on the database contents and the selection, so a rerun over the same
database gives identical files (no wall-clock time unless asked for).
"""

from fieldbank.interventions.report.build import ReportOutput, build_report
from fieldbank.interventions.report.select import CaseSpec, Selection, select_cases

__all__ = ["CaseSpec", "ReportOutput", "Selection", "build_report", "select_cases"]
