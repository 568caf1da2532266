"""Which C3D reader: fieldbank's own, the ``c3d`` package or ``ezc3d``, on real files.

For every C3D file in the real-file folder (``FIELDBANK_REALFILES``, else
``<repository>/../shared/realfiles``; its ``c3d/`` sub-folder when there is one), each reader
runs in its own process (a reader that crashes the process — a segmentation fault — is counted
as such, not taken down with the benchmark) and reports whether it read the file, its analog
array and its read time (median of 3 reads: wall and CPU). The analog values of every pair of
readers that both read a file are compared (largest difference over the largest value).

    .venv/bin/python benchmarks/bench_c3d_readers.py            # the table, Markdown
    .venv/bin/python benchmarks/bench_c3d_readers.py --json     # the same as JSON

The baseline is the ``c3d`` package, the reader fieldbank used before; time ratios are against
it on the files it reads. ``ezc3d`` is not a dependency: install it to include it
(``pip install ezc3d``), its column says "not installed" otherwise.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))

READERS = ("fieldbank", "c3d", "ezc3d")


def realfiles() -> list[Path]:
    base = Path(os.environ.get("FIELDBANK_REALFILES", ROOT.parent / "shared" / "realfiles"))
    folder = base / "c3d" if (base / "c3d").is_dir() else base
    return sorted(p for p in folder.iterdir() if p.suffix.lower() == ".c3d")


def _read(lib: str, path: str) -> object:
    """The analog array (channels, samples) as the library reads it."""
    import numpy as np

    data = Path(path).read_bytes()
    if lib == "fieldbank":
        from fieldbank.measure.c3dfile import read_c3d
        return read_c3d(data).analog
    if lib == "c3d":
        import io
        import warnings

        import c3d
        warnings.simplefilter("ignore")
        r = c3d.Reader(io.BytesIO(data))
        blocks = [a for _, _, a in r.read_frames()]
        return np.concatenate(blocks, axis=1) if blocks else np.zeros((0, 0))
    import ezc3d
    return np.asarray(ezc3d.c3d(path)["data"]["analogs"])[0]


def worker(lib: str, path: str, out: str) -> None:
    """Run in a child process: read three times, save the analog array, print the times."""
    import numpy as np

    walls, cpus = [], []
    arr = None
    for _ in range(3):
        w0, c0 = time.perf_counter(), time.process_time()
        arr = _read(lib, path)
        walls.append(time.perf_counter() - w0)
        cpus.append(time.process_time() - c0)
    np.save(out, np.asarray(arr, dtype=float))
    print(json.dumps({"wall": sorted(walls)[1], "cpu": sorted(cpus)[1]}))


def run(lib: str, path: Path, tmp: Path) -> dict[str, object]:
    if lib == "ezc3d":
        probe = subprocess.run([sys.executable, "-c", "import ezc3d"], capture_output=True)
        if probe.returncode:
            return {"status": "not installed"}
    out = tmp / f"{lib}-{path.stem}.npy"
    p = subprocess.run([sys.executable, __file__, "--worker", lib, str(path), str(out)],
                       capture_output=True, text=True, timeout=600)
    if p.returncode < 0:
        return {"status": f"crashed (signal {-p.returncode})"}
    if p.returncode:
        last = (p.stderr.strip().splitlines() or ["?"])[-1]
        return {"status": "failed: " + last[:90]}
    res: dict[str, object] = {"status": "read", **json.loads(p.stdout.strip().splitlines()[-1])}
    res["npy"] = str(out)
    return res


def main() -> None:
    import numpy as np
    from timing import load_line

    files = realfiles()
    rows = []
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        for path in files:
            row: dict[str, object] = {"file": path.name}
            arrays = {}
            for lib in READERS:
                r = run(lib, path, tmp)
                if "npy" in r:
                    arrays[lib] = np.load(str(r.pop("npy")))
                row[lib] = r
            for a, b in (("fieldbank", "c3d"), ("fieldbank", "ezc3d"), ("c3d", "ezc3d")):
                if a in arrays and b in arrays:
                    x, y = arrays[a], arrays[b]
                    if x.shape != y.shape:
                        row[f"{a}~{b}"] = f"shapes {x.shape} vs {y.shape}"
                    elif x.size == 0:
                        row[f"{a}~{b}"] = "both empty"
                    else:
                        scale = max(float(np.nanmax(np.abs(y))), 1e-30)
                        row[f"{a}~{b}"] = f"{float(np.nanmax(np.abs(x - y))) / scale:.1e}"
            rows.append(row)
    if "--json" in sys.argv:
        print(json.dumps({"load": load_line(), "files": rows}, indent=1))
        return
    print(f"{len(files)} C3D files; {load_line()}\n")
    print("| file | fieldbank | c3d | ezc3d | analog fieldbank~c3d | fieldbank~ezc3d |")
    print("|---|---|---|---|---|---|")

    def cell(r: dict[str, object]) -> str:
        if r["status"] != "read":
            return str(r["status"])
        return f"{float(r['cpu']) * 1e3:.1f} ms CPU"  # type: ignore[arg-type]

    for row in rows:
        print(f"| {row['file']} | {cell(row['fieldbank'])} | {cell(row['c3d'])} | "  # type: ignore[arg-type]
              f"{cell(row['ezc3d'])} | {row.get('fieldbank~c3d', '—')} | "  # type: ignore[arg-type]
              f"{row.get('fieldbank~ezc3d', '—')} |")
    print()
    for lib in READERS:
        ok = [r for r in rows if r[lib]["status"] == "read"]  # type: ignore[index]
        crashed = sum(str(r[lib]["status"]).startswith("crashed") for r in rows)  # type: ignore[index]
        both = [r for r in ok if r["c3d"]["status"] == "read"]  # type: ignore[index]
        cpu = sum(float(r[lib]["cpu"]) for r in both)  # type: ignore[index]
        wall = sum(float(r[lib]["wall"]) for r in both)  # type: ignore[index]
        base = sum(float(r["c3d"]["cpu"]) for r in both)  # type: ignore[index]
        ratio = f"{cpu / base:.2f}" if base > 0 and both else "—"
        print(f"{lib}: read {len(ok)} of {len(rows)}, crashed on {crashed}; on the {len(both)} "
              f"files c3d reads: {cpu:.3f} s CPU, {wall:.3f} s wall, CPU ratio to c3d {ratio}")


if __name__ == "__main__":
    if len(sys.argv) == 5 and sys.argv[1] == "--worker":
        worker(sys.argv[2], sys.argv[3], sys.argv[4])
    else:
        main()
