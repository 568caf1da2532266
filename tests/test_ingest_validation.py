"""Every class of bad file is rejected with a located message, and nothing is written."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from fieldbank.errors import ValidationError
from fieldbank.ingest import ingest_paths, write_hdf5, write_mat5
from fieldbank.maps import postural_map
from fieldbank.model import Arm
from fieldbank.storage import Database

ROOT = Path(__file__).resolve().parents[1]
HEAD = "# kind: postural\n# frame: shoulder\n# sign: arm-on-handle\n# source: lab\n"
GOOD_ROWS = "0.05,0.40,1.0,-0.5\n0.10,0.35,0.5,0.2\n"
COLS = "x_m,y_m,fx_n,fy_n\n"

BAD_CSV = {
    "missing column": (HEAD + "x_m,y_m,fx_n\n0.05,0.40,1.0\n", "row 5", "missing column for fy"),
    "unknown column": (HEAD + "x_m,y_m,fx_n,fy_n,temp_c\n0.05,0.40,1,2,3\n", "row 5",
                       "unknown column 'temp_c'"),
    "non-number": (HEAD + COLS + "0.05,0.40,abc,1\n", "row 6", "'abc' is not a number"),
    "nan": (HEAD + COLS + "0.05,0.40,nan,1\n", "row 6", "NaN"),
    "inf": (HEAD + COLS + "0.05,0.40,inf,1\n", "row 6", "infinite"),
    "duplicate position": (HEAD + COLS + "0.05,0.40,1,1\n0.10,0.35,1,1\n0.05,0.40,2,2\n",
                           "row 8", "duplicate position"),
    "unreachable": (HEAD + COLS + "0.05,0.40,1,1\n0.90,0.90,1,1\n", "row 7", "out of reach"),
    "unknown unit": (HEAD + "x_furlong,y_m,fx_n,fy_n\n1,0.4,1,1\n", "row 5",
                     "unknown unit 'furlong'"),
    "unknown force unit": (HEAD + "x_m,y_m,fx_stone,fy_n\n0.05,0.4,1,1\n", "row 5",
                           "unknown unit 'stone'"),
    "missing kind": ("# frame: shoulder\n# sign: arm-on-handle\n" + COLS + GOOD_ROWS, "bad.csv",
                     "missing 'kind'"),
    "missing frame": ("# kind: postural\n# sign: arm-on-handle\n" + COLS + GOOD_ROWS,
                      "bad.csv", "missing 'frame'"),
    "missing sign": ("# kind: postural\n# frame: shoulder\n" + COLS + GOOD_ROWS, "bad.csv",
                     "missing 'sign'"),
    "unknown sign": ("# kind: postural\n# frame: shoulder\n# sign: pushing\n" + COLS + GOOD_ROWS,
                     "bad.csv", "unknown sign 'pushing'"),
    "stiffness without velocity": (
        "# kind: stiffness\n# frame: shoulder\n# sign: arm-on-handle\n"
        "x_m,y_m,kxx_n_per_m,kxy_n_per_m,kyx_n_per_m,kyy_n_per_m\n0.05,0.4,1,2,3,4\n",
        "bad.csv", "missing 'velocity_m_per_s'"),
    "speed without direction": (
        "# kind: stiffness\n# frame: shoulder\n# sign: arm-on-handle\n# velocity_m_per_s: 0.2\n"
        "x_m,y_m,kxx_n_per_m,kxy_n_per_m,kyx_n_per_m,kyy_n_per_m\n0.05,0.4,1,2,3,4\n",
        "bad.csv", "no direction"),
    "ragged row": (HEAD + COLS + "0.05,0.40,1\n", "row 6", "3 fields, the header has 4"),
    "no rows": (HEAD + COLS, "bad.csv", "no data rows"),
    "negative sd": (HEAD + "x_m,y_m,fx_n,fy_n,sd_fx_n,sd_fy_n\n0.05,0.40,1,1,-1,1\n", "row 6",
                    "negative"),
}


@pytest.fixture
def db(tmp_path: Path):
    d = Database.open(f"sqlite:///{tmp_path / 'v.sqlite3'}", store_root=tmp_path / "arrays")
    d.add_patient("V-1", 75, 1.75, "right")
    yield d
    d.close()


def _state(db: Database) -> tuple:
    return (db.list_maps(), db.list_sessions(), len(db.audit_entries()),
            sorted(db.store.keys()))


def _rejects(db: Database, paths: list[Path]) -> ValidationError:
    before = _state(db)
    with pytest.raises(ValidationError) as info:
        ingest_paths(db, paths, "V-1", "s1")
    assert _state(db) == before
    assert "Nothing was stored" in str(info.value)
    return info.value


@pytest.mark.parametrize("case", sorted(BAD_CSV))
def test_bad_csv_is_rejected_with_location(db: Database, tmp_path: Path, case: str) -> None:
    text, where, reason = BAD_CSV[case]
    path = tmp_path / "bad.csv"
    path.write_text(text)
    good = tmp_path / "good.csv"
    good.write_text(HEAD + COLS + GOOD_ROWS)
    err = _rejects(db, [good, path])  # a good file in the batch is not stored either
    hits = [p for p in err.problems if reason in p.reason]
    assert hits, [str(p) for p in err.problems]
    assert any(where in p.location and p.location.startswith("bad.csv") for p in hits)
    assert not any(p.location.startswith("good.csv") for p in err.problems)


def test_every_problem_in_a_file_is_reported(db: Database, tmp_path: Path) -> None:
    path = tmp_path / "many.csv"
    path.write_text("# frame: elbow\n# sign: arm-on-handle\n" + COLS
                    + "0.05,0.40,x,1\n0.05,0.40,1,nan\n2,2,1,1\n")
    err = _rejects(db, [path])
    reasons = " | ".join(str(p) for p in err.problems)
    for piece in ("missing 'kind'", "unknown frame 'elbow'", "'x' is not a number",
                  "row 5: NaN", "duplicate position", "row 6: position (2, 2) m is out of reach"):
        assert piece in reasons, reasons


def test_bad_hdf5_and_mat_are_rejected(db: Database, tmp_path: Path) -> None:
    arm = Arm.from_params(db.get_patient("V-1").arm_params())
    m = postural_map(arm, [[0.05, 0.4], [0.1, 0.35]])
    h5 = tmp_path / "bad.h5"
    write_hdf5(h5, [m])
    with h5py.File(h5, "r+") as f:
        del f["maps/000/values"].attrs["unit"]
        f["maps/000/positions"].attrs["unit"] = "inch"
        del f["maps/000"].attrs["sign"]
    mat = tmp_path / "bad.mat"
    write_mat5(mat, m)
    import scipy.io

    v = scipy.io.loadmat(mat)
    v = {k: x for k, x in v.items() if not k.startswith("__") and k != "values_unit"}
    v["positions"] = np.array([[0.05, 0.4], [np.inf, 0.35]])
    scipy.io.savemat(mat, v)
    junk = tmp_path / "junk.bin"
    junk.write_bytes(b"\x00\x01\x02garbage" * 10)
    err = _rejects(db, [h5, mat, junk])
    text = "\n".join(str(p) for p in err.problems)
    assert "bad.h5:/maps/000/values: missing 'unit' attribute" in text
    assert "bad.h5:/maps/000/positions: unknown unit 'inch'" in text
    assert "bad.h5:/maps/000: missing 'sign'" in text
    assert "bad.mat: missing variable 'values_unit'" in text
    assert "junk.bin: unknown format" in text


def test_cli_rejects_bad_batch_with_every_problem(tmp_path: Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "FIELDBANK_HOME": str(tmp_path / "home")}

    def cli(*a: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, "-m", "fieldbank.cli", *a], cwd=ROOT, env=env,
                              text=True, capture_output=True, timeout=120)

    assert cli("patient", "add", "V-2", "--mass-kg", "75", "--height-m", "1.75",
               "--side", "right").returncode == 0
    good = tmp_path / "good.csv"
    good.write_text(HEAD + COLS + GOOD_ROWS)
    bad = tmp_path / "bad.csv"
    bad.write_text(BAD_CSV["nan"][0])
    bad2 = tmp_path / "bad2.csv"
    bad2.write_text(BAD_CSV["unknown unit"][0])
    r = cli("ingest", str(good), str(bad), str(bad2), "--patient", "V-2", "--session", "s")
    assert r.returncode == 1
    assert "bad.csv:row 6: NaN" in r.stderr
    assert "bad2.csv:row 5: unknown unit 'furlong'" in r.stderr
    assert cli("maps", "list", "--json").stdout.strip() == "[]"
    r = cli("patient", "show", "V-2", "--json")
    assert '"sessions": []' in r.stdout
