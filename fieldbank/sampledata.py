"""Synthetic sample data: lab-style map files of made-up patients, from a seeded generator.

Nothing here is patient data. Every file says so in its ``source`` (``fieldbank synthetic sample
(not patient data)``), and the directory holds a ``README.txt`` and a ``manifest.json`` that
list the synthetic patients, their sessions, each file's format and kind, and the model
parameters each patient's maps were computed from (``params-<session>.json``), so that a fit can
be compared with the truth.

Each patient has two sessions: 'pre-BoNT' on :data:`PRE_DATE`, after which a treatment is
given (its plan document is recorded in the manifest with the day it was given), and
'post-BoNT' ``post_weeks`` later. The treatment is passed in (:class:`Treatment`): the core does
not know the intervention catalogue, so the shipped set is written by
:func:`fieldbank.interventions.samples.write_samples`, which gives every patient the catalogue's
botulinum toxin A (150 U into each hypertonic group) and computes the later session's maps from
the truth with the catalogue's own effect at those weeks - for all patients but one, whose
``response`` is a fraction of it (a patient the plan's prediction gets wrong). Maps are the
model's postural map on 25 scattered reachable positions and stiffness maps on 9, static and at
a moving endpoint, the same positions in both sessions, with 5 % Gaussian noise (plus a small
floor) and the matching standard deviations. The files come in every format ingest reads: CSV in
SI units, CSV in lab units (mm, kgf, N/mm), MATLAB v5, MATLAB v7.3 and fieldbank HDF5; and one
file as a lab's own software writes it, without metadata and with its own column names
(:data:`LAB_EXPORT`, listed under ``lab_exports`` in the manifest).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import date, timedelta
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from fieldbank.ingest.hdf5fmt import write_hdf5
from fieldbank.ingest.matfmt import write_mat5, write_mat73
from fieldbank.maps import FieldMap, postural_map, stiffness_map
from fieldbank.model import Arm
from fieldbank.params import ArmParams
from fieldbank.units import KGF_N

SOURCE = "fieldbank synthetic sample (not patient data)"
NOISE_FRACTION = 0.05
FORCE_FLOOR_N = 0.05
STIFFNESS_FLOOR_N_PER_M = 5.0
N_POSTURAL = 25
N_STIFFNESS = 9
#: Speed of the moving stiffness measurement. The seed's reflex (eq. 3) only fires on a fast
#: stretch, so the lab perturbs the arm while moving the hand at 1 m/s along the mid-sagittal
#: direction that stretches the patient's hypertonic groups (see ``SyntheticPatient``).
MOVING_SPEED_M_PER_S = 1.0
#: The day of every patient's first session; the treatment is given the same day, after it.
PRE_DATE = date(2024, 1, 10)
PRE_SESSION = "pre-BoNT"
POST_SESSION = "post-BoNT"


@dataclass(frozen=True)
class SyntheticPatient:
    code: str
    body_mass_kg: float
    height_m: float
    side: str
    hypertonic: tuple[tuple[str, float], ...]  # (group, Km multiple of unimpaired)
    #: +1: hand moving away from the body (+y, stretches the flexors); -1: toward the body.
    moving_direction: float = -1.0
    #: Weeks from the treatment to the second session.
    post_weeks: float = 6.0
    #: Fraction of the treatment's predicted effect the patient shows (1: as predicted).
    response: float = 1.0

    @property
    def moving_velocity_m_per_s(self) -> tuple[float, float]:
        return (0.0, self.moving_direction * MOVING_SPEED_M_PER_S)

    def params(self) -> ArmParams:
        p = ArmParams.from_anthropometry(self.body_mass_kg, self.height_m, self.side)
        for g, mult in self.hypertonic:
            km = p.group_value("km_n_per_m", g) * mult
            alpha = p.group_value("alpha_n", g) * mult
            p = p.with_group(g, km_n_per_m=km, alpha_n=alpha, beta=0.8)
        return p

    @property
    def post_date(self) -> date:
        return PRE_DATE + timedelta(days=round(7 * self.post_weeks))


@dataclass(frozen=True)
class Given:
    """A treatment as given to a sample patient: its plan document, the truth at the later
    session, and the response in words (for the manifest)."""

    plan: Mapping[str, Any]
    after: ArmParams
    response: str


class Treatment(Protocol):
    """What happens between a patient's sessions (see :func:`write_samples`)."""

    def __call__(self, patient: SyntheticPatient, truth: ArmParams, weeks: float) -> Given: ...


PATIENTS = (
    SyntheticPatient("SYN-001", 72.0, 1.74, "right", (("ef", 6.0), ("bf", 4.0)), +1.0),
    SyntheticPatient("SYN-002", 61.0, 1.62, "left", (("sf", 5.0),), post_weeks=4.0),
    # measured effect a tenth of the catalogue's (e.g. a partial secondary non-responder)
    SyntheticPatient("SYN-003", 85.0, 1.83, "right", (("ee", 3.0), ("be", 3.0)),
                     response=0.1),
)


