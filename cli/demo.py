"""``fieldbank demo``: the whole product once, on a fresh embedded database and the shipped
synthetic sample data - a tour composed of library calls.

Steps, each announced on stderr as it runs:

1. a fresh data directory (``FIELDBANK_HOME``) with the embedded SQLite database;
2. the shipped synthetic sample files (:mod:`fieldbank.sampledata`, not patient data);
3. ingest: each patient and both sessions (pre-BoNT, post-BoNT), dated as the manifest says;
4. fit: each patient's arm model to the pre-BoNT maps (:mod:`fieldbank.fitting`);
5. what-if: the botulinum plan each patient was given (150 U into each hypertonic group,
   recorded with the day it was given, so ``fieldbank validate`` checks it against the
   post-BoNT maps) and a lengthening plan (+1 cm of the first hypertonic group, only explored)
   on each fitted model, stored with lineage;
6. report: ``report.html``, ``metrics.csv``, ``metrics.json`` over every stored plan;
7. haptics: a short simulated side-by-side session (before and after, with a switch) on the
   simulated robot ``sim://``, traces stored.

:func:`populate` (steps 2-5) is also what the tests use to build a small stored batch.
"""

from __future__ import annotations

import shutil
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import date, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from fieldbank.errors import FieldbankError

if TYPE_CHECKING:  # typing only: the library loads when a command runs
    from fieldbank.interventions import Plan
    from fieldbank.storage import Database

Say = Callable[[str], None]

FIT_SESSION = "pre-BoNT"
LENGTHENING_M = 0.01
DB_FILE = "fieldbank.sqlite3"


def _quiet(msg: str) -> None:
    del msg


@dataclass
class DemoResult:
    home: Path
    db_url: str
    samples: Path
    report_dir: Path
    patients: list[str] = field(default_factory=list)
    fitted_models: dict[str, int] = field(default_factory=dict)
    plans: dict[str, list[int]] = field(default_factory=dict)
    haptic: dict[str, Any] | None = None
    timings_s: dict[str, float] = field(default_factory=dict)


def demo_plans(entry: dict[str, Any]) -> list[tuple[Plan, date | None]]:
    """A sample patient's plans with the day each was given: the botulinum plan of the
    manifest (given), and a lengthening of the first hypertonic group (only explored)."""
    from fieldbank.interventions import Lengthening, Plan

    groups = list(entry["hypertonic"])
    given = entry["treatment"]
    bot = Plan.from_dict(given["plan"], where=f"manifest, patient {entry['code']}")
    length = Plan.of(Lengthening(group=groups[0], delta_m=LENGTHENING_M),
                     label=f"lengthening of {groups[0]} by {LENGTHENING_M * 100:g} cm")
    return [(bot, date.fromisoformat(given["given_on"])), (length, None)]


