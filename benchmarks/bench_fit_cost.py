"""What one patient's fit costs: the compiled evaluation against the reference path, same run.

For a few virtual patients with known truth (:mod:`fieldbank.fitting.synthetic`: 25 postural
positions and 9 stiffness positions static and at ±1 m/s, 5 % noise), three figures, CPU time
(this process, all threads) beside wall time:

* **fit + uncertainty** - ``ArmFitter().fit(maps, base)`` with every default (the search, the
  hold of what the maps leave open, the attribution, the prior ranges, the uncertainty 'auto'
  - a parametric bootstrap of 40 replicates wherever the Gauss-Newton estimate does not hold -
  and the severity grades); target ≤ 0.6 s CPU;
* **fit, Gauss-Newton only** - the same with ``uncertainty='gauss-newton'`` (no bootstrap);
* **search alone** - :func:`fieldbank.fitting.search.run_nlopt` on the patient's problem (the
  global search, the polish and the coordinate scans); target ≤ 0.2 s CPU.

The baseline is the reference path of the same code (:func:`fieldbank.fitting.reference.
reference_kernels`: the numpy evaluation of the cost the compiled kernels replaced), run in
this process on the same patients, so the ratio is the gain of the kernels alone. Each figure
is the median of ``--repeat`` runs after one warm-up; the optimum's cost of both paths is
printed beside it (they must agree).

``--profile`` adds cProfile's top ten functions by cumulative and by own time for one default
fit of the first patient, on each path.

    python benchmarks/bench_fit_cost.py [--repeat 3] [--profile]
"""

from __future__ import annotations

import argparse
import cProfile
import io
import os
import pstats
import statistics
import sys
import time
from collections.abc import Callable

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import numpy as np
from timing import load_line, per_call

from fieldbank.fitting import ArmFitter
from fieldbank.fitting.fitter import validate_maps
from fieldbank.fitting.problem import FitProblem
from fieldbank.fitting.reference import reference_kernels
from fieldbank.fitting.search import run_nlopt
from fieldbank.fitting.space import ParamSpace
from fieldbank.fitting.synthetic import impaired_params, synthetic_patient
from fieldbank.maps import FieldMap
from fieldbank.model import Arm
from fieldbank.params import ArmParams

#: The virtual patients: (group, level, seed).
PATIENTS = (("elbow", "severe", 0), ("shoulder", "moderate", 1), ("elbow", "mild", 2))
TARGET_FIT_S = 0.6
TARGET_SEARCH_S = 0.2


def measure(fn: Callable[[], float], repeat: int) -> tuple[float, float, float]:
    """(median CPU s, median wall s, the cost ``fn`` returned) over ``repeat`` calls after one
    warm-up."""
    fn()
    cpus, walls = [], []
    cost = float("nan")
    for _ in range(repeat):
        c0, w0 = time.process_time(), time.perf_counter()
        cost = fn()
        cpus.append(time.process_time() - c0)
        walls.append(time.perf_counter() - w0)
    return statistics.median(cpus), statistics.median(walls), cost


def cases(maps: tuple[FieldMap, ...], base: ArmParams,
          seed: int) -> dict[str, Callable[[], float]]:
    def fit(method: str) -> Callable[[], float]:
        return lambda: ArmFitter(seed=seed, uncertainty=method).fit(maps, base).cost_

    def search() -> float:
        arm = Arm.from_params(base)
        problem = FitProblem.from_maps(validate_maps(maps, arm), arm, ParamSpace.build(base))
        return run_nlopt(problem, "mlsl+lbfgs", seed, None).cost

    return {"fit + uncertainty": fit("auto"), "fit, Gauss-Newton only": fit("gauss-newton"),
            "search alone": search}


