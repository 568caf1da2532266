"""A stored cohort of measured sessions, built by the real ingest (no fits): for the batch
fit, the cluster tests and benchmarks/bench_cluster.py."""

from __future__ import annotations

import hashlib
from datetime import date, timedelta
from typing import Any

import numpy as np

from tests.report_helpers import COHORT_SEVERITIES


def store_sessions(db: Any, n_patients: int, sessions: tuple[str, ...] = ("pre", "post"),
                   seed: int = 0, n_postural: int = 25, n_stiffness: int = 9,
                   prefix: str = "COH") -> list[tuple[str, str]]:
    """``n_patients`` synthetic patients (severities of COHORT_SEVERITIES in turn, body size
    drawn from a seeded generator), each with ``sessions`` of noisy postural and stiffness maps
    (static and moving), ingested as CSV files. Returns the (patient, session) pairs."""
    from fieldbank.evaluate.severity import parse_severity_options, synthesize
    from fieldbank.fitting.synthetic import synthetic_patient
    from fieldbank.params import ArmParams

    rng = np.random.default_rng(seed)
    out = []
    for i in range(n_patients):
        code = f"{prefix}-{i:04d}"
        mass, height = round(float(rng.uniform(55, 90)), 1), round(float(rng.uniform(1.6, 1.9)), 2)
        side = ("right", "left")[i % 2]
        db.add_patient(code, mass, height, side, notes="synthetic")
        sev = COHORT_SEVERITIES[i % len(COHORT_SEVERITIES)]
        truth = synthesize(parse_severity_options([",".join(f"{k}={v}" for k, v in sev.items())]),
                           ArmParams.from_anthropometry(mass, height, side))
        for k, label in enumerate(sessions):
            pat = synthetic_patient(truth, seed=seed * 10_000 + i * 10 + k, n_postural=n_postural,
                                    n_stiffness=n_stiffness, n_held_out=1, patient=code)
            ingest_maps(db, code, label, pat.maps, date(2024, 1, 10) + timedelta(days=40 * k))
            out.append((code, label))
    return out


def ingest_maps(db: Any, code: str, label: str, maps: Any, when: date | None = None) -> None:
    """Ingest ``maps`` as CSV files into a session of patient ``code``."""
    from dataclasses import replace

    from fieldbank.storage import IncomingFile

    files = []
    for j, m in enumerate(maps):
        m = replace(m, metadata={"patient": code})
        data = m.to_csv().encode()
        files.append(IncomingFile(f"{code}-{label}-{j}.csv", hashlib.sha256(data).hexdigest(),
                                  "csv", data, (m,)))
    db.ingest_files(code, label, files, when)