def populate(db: Database, samples: Path, patients: Sequence[str] | None = None,
             say: Say = _quiet, seed: int = 0) -> dict[str, Any]:
    """Write the samples, ingest, fit and store both plans for each (chosen) sample patient.

    The plans are stored as ``fieldbank whatif PATIENT ... --save`` stores them: the after
    model has origin 'intervention' and the fitted model as its parent.
    Returns {'patients': [...], 'fitted_models': {code: id}, 'plans': {code: [ids]}}.
    """
    from fieldbank import modelsource
    from fieldbank.fitting import ArmFitter
    from fieldbank.fitting.dbstore import DatabaseFitStore
    from fieldbank.fitting.records import fit_patient
    from fieldbank.ingest import ingest_paths
    from fieldbank.interventions.samples import write_samples
    from fieldbank.interventions.whatif import save_plan

    manifest = write_samples(samples)
    say(f"wrote the synthetic sample files to {samples} (see its README.txt; not patient data)")
    out: dict[str, Any] = {"patients": [], "fitted_models": {}, "plans": {}}
    chosen = [p for p in manifest["patients"] if patients is None or p["code"] in patients]
    if not chosen:
        raise FieldbankError(f"none of {list(patients or [])} is a sample patient.")
    for p in chosen:
        code = p["code"]
        db.add_patient(code, p["body_mass_kg"], p["height_m"], p["side"],
                       notes="synthetic sample patient (not patient data)")
        for s in p["sessions"]:
            files = [samples / f["file"] for f in s["files"]]
            rep = ingest_paths(db, files, code, s["label"], date.fromisoformat(s["date"]))
            say(f"ingested {rep.n_stored} file(s) for {code} / {s['label']} "
                f"({', '.join(sorted({f['format'] for f in s['files']}))})")
        out["patients"].append(code)
    store = DatabaseFitStore(db)
    for code in out["patients"]:
        t0 = time.perf_counter()
        fit = fit_patient(store, code, FIT_SESSION, ArmFitter(seed=seed))
        f = fit.fitter
        say(f"fitted {code} to {len(f.maps_)} {FIT_SESSION} maps: model "
            f"{fit.saved.model_id}, R² " + ", ".join(f"{r:.3f}" for r in f.r2_)
            + f" ({time.perf_counter() - t0:.1f} s)")
        out["fitted_models"][code] = int(fit.saved.model_id)
    for p in chosen:
        code = p["code"]
        source = modelsource.stored(db, out["fitted_models"][code])
        ids = []
        for plan, given_on in demo_plans(p):
            saved = save_plan(db, source, plan, given_on=given_on)
            ids.append(saved.plan_id)
            say(f"what-if for {code}: {plan.label} -> after model {saved.result_model_id}, "
                f"plan {saved.plan_id}" + (f", given on {given_on}" if given_on else ""))
        out["plans"][code] = ids
    return out


def run_demo(out_dir: str | Path, home: str | Path | None = None, force: bool = False,
             jobs: int | None = None, haptic_s: float = 3.0, say: Say = _quiet) -> DemoResult:
    """Run every step (module docstring) under ``out_dir``; returns what was made."""
    from fieldbank.engine import default_jobs
    from fieldbank.interventions.report import Selection, build_report
    from fieldbank.storage import Database

    out = Path(out_dir)
    h = Path(home) if home is not None else out / "home"
    if h.exists() and any(h.iterdir()) and not force:
        raise FieldbankError(
            f"{h} is not empty: the demo starts from a fresh database. Remove it, choose "
            "another --out/--home, or give --force to delete the demo's files there.")
    if force and h.exists():
        _clear_demo_home(h)
    h.mkdir(parents=True, exist_ok=True)
    url = f"sqlite:///{(h / DB_FILE).resolve()}"
    res = DemoResult(h, url, out / "samples", out / "report")
    t = time.perf_counter()
    say(f"[1/7] fresh embedded database {h / DB_FILE} (FIELDBANK_HOME={h})")
    with Database.open(url) as db:
        say("[2-5/7] samples, ingest, fit, what-if")
        pop = populate(db, res.samples, say=say)
        res.patients, res.fitted_models, res.plans = (pop["patients"], pop["fitted_models"],
                                                      pop["plans"])
        res.timings_s["populate"] = time.perf_counter() - t
        t = time.perf_counter()
        say("[6/7] report over every stored plan")
        rep = build_report(db, Selection(), res.report_dir, jobs=jobs or default_jobs(), force=True,
                           progress=True, title="fieldbank demo report",
                           stamp=datetime.now().astimezone().isoformat(timespec="seconds"))
        res.timings_s["report"] = time.perf_counter() - t
        say(f"wrote {rep.html} ({rep.n_cases} cases, {rep.jobs_used} process(es)), "
            f"{rep.csv.name}, {rep.json.name}")
        t = time.perf_counter()
        say("[7/7] simulated side-by-side haptic session")
        first = res.patients[0]
        # the lengthening plan: its change is felt at rest as well as in motion
        res.haptic = run_haptic(db, first, res.fitted_models[first], res.plans[first][-1],
                                haptic_s, say)
        res.timings_s["haptic"] = time.perf_counter() - t
    return res


