"""Start-up time of the command line (issue: one-way layers ... and an instant command line).

Each command runs as a fresh process, as a user starts it, and its wall time is compared with
``python -c "import click"`` measured in the same run, interleaved round by round so that a
busy machine slows both alike. The commands:

* ``fieldbank --version`` and ``fieldbank --help``;
* ``fieldbank haptic switch B`` - the live command a clinician sends to a running renderer. No
  renderer runs here, so it exits with "no renderer" after the same imports and argument
  parsing it does in a session (the socket connect is what is left out);
* ``fieldbank haptic --help`` and, for contrast, ``fieldbank field --help`` (loads the model).

Target: ≤ 3x the ``import click`` baseline for --version, --help and haptic switch.
Run: python benchmarks/bench_cli_startup.py [--rounds N]
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TARGET_RATIO = 3.0


def _fieldbank() -> list[str]:
    exe = Path(sys.executable).with_name("fieldbank")
    if exe.exists():
        return [str(exe)]
    found = shutil.which("fieldbank")
    if found is None:
        raise SystemExit("the fieldbank command is not installed (run scripts/setup)")
    return [found]


def _time(cmd: list[str], env: dict[str, str]) -> float:
    t0 = time.perf_counter()
    subprocess.run(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                   check=False)
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=15)
    args = ap.parse_args()
    fb = _fieldbank()
    with tempfile.TemporaryDirectory() as home:
        env = {**os.environ, "FIELDBANK_HOME": home}
        sock = str(Path(home) / "no-renderer.sock")
        cases: dict[str, list[str]] = {
            'python -c "import click" (baseline)': [sys.executable, "-c", "import click"],
            "fieldbank --version": [*fb, "--version"],
            "fieldbank --help": [*fb, "--help"],
            "fieldbank haptic switch B": [*fb, "haptic", "switch", "B", "--socket", sock],
            "fieldbank haptic --help": [*fb, "haptic", "--help"],
            "fieldbank field --help (loads the model)": [*fb, "field", "--help"],
        }
        for cmd in cases.values():  # warm the file cache once
            _time(cmd, env)
        times: dict[str, list[float]] = {k: [] for k in cases}
        for _ in range(args.rounds):
            for name, cmd in cases.items():
                times[name].append(_time(cmd, env))
    base = statistics.median(next(iter(times.values())))
    print(f"{'command':<44} {'median ms':>10} {'x baseline':>11}")
    worst = 0.0
    for i, (name, ts) in enumerate(times.items()):
        med = statistics.median(ts)
        ratio = med / base
        if 1 <= i <= 3:
            worst = max(worst, ratio)
        print(f"{name:<44} {med * 1000:>10.1f} {ratio:>10.2f}x")
    verdict = "meets" if worst <= TARGET_RATIO else "MISSES"
    print(f"worst of --version, --help, haptic switch: {worst:.2f}x the baseline "
          f"({verdict} the {TARGET_RATIO:g}x target); {args.rounds} rounds")


if __name__ == "__main__":
    main()
