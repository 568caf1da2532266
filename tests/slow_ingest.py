"""Test program: an ingest that marks and pauses after each file it writes, so a test can kill
it in the middle of a batch.

    python tests/slow_ingest.py --db URL --arrays DIR --patient CODE --session LABEL
                                [--mark FILE] [--sleep-s S] FILES...

Each file is read and validated with :func:`fieldbank.ingest.read_file`, then the batch goes to
:meth:`fieldbank.storage.Database.ingest_files` with a progress callback that runs inside the
open transaction after each file is written: it appends the file's SHA-256 to FILE (flushed,
so the test sees it at once) and sleeps S seconds. Exit status 0 when the batch is stored,
2 when a file has problems (listed on stderr).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from fieldbank.ingest import read_file
from fieldbank.model import Arm
from fieldbank.storage import Database, IncomingFile, IngestOutcome


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--db", required=True, help="database URL")
    ap.add_argument("--arrays", required=True, help="array store directory")
    ap.add_argument("--patient", required=True)
    ap.add_argument("--session", required=True)
    ap.add_argument("--mark", type=Path, default=None,
                    help="append each written file's SHA-256 here")
    ap.add_argument("--sleep-s", type=float, default=0.0,
                    help="pause after each written file, s (inside the transaction)")
    ap.add_argument("files", nargs="+", type=Path)
    args = ap.parse_args(argv)

    def written(outcome: IngestOutcome) -> None:
        if args.mark is not None:
            with open(args.mark, "a", encoding="utf-8") as fh:
                fh.write(outcome.sha256 + "\n")
        if args.sleep_s > 0:
            time.sleep(args.sleep_s)

    with Database.open(args.db, store_root=args.arrays) as db:
        patient = db.get_patient(args.patient)
        arm = Arm.from_params(patient.arm_params())
        incoming: list[IncomingFile] = []
        for path in args.files:
            inc, problems = read_file(path.name, path.read_bytes(), arm, patient.code)
            if inc is None:
                print("\n".join(map(str, problems)), file=sys.stderr)
                return 2
            incoming.append(inc)
        db.ingest_files(patient.code, args.session, incoming, progress=written)
    return 0


if __name__ == "__main__":
    sys.exit(main())