def scattered_positions(arm: Arm, n: int, rng: np.random.Generator) -> np.ndarray:
    """n reachable hand positions (m), scattered, at least 2 cm apart, away from the limits."""
    p = arm.params
    out: list[np.ndarray] = []
    lo1, hi1 = p.shoulder_range_rad
    lo2, hi2 = p.elbow_range_rad
    while len(out) < n:
        q = np.array([rng.uniform(lo1 + 0.25, hi1 - 0.25), rng.uniform(lo2 + 0.35, hi2 - 0.25)])
        x = arm.fk(q[None])[0]
        x = np.round(x, 4)  # lab robots report positions to 0.1 mm
        if arm.reachable(x[None])[0] and all(np.hypot(*(x - y)) > 0.02 for y in out):
            out.append(x)
    return np.array(out)


def _noisy(m: FieldMap, floor: float, rng: np.random.Generator, **changes: Any) -> FieldMap:
    sd = NOISE_FRACTION * np.abs(m.values) + floor
    vals = m.values + rng.normal(0.0, 1.0, m.values.shape) * sd
    return FieldMap(kind=m.kind, positions_m=m.positions_m, values=vals, sd=sd,
                    velocity_m_per_s=m.velocity_m_per_s, source=m.source,
                    metadata=changes.get("metadata", {}))


def lab_units_csv(m: FieldMap) -> str:
    """The map as CSV in lab units: positions in mm, forces in kgf, stiffness in N/mm."""
    lines = [f"# kind: {m.kind}", f"# frame: {m.frame}", f"# sign: {m.sign}",
             f"# velocity_m_per_s: {m.speed_m_per_s:.17g}"]
    if m.speed_m_per_s > 0:
        lines.append("# velocity_vector_m_per_s: {:.17g}, {:.17g}".format(*m.velocity_m_per_s))
    lines.append(f"# source: {m.source}")
    lines += [f"# {k}: {v}" for k, v in m.metadata.items()]
    n = m.n
    if m.kind == "postural":
        names = ["fx_kgf", "fy_kgf"]
        scale = 1.0 / KGF_N
    else:
        names = ["kxx_n_per_mm", "kxy_n_per_mm", "kyx_n_per_mm", "kyy_n_per_mm"]
        scale = 1e-3
    cols = ["x_mm", "y_mm", *names]
    parts = [m.positions_m * 1e3, m.values.reshape(n, -1) * scale]
    if m.sd is not None:
        cols += [f"sd_{c}" for c in names]
        parts.append(m.sd.reshape(n, -1) * scale)
    table = np.hstack(parts)
    lines.append(",".join(cols))
    lines += [",".join(f"{v:.10g}" for v in row) for row in table]
    return "\n".join(lines) + "\n"


#: A lab's own export of SYN-001's first session: no metadata, the lab's column names
#: (:func:`lab_export_csv`); ingest reads it with --kind, --frame, --sign and --column.
LAB_EXPORT = "lab-export.csv"
LAB_EXPORT_COLUMNS = {"x_mm": "PosX", "y_mm": "PosY", "fx_n": "FX", "fy_n": "FY"}


def lab_export_csv(m: FieldMap) -> str:
    """A postural map as a lab's software exports it: no ``# key: value`` lines, its own
    column names (:data:`LAB_EXPORT_COLUMNS`), positions in mm, forces in N, no sd."""
    lines = [",".join(LAB_EXPORT_COLUMNS.values())]
    lines += [f"{x * 1e3:.1f},{y * 1e3:.1f},{fx:.4f},{fy:.4f}"
              for (x, y), (fx, fy) in zip(m.positions_m, m.values.reshape(m.n, 2), strict=True)]
    return "\n".join(lines) + "\n"


def _write_lab_export(base: Path, seed: int) -> dict[str, str]:
    """SYN-001's pre-BoNT postural map measured again and exported by a lab's own software
    (a stream of its own, so the other files do not change with it)."""
    rng = np.random.default_rng([seed, 1])
    pat = PATIENTS[0]
    arm = Arm.from_params(pat.params())
    m = _noisy(postural_map(arm, scattered_positions(arm, N_POSTURAL, rng)), FORCE_FLOOR_N, rng)
    rel = f"{pat.code}/{LAB_EXPORT}"
    (base / rel).write_text(lab_export_csv(m), encoding="utf-8")
    return {"file": rel, "format": "csv", "kinds": "postural", "session": PRE_SESSION,
            "columns": ",".join(f"{k}={v}" for k, v in LAB_EXPORT_COLUMNS.items()),
            "note": "a lab's export without metadata: give --kind postural --frame shoulder "
                    "--sign arm-on-handle and a --column for each column"}


