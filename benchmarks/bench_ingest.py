"""Ingest and listing speed on SQLite.

Writes 1,000 synthetic postural/stiffness map CSV files (25 and 9 points) for 20 patients (50
maps each, two sessions), ingests them into a fresh SQLite database (one batch per patient and
session; validation against the patient's arm included) and prints files/s; then the median time
to list one patient's maps (targets: 1,000 files in ≤ 30 s; listing ≤ 5 ms median). For scale
it also times reading the same files without storing them (the baseline), ingesting all 1,000
as a single batch for one patient, and listing that patient's 1,000 maps.

    python benchmarks/bench_ingest.py [--files 1000]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fieldbank.ingest import ingest_paths, read_file
from fieldbank.maps import postural_map, stiffness_map
from fieldbank.model import Arm
from fieldbank.sampledata import scattered_positions
from fieldbank.storage import Database


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--files", type=int, default=1000)
    ap.add_argument("--list-repeats", type=int, default=200)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        db = Database.open(f"sqlite:///{root / 'bench.sqlite3'}")
        n_pat = 20
        per = args.files // n_pat
        patients = [db.add_patient(f"BENCH-{i:02d}", 75.0, 1.75, "right") for i in range(n_pat)]
        arm = Arm.from_params(patients[0].arm_params())
        rng = np.random.default_rng(1)
        files = []
        t0 = time.perf_counter()
        (root / "in").mkdir()
        for i in range(per * n_pat):
            if i % 3 == 2:
                m = stiffness_map(arm, scattered_positions(arm, 9, rng), source=f"bench {i}")
            else:
                m = postural_map(arm, scattered_positions(arm, 25, rng), source=f"bench {i}")
            f = root / "in" / f"map{i:05d}.csv"
            f.write_text(m.to_csv())
            files.append(f)
        t_gen = time.perf_counter() - t0

        t0 = time.perf_counter()
        for f in files:
            read_file(f.name, f.read_bytes(), arm, "BENCH-00")
        t_read = time.perf_counter() - t0

        t0 = time.perf_counter()
        for k, p in enumerate(patients):
            mine = files[k * per:(k + 1) * per]
            half = len(mine) // 2
            ingest_paths(db, mine[:half], p.code, "pre-BoNT")
            ingest_paths(db, mine[half:], p.code, "post-BoNT")
        t_ingest = time.perf_counter() - t0
        assert len(db.list_maps()) == len(files)
        t_list = _median_time(lambda: db.list_maps("BENCH-07"), args.list_repeats)
        db.close()

        db1 = Database.open(f"sqlite:///{root / 'one.sqlite3'}")
        db1.add_patient("ONE", 75.0, 1.75, "right")
        t0 = time.perf_counter()
        rep = ingest_paths(db1, files, "ONE", "bench")
        t_one = time.perf_counter() - t0
        assert rep.n_stored == len(files)
        t_list_all = _median_time(lambda: db1.list_maps("ONE"), args.list_repeats)
        db1.close()
    n = len(files)
    print(f"generated {n} files in {t_gen:.2f} s")
    print(f"baseline, read+validate only: {t_read:.2f} s ({n / t_read:.0f} files/s)")
    print(f"ingest {n} files into SQLite ({2 * n_pat} batches): {t_ingest:.2f} s "
          f"({n / t_ingest:.0f} files/s; target ≤ 30 s; {t_ingest / t_read:.2f}× baseline)")
    print(f"ingest {n} files into SQLite (1 batch): {t_one:.2f} s ({n / t_one:.0f} files/s)")
    print(f"list one patient's maps ({per} of {n}): median {t_list * 1e3:.2f} ms "
          "(target ≤ 5 ms)")
    print(f"list a patient with all {n} maps: median {t_list_all * 1e3:.2f} ms")


def _median_time(fn: Callable[[], object], repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


if __name__ == "__main__":
    main()
