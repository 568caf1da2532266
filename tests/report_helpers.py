"""Shared set-up of the report tests: a small stored batch built by the real flow."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
from click.testing import CliRunner, Result

from fieldbank.interventions.catalogue import (
    Botulinum,
    Lengthening,
    Rhizotomy,
    SerialCasting,
    Tenotomy,
)


def build_batch(root: Path, patients: tuple[str, ...] = ("SYN-001", "SYN-002")) -> dict[str, Any]:
    """Samples → ingest → fit → botulinum and lengthening plans, on a SQLite file under root."""
    from fieldbank.cli.demo import populate
    from fieldbank.storage import Database

    url = f"sqlite:///{root / 'db' / 'fieldbank.sqlite3'}"
    with Database.open(url) as db:
        info = populate(db, root / "samples", patients=patients)
    info["url"] = url
    return info


#: Plans of the synthetic cohort, in turn: botulinum into a flexor and into an extensor group
#: come first, so any cohort of two or more has both.
COHORT_PLANS = (
    ("botulinum ef", lambda: Botulinum({"ef": 150.0})),
    ("botulinum ee", lambda: Botulinum({"ee": 150.0})),
    ("lengthening bf", lambda: Lengthening(group="bf", delta_m=0.01)),
    ("botulinum sf+ef", lambda: Botulinum({"sf": 100.0, "ef": 100.0})),
    ("rhizotomy", lambda: Rhizotomy()),
    ("casting ef", lambda: SerialCasting(group="ef")),
    ("tenotomy be", lambda: Tenotomy(group="be")),
    ("botulinum se", lambda: Botulinum({"se": 200.0})),
)
#: Synthetic hypertonia of the cohort's patients, in turn.
COHORT_SEVERITIES = (
    {"elbow": "severe"}, {"elbow": "moderate", "shoulder": "mild"},
    {"biarticular": "severe"}, {"shoulder": "moderate", "elbow": "mild"},
    {"elbow-flexors:dynamic": "severe"}, {"elbow": "mild"},
)


def store_cohort(db: Any, n: int, seed: int = 7) -> list[int]:
    """N synthetic patients (no fits: models synthesized from COHORT_SEVERITIES), each with
    one stored plan from COHORT_PLANS, in turn; body size drawn from a seeded generator.
    Returns the plan ids."""
    from fieldbank.evaluate.severity import parse_severity_options, synthesize
    from fieldbank.interventions import Plan
    from fieldbank.params import ArmParams

    rng = np.random.default_rng(seed)
    ids = []
    for i in range(n):
        code = f"SYN-C{i:03d}"
        mass, height = float(rng.uniform(50, 95)), float(rng.uniform(1.5, 1.95))
        side = ("right", "left")[i % 2]
        db.add_patient(code, round(mass, 1), round(height, 2), side, notes="synthetic")
        sev = COHORT_SEVERITIES[i % len(COHORT_SEVERITIES)]
        p = synthesize(parse_severity_options([",".join(f"{k}={v}" for k, v in sev.items())]),
                       ArmParams.from_anthropometry(mass, height, side))
        base = db.add_model(p, "synthetic", "synthetic " + ", ".join(
            f"{k} {v}" for k, v in sev.items()), code)
        label, step = COHORT_PLANS[i % len(COHORT_PLANS)]
        plan = Plan.of(step(), label=label)
        after, lineage = plan.derive(p)
        child = db.add_model(after, "intervention", plan.label, code, parent_id=base.id)
        ids.append(db.add_plan(base.id, child.id, lineage.to_dict(), label=plan.label,
                               patient_code=code).id)
    return ids


def run_cli(*args: str) -> Result:
    from fieldbank.cli.main import cli

    return CliRunner().invoke(cli, list(args), catch_exceptions=False)


def svg_paths(svg: str, **attrs: str) -> list[list[np.ndarray]]:
    """The polylines (px) of every ``<path>`` of an SVG whose ``data-*`` attributes match
    ``attrs`` (``curve="fast after"`` matches ``data-curve="fast after"``)."""
    out = []
    for m in re.finditer(r"<path\b([^>]*)/?>", svg):
        tag = m.group(1)
        if not all(f'data-{k.replace("_", "-")}="{v}"' in tag for k, v in attrs.items()):
            continue
        d = re.search(r'\bd="([^"]*)"', tag)
        assert d is not None, tag
        out.append(decode_path(d.group(1)))
    return out


def decode_path(d: str) -> list[np.ndarray]:
    """Polylines of compact path data (M x y, l dx dy ..., h, v, z), px."""
    lines: list[list[list[float]]] = []
    tokens = re.findall(r"[MlhvzZ]|-?(?:\d+\.?\d*|\.\d+)", d)
    cmd, i, x, y = "", 0, 0.0, 0.0
    while i < len(tokens):
        t = tokens[i]
        if t in "MlhvzZ":
            cmd = t
            i += 1
            if t in "zZ":
                lines[-1].append(list(lines[-1][0]))
            continue
        if cmd == "M":
            x, y = float(tokens[i]), float(tokens[i + 1])
            lines.append([[x, y]])
            i += 2
            cmd = "l"
        elif cmd == "l":
            x, y = x + float(tokens[i]), y + float(tokens[i + 1])
            lines[-1].append([x, y])
            i += 2
        elif cmd == "h":
            x += float(tokens[i])
            lines[-1].append([x, y])
            i += 1
        elif cmd == "v":
            y += float(tokens[i])
            lines[-1].append([x, y])
            i += 1
        else:
            raise ValueError(f"unexpected token {t!r} in {d[:80]!r}")
    return [np.array(p) for p in lines]


def store_fitted_cohort(db: Any, n: int, templates: int = 6, seed: int = 7) -> list[int]:
    """N patients with fitted models, one stored plan each (COHORT_PLANS in turn), as a clinic
    holds them: maps of a 'pre' and a 'post' session, a fit of the 'pre' maps with its
    parameter samples, the plan recorded as given between the two sessions (so a report
    checks it against the 'post' maps). ``templates`` patients (COHORT_SEVERITIES in turn) are
    fitted for real; the others are their namesakes - the same body, maps, fit report and
    samples, stored as their own patient, maps, fitted model and fit - so that a cohort of a
    hundred costs a few fits to build. Returns the plan ids."""
    from datetime import date

    from fieldbank import modelsource
    from fieldbank.fitting.dbstore import DatabaseFitStore
    from fieldbank.fitting.fitter import ArmFitter
    from fieldbank.fitting.records import fit_patient
    from fieldbank.interventions import Plan
    from fieldbank.interventions.whatif import save_plan
    from tests.cohort_helpers import ingest_maps, store_sessions

    pairs = store_sessions(db, templates, seed=seed, prefix="FIT")
    codes = list(dict.fromkeys(code for code, _ in pairs))
    fits = {}
    for code in codes:
        out = fit_patient(DatabaseFitStore(db), code, "pre", ArmFitter(seed=0))
        fits[code] = (out.fitter.params_, dict(out.record.report))
    ids = []
    for i in range(n):
        template = codes[i % templates]
        if i < templates:
            code = template
            model_id = int(db.list_models(code, origin="fitted")[-1].id)
        else:
            code = f"FIT-C{i:04d}"
            t = db.get_patient(template)
            db.add_patient(code, t.body_mass_kg, t.height_m, t.side, notes="synthetic")
            for label in ("pre", "post"):
                stored = db.list_maps(template, label)
                when = stored[0].session_date
                ingest_maps(db, code, label, db.get_maps([m.id for m in stored]), when)
            map_ids = [m.id for m in db.list_maps(code, "pre")]
            params, report = fits[template]
            report = {**report, "patient": code, "map_ids": map_ids}
            model, _ = db.add_fitted_model(params, f"fit of {len(map_ids)} maps", code,
                                           report["algorithm"], report["seed"],
                                           report["n_evals"], report["time_s"],
                                           report["cost"], report, map_ids,
                                           session_label="pre")
            model_id = int(model.id)
        label, step = COHORT_PLANS[i % len(COHORT_PLANS)]
        saved = save_plan(db, modelsource.stored(db, model_id), Plan.of(step(), label=label),
                          given_on=date(2024, 1, 20), accept_poor_fit=True)
        ids.append(saved.plan_id)
    return ids