def write_samples(root: str | Path, *, treatment: Treatment,
                  seed: int = 20240601) -> dict[str, Any]:
    """Write the sample set under ``root``; returns the manifest (also in manifest.json).

    ``treatment`` is given on :data:`PRE_DATE` after the first session; the second session's
    truth is what it returns for the patient's ``post_weeks``.
    """
    rng = np.random.default_rng(seed)
    base = Path(root)
    base.mkdir(parents=True, exist_ok=True)
    manifest: dict[str, Any] = {"synthetic": True, "source": SOURCE, "seed": seed,
                                "patients": []}
    for k, pat in enumerate(PATIENTS):
        pdir = base / pat.code
        pdir.mkdir(exist_ok=True)
        entry: dict[str, Any] = {"code": pat.code, "body_mass_kg": pat.body_mass_kg,
                                 "height_m": pat.height_m, "side": pat.side,
                                 "hypertonic": dict(pat.hypertonic), "sessions": []}
        pre_arm = Arm.from_params(pat.params())
        pos_p = scattered_positions(pre_arm, N_POSTURAL, rng)
        pos_k = scattered_positions(pre_arm, N_STIFFNESS, rng)
        given = treatment(pat, pat.params(), pat.post_weeks)
        entry["treatment"] = {"given_on": PRE_DATE.isoformat(), "after_session": POST_SESSION,
                              "weeks_to_after_session": pat.post_weeks,
                              "plan": dict(given.plan), "response": given.response}
        dates = {PRE_SESSION: PRE_DATE, POST_SESSION: pat.post_date}
        for label, params in ((PRE_SESSION, pat.params()), (POST_SESSION, given.after)):
            arm = Arm.from_params(params)
            sdir = pdir / label
            sdir.mkdir(exist_ok=True)
            (pdir / f"params-{label}.json").write_text(params.to_json() + "\n", encoding="utf-8")
            meta = {"patient": pat.code, "session": label, "synthetic": "yes",
                    "robot": "simulated 2-DOF planar manipulandum"}
            src = f"{SOURCE}; seed {seed}; patient {pat.code}; session {label}"
            post = _noisy(postural_map(arm, pos_p, source=src), FORCE_FLOOR_N, rng,
                          metadata=meta)
            stat = _noisy(stiffness_map(arm, pos_k, source=src), STIFFNESS_FLOOR_N_PER_M, rng,
                          metadata=meta)
            mov = _noisy(stiffness_map(arm, pos_k, pat.moving_velocity_m_per_s, source=src),
                         STIFFNESS_FLOOR_N_PER_M, rng, metadata=meta)
            files: list[dict[str, str]] = []
            rel = f"{pat.code}/{label}"

            def add(name: str, fmt: str, kinds: str, files: list[dict[str, str]] = files,
                    rel: str = rel) -> None:
                files.append({"file": f"{rel}/{name}", "format": fmt, "kinds": kinds})

            if label == PRE_SESSION:
                (sdir / "postural.csv").write_text(post.to_csv(), encoding="utf-8")
                add("postural.csv", "csv", "postural")
                if k % 2 == 0:
                    (sdir / "stiffness-static.csv").write_text(stat.to_csv(), encoding="utf-8")
                else:
                    (sdir / "stiffness-static.csv").write_text(lab_units_csv(stat),
                                                               encoding="utf-8")
                add("stiffness-static.csv", "csv", "stiffness")
                write_mat5(sdir / "stiffness-moving.mat", mov)
                add("stiffness-moving.mat", "mat5", "stiffness")
            else:
                (sdir / "postural-lab-units.csv").write_text(lab_units_csv(post),
                                                             encoding="utf-8")
                add("postural-lab-units.csv", "csv", "postural")
                write_mat73(sdir / "postural.mat", post)
                add("postural.mat", "mat73", "postural")
                write_hdf5(sdir / "stiffness.h5", [stat, mov])
                add("stiffness.h5", "hdf5", "stiffness,stiffness")
            entry["sessions"].append({"label": label, "date": dates[label].isoformat(),
                                      "params": f"{pat.code}/params-{label}.json",
                                      "files": files})
        manifest["patients"].append(entry)
    manifest["lab_exports"] = [_write_lab_export(base, seed)]
    (base / "manifest.json").write_text(json.dumps(manifest, indent=2) + "\n", encoding="utf-8")
    (base / "README.txt").write_text(
        "SYNTHETIC SAMPLE DATA - NOT PATIENT DATA.\n"
        f"Written by fieldbank.sampledata (seed {seed}): maps of made-up patients computed from "
        "the arm model with 5 % noise. manifest.json lists patients, sessions (with dates) and "
        "files, and the treatment each patient was given between the sessions; params-*.json "
        f"hold the true model parameters of each session. {PATIENTS[0].code}/{LAB_EXPORT} is "
        "the same arm's postural map as a lab's own software exports it (no metadata; columns "
        + ", ".join(LAB_EXPORT_COLUMNS.values()) + " in mm and N).\n",
        encoding="utf-8",
    )
    return manifest
