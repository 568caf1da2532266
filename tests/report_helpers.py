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