def run_haptic(db: Database, patient: str, before_id: int, plan_id: int, duration_s: float,
               say: Say) -> dict[str, Any]:
    """A short before/after session on the simulated robot.

    The simulated operator explores around the rest hand position at 1 kHz (real time) while
    the renderer shows the model before (A), crossfades to the model after (B) halfway and
    back for the last quarter. The trace goes to the database (``haptic_sessions``, traces in
    the array store).
    """
    from fieldbank.haptic import session
    from fieldbank.haptic.rendererconfig import RendererConfig

    before = db.get_model(before_id).params
    plan = db.get_plan(plan_id)
    after = db.get_model(plan.result_model_id).params
    say(f"rendering {patient} before (A, model {before_id}) and after plan {plan_id} (B, model "
        f"{plan.result_model_id}) for {duration_s:g} s at 1 kHz on the simulated robot")
    res = session.serve(
        "sim://?mode=realtime", before, after, model_ids=(before_id, plan.result_model_id),
        patient_code=patient, duration_s=duration_s,
        config=RendererConfig(rate_hz=1000, crossfade_s=0.5), control=False,
        switches=(session.ScheduledSwitch(0.4 * duration_s, "B"),
                  session.ScheduledSwitch(0.75 * duration_s, "A")),
        trace_name=f"demo-{patient}-plan-{plan_id}", db=db, say=say)
    trace, ref = res.trace, res.database
    summ = trace.summary()
    st = trace.stats.get("period_error_us", {})
    say(f"haptic session: {summ['ticks']} ticks, max force {summ['max_force_n']:.2f} N, "
        f"{len(trace.faults)} fault(s), period error p99 {st.get('p99', 0):.0f} µs; "
        f"recorded as {ref}")
    return {"ticks": summ["ticks"], "max_force_n": summ["max_force_n"],
            "faults": len(trace.faults), "record": ref,
            "switches": [e for e in trace.events if e.get("event") == "switch"]}


def _clear_demo_home(h: Path) -> None:
    """Remove what a previous demo left in ``h``: its database and array store, and what
    fieldbank's commands wrote into that data directory while the README's tours ran on it
    (haptic trace files, a stale control socket, database backups). Anything else is refused
    by name, with the way out."""
    known = {DB_FILE, f"{DB_FILE}-wal", f"{DB_FILE}-shm", f"{DB_FILE}-journal",
             f"{DB_FILE}.arrays", "traces", "haptic.sock", "backups"}
    strangers = sorted(p.name for p in h.iterdir() if p.name not in known
                       and not p.name.startswith(f"{DB_FILE}.backup-"))
    if strangers:
        raise FieldbankError(
            f"{h} holds files neither the demo nor fieldbank wrote ({', '.join(strangers)}); "
            "not deleting them. Move them out of it, or run the demo elsewhere: "
            "'fieldbank demo --out OTHER' (or --home OTHER).")
    for p in h.iterdir():
        if p.is_dir():
            shutil.rmtree(p)
        else:
            p.unlink()


@click.command("demo")
@click.option("--out", "out_dir", default="demo-out", show_default=True,
              type=click.Path(file_okay=False), help="Directory for everything the demo writes.")
@click.option("--home", default=None, type=click.Path(file_okay=False),
              help="Data directory of the fresh database (default: OUT/home).")
@click.option("--force", is_flag=True,
              help="Start over in a data directory a previous demo left behind.")
@click.option("--jobs", type=click.IntRange(min=1), default=None,
              help="Worker processes for the report (default: the cores available).")
@click.option("--haptic-seconds", type=click.FloatRange(min=0.5, max=30.0), default=3.0,
              show_default=True, help="Length of the simulated haptic session.")
def demo(out_dir: str, home: str | None, force: bool, jobs: int | None,
         haptic_seconds: float) -> None:
    """Run the whole product once on synthetic sample data, saying what it does."""
    t0 = time.perf_counter()

    def say(msg: str) -> None:
        click.echo(f"[{time.perf_counter() - t0:5.1f} s] {msg}", err=True)

    res = run_demo(out_dir, home, force, jobs, haptic_seconds, say)
    say(f"done: report {res.report_dir / 'report.html'}; database {res.home}; "
        f"total {time.perf_counter() - t0:.1f} s")
    click.echo(f"next: FIELDBANK_HOME={res.home} fieldbank report --kind botulinum "
               f"--out {res.report_dir}-botulinum", err=True)
    click.echo(f"      FIELDBANK_HOME={res.home} fieldbank validate   (the given plans against "
               "the post-BoNT maps)", err=True)
