"""Ingest of each format: CSV (SI and lab units), fieldbank HDF5, MATLAB v5 and v7.3."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fieldbank.errors import ValidationError
from fieldbank.ingest import (
    detect_format,
    ingest_paths,
    read_file,
    write_hdf5,
    write_mat5,
    write_mat73,
)
from fieldbank.maps import FieldMap, postural_map, stiffness_map
from fieldbank.model import Arm
from fieldbank.params import ArmParams
from fieldbank.sampledata import lab_units_csv
from fieldbank.storage import Database
from fieldbank.units import KGF_N

ROOT = Path(__file__).resolve().parents[1]
P = ArmParams.from_anthropometry(75.0, 1.75, "right")
ARM = Arm.from_params(P)
POS = np.array([[0.05, 0.40], [0.12, 0.33], [-0.06, 0.45], [0.0, 0.30]])


def _maps() -> list[FieldMap]:
    post = postural_map(ARM, POS, source="lab A, robot B 2.1")
    post = FieldMap(kind="postural", positions_m=post.positions_m, values=post.values,
                    sd=np.full((4, 2), 0.1), source=post.source, metadata={"operator": "K"})
    stiff = stiffness_map(ARM, POS, (0.05, -0.1), source="lab A")
    return [post, stiff]


def _same(a: FieldMap, b: FieldMap, rtol: float = 1e-9) -> None:
    assert (a.kind, a.frame, a.sign) == (b.kind, b.frame, b.sign)
    np.testing.assert_allclose(b.positions_m, a.positions_m, rtol=rtol, atol=1e-12)
    np.testing.assert_allclose(b.values, a.values, rtol=rtol, atol=1e-9)
    np.testing.assert_allclose(b.velocity_m_per_s, a.velocity_m_per_s, rtol=1e-12)
    if a.sd is not None:
        np.testing.assert_allclose(b.sd, a.sd, rtol=rtol)
    assert b.source == a.source


@pytest.mark.parametrize("fmt", ["csv", "csv-lab", "hdf5", "mat5", "mat73"])
@pytest.mark.parametrize("which", [0, 1])
def test_each_format_reads_back_the_map(tmp_path: Path, fmt: str, which: int) -> None:
    m = _maps()[which]
    path = tmp_path / f"map.{fmt}"
    if fmt == "csv":
        path.write_text(m.to_csv())
    elif fmt == "csv-lab":
        path.write_text(lab_units_csv(m))
    elif fmt == "hdf5":
        write_hdf5(path, [m])
    elif fmt == "mat5":
        write_mat5(path, m)
    else:
        write_mat73(path, m)
    data = path.read_bytes()
    assert detect_format(data) == {"csv-lab": "csv"}.get(fmt, fmt)
    inc, problems = read_file(path.name, data, ARM, "X")
    assert problems == []
    assert inc is not None and len(inc.maps) == 1
    _same(m, inc.maps[0], rtol=1e-8 if fmt != "csv" else 1e-9)
    if fmt in ("hdf5", "mat5", "mat73", "csv"):
        assert inc.maps[0].metadata.get("operator") == m.metadata.get("operator")


def test_lab_units_are_converted() -> None:
    text = ("# kind: postural\n# frame: shoulder\n# sign: arm-on-handle\n# source: s\n"
            "x_mm,y_cm,fx_kgf,fy_mn\n50,40,1,500\n")
    inc, problems = read_file("u.csv", text.encode(), ARM, "X")
    assert problems == []
    m = inc.maps[0]
    np.testing.assert_allclose(m.positions_m, [[0.05, 0.40]])
    np.testing.assert_allclose(m.values, [[KGF_N, 0.5]])
    k = ("# kind: stiffness\n# frame: shoulder\n# sign: arm-on-handle\n# velocity_m_per_s: 0\n"
         "x_m,y_m,kxx_n_per_mm,kxy_n_per_mm,kyx_n_per_cm,kyy_n_per_m\n0.05,0.4,1,2,3,4\n")
    inc, problems = read_file("k.csv", k.encode(), ARM, "X")
    assert problems == []
    np.testing.assert_allclose(inc.maps[0].values, [[[1000, 2000], [300, 4]]])


def test_hdf5_with_several_maps(tmp_path: Path) -> None:
    maps = _maps()
    write_hdf5(tmp_path / "two.h5", maps)
    inc, problems = read_file("two.h5", (tmp_path / "two.h5").read_bytes(), ARM, "X")
    assert problems == []
    assert [m.kind for m in inc.maps] == ["postural", "stiffness"]


def test_ingest_sample_set_and_export_round_trip(sample_dir: Path, tmp_path: Path,
                                                  any_db_url: str) -> None:
    manifest = json.loads((sample_dir / "manifest.json").read_text())
    db = Database.open(any_db_url, upgrade="always", store_root=tmp_path / "arrays")
    n_maps = 0
    for p in manifest["patients"]:
        db.add_patient(p["code"], p["body_mass_kg"], p["height_m"], p["side"])
        for s in p["sessions"]:
            rep = ingest_paths(db, [sample_dir / f["file"] for f in s["files"]], p["code"],
                               s["label"])
            assert rep.n_stored == len(s["files"])
            n_maps += sum(len(f["kinds"].split(",")) for f in s["files"])
    assert len(db.list_maps()) == n_maps
    assert {f["format"] for p in manifest["patients"] for s in p["sessions"]
            for f in s["files"]} == {"csv", "hdf5", "mat5", "mat73"}
    # every sample source says it is synthetic
    assert all("not patient data" in m.source_text for m in db.list_maps())
    # export to HDF5 and ingest the export into a new session of the same patient: same maps
    # (the maps name their patient, so another patient would be refused)
    from fieldbank.ingest.hdf5fmt import write_hdf5 as w

    rows = db.list_maps("SYN-001", kind="stiffness")
    w(tmp_path / "exp.h5", db.get_maps([r.id for r in rows]))
    rep = ingest_paths(db, [tmp_path / "exp.h5"], "SYN-001", "re-import")
    again = db.get_maps(list(rep.outcomes[0].map_ids))
    for a, b in zip(db.get_maps([r.id for r in rows]), again, strict=True):
        _same(a, b)
    p = db.get_patient("SYN-001")
    db.add_patient("SYN-001-copy", p.body_mass_kg, p.height_m, p.side)
    with pytest.raises(ValidationError, match="being ingested for patient 'SYN-001-copy'"):
        ingest_paths(db, [tmp_path / "exp.h5"], "SYN-001-copy", "re-import")
    assert db.check().ok
    db.close()


@pytest.mark.slow
def test_cli_ingest_dry_run_json_and_duplicates(sample_dir: Path, tmp_path: Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "FIELDBANK_HOME": str(tmp_path / "home")}

    def cli(*a: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, "-m", "fieldbank.cli", *a], cwd=ROOT, env=env,
                              text=True, capture_output=True, timeout=120)

    files = sorted(str(p) for p in (sample_dir / "SYN-002" / "post-BoNT").iterdir())
    assert cli("patient", "add", "SYN-002", "--mass-kg", "61", "--height-m", "1.62",
               "--side", "left").returncode == 0
    r = cli("ingest", *files, "--patient", "SYN-002", "--session", "post-BoNT", "--dry-run",
            "--json")
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    assert summary["dry_run"] and {f["status"] for f in summary["files"]} == {"would-store"}
    assert json.loads(cli("maps", "list", "--json").stdout) == []
    r = cli("ingest", *files, "--patient", "SYN-002", "--session", "post-BoNT", "--date",
            "2024-02-03", "--json")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["stored"] == 3
    listed = json.loads(cli("maps", "list", "--patient", "SYN-002", "--json").stdout)
    assert len(listed) == 4 and listed[0]["session_date"] == "2024-02-03"
    r = cli("ingest", *files, "--patient", "SYN-002", "--session", "post-BoNT", "--json")
    assert json.loads(r.stdout)["duplicates"] == 3 and "already stored" in r.stderr
    assert len(json.loads(cli("maps", "list", "--json").stdout)) == 4
    out = tmp_path / "export.h5"
    assert cli("export", "--patient", "SYN-002", "-o", str(out)).returncode == 0
    inc, problems = read_file("export.h5", out.read_bytes(), None)
    assert problems == [] and len(inc.maps) == 4
    raw = tmp_path / "raw.bin"
    sha = listed[0]["source_sha256"]
    assert cli("export", "--raw", sha, "-o", str(raw)).returncode == 0
    import hashlib

    assert hashlib.sha256(raw.read_bytes()).hexdigest() == sha
    r = cli("patient", "show", "SYN-002", "--json")
    assert json.loads(r.stdout)["sessions"][0]["n_maps"] == 4
    assert cli("db", "check").returncode == 0


def test_export_csv_round_trip(sample_dir: Path, tmp_path: Path) -> None:
    from click.testing import CliRunner

    from fieldbank.cli.main import cli

    url = f"sqlite:///{tmp_path / 'e.sqlite3'}"
    db = Database.open(url)
    db.add_patient("SYN-003", 85.0, 1.83, "right")
    files = sorted((sample_dir / "SYN-003" / "post-BoNT").iterdir())
    ingest_paths(db, files, "SYN-003", "post-BoNT")
    out = tmp_path / "csv"
    r = CliRunner().invoke(cli, ["export", "--db", url, "--patient", "SYN-003", "--kind",
                                 "stiffness", "--format", "csv", "-o", str(out), "--json"])
    assert r.exit_code == 0, r.output
    written = json.loads(r.stdout)["files"]
    assert len(written) == 2
    stored = db.get_maps([m.id for m in db.list_maps("SYN-003", kind="stiffness")])
    for path, m in zip(written, stored, strict=True):
        inc, problems = read_file(Path(path).name, Path(path).read_bytes(), None)
        assert problems == []
        _same(m, inc.maps[0], rtol=1e-8)
    r = CliRunner().invoke(cli, ["export", "--db", url, "--patient", "NOBODY", "-o",
                                 str(tmp_path / "x.h5")])
    assert r.exit_code == 1 and "No patient with code 'NOBODY'" in r.output
    r = CliRunner().invoke(cli, ["export", "--db", url, "--patient", "SYN-003", "--kind",
                                 "postural", "--since", "2030-01-01", "-o", str(tmp_path / "x.h5")])
    assert r.exit_code == 1 and "No map matches" in r.output
    db.close()