def per_evaluation(base: ArmParams) -> None:
    """CPU µs of one projected evaluation, and of one with its gradient, on each path."""
    maps = synthetic_patient(impaired_params("elbow", "severe", base), seed=0).maps
    arm = Arm.from_params(base)
    used = validate_maps(maps, arm)
    with reference_kernels():
        ref = FitProblem.from_maps(used, arm, ParamSpace.build(base))
    new = FitProblem.from_maps(used, arm, ParamSpace.build(base))
    phi = np.full(6, 0.5)
    theta = new.full_from_nonlinear(phi)
    got = {}
    for name, p in (("reference", ref), ("compiled", new)):
        got[name] = (per_call(lambda p=p: p.project(theta), 2000, 3)[1],
                     per_call(lambda p=p: p.projected_cost_grad(phi), 1000, 3)[1])
    (r1, r2), (c1, c2) = got["reference"], got["compiled"]
    print(f"one evaluation (elbow severe, beta 0.5), CPU: project {r1:.0f} -> {c1:.0f} us "
          f"({r1 / c1:.1f}x); with its gradient {r2:.0f} -> {c2:.0f} us ({r2 / c2:.1f}x)")


def top10(fn: Callable[[], object]) -> str:
    prof = cProfile.Profile(time.process_time)  # CPU time: the machine is shared
    prof.enable()
    fn()
    prof.disable()
    out = []
    for key in ("cumulative", "tottime"):
        buf = io.StringIO()
        st = pstats.Stats(prof, stream=buf)
        st.sort_stats(key).print_stats(10)
        text = buf.getvalue()
        here = os.path.dirname(os.path.dirname(os.path.abspath(__file__))) + os.sep
        text = text.replace(here, "").replace("benchmarks/.." + os.sep, "")
        text = text.replace(sys.prefix + os.sep, "")
        lines = [ln for ln in text.splitlines() if ln.strip()]
        out.append(f"-- by {key} time --\n" + "\n".join(lines[-12:]))
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--profile", action="store_true")
    ap.add_argument("--evaluation-only", action="store_true",
                    help="only the cost of one evaluation on each path")
    args = ap.parse_args()
    base = ArmParams.from_anthropometry()
    print(load_line())
    per_evaluation(base)
    if args.evaluation_only:
        return
    print(f"{'patient':<18} {'figure':<24} {'reference CPU':>13} {'compiled CPU':>12} "
          f"{'ratio':>6} {'ref wall':>8} {'wall':>6}  cost ref / compiled")
    worst = {"fit + uncertainty": 0.0, "search alone": 0.0}
    for group, level, seed in PATIENTS:
        patient = synthetic_patient(impaired_params(group, level, base), seed=seed)
        todo = cases(patient.maps, base, seed)
        for name, fn in todo.items():
            with reference_kernels():
                ref = measure(fn, args.repeat)
            new = measure(fn, args.repeat)
            if name in worst:
                worst[name] = max(worst[name], new[0])
            print(f"{group + ' ' + level:<18} {name:<24} {ref[0]:12.3f}s {new[0]:11.3f}s "
                  f"{ref[0] / new[0]:5.1f}x {ref[1]:7.3f}s {new[1]:5.3f}s  "
                  f"{ref[2]:.6g} / {new[2]:.6g}")
    print(load_line())
    fit_s, search_s = worst["fit + uncertainty"], worst["search alone"]
    print(f"targets (CPU, worst patient): fit + uncertainty {fit_s:.3f} s <= {TARGET_FIT_S} s: "
          f"{'met' if fit_s <= TARGET_FIT_S else 'MISSED'}; search {search_s:.3f} s <= "
          f"{TARGET_SEARCH_S} s: {'met' if search_s <= TARGET_SEARCH_S else 'MISSED'}")
    if args.profile:
        group, level, seed = PATIENTS[0]
        patient = synthetic_patient(impaired_params(group, level, base), seed=seed)
        fn = cases(patient.maps, base, seed)["fit + uncertainty"]
        with reference_kernels():
            fn()
            print(f"\n== profile, reference path: one default fit ({group} {level}) ==")
            print(top10(fn))
        fn()
        print(f"\n== profile, compiled path: one default fit ({group} {level}) ==")
        print(top10(fn))


if __name__ == "__main__":
    main()
