"""Attacks through exports and printouts: labels that climb out of the export directory,
exports that overwrite or follow links, a suffix that says one format while another is
written, formulas in CSV cells, terminal escapes in printed labels.

Each case is generated here; each must be refused with a message naming the path and exit
status 1 with nothing written (or, for the neutralisers, produce text that is harmless).
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from fieldbank.ingest import read_file
from fieldbank.maps import postural_map
from fieldbank.model import Arm
from fieldbank.params import ArmParams
from fieldbank.sanitize import csv_cell, csv_comment, file_component, printable
from fieldbank.storage import Database, IncomingFile

ARM = Arm.from_params(ArmParams.from_anthropometry(75, 1.75, "right"))
FORMULAS = ["=cmd|' /C calc'!A0", "+SUM(A1:A2)", "-2+3", "@SUM(1)", "\t=1", "\r=1",
            "=HYPERLINK(\"http://x\")"]
ESCAPE = "\x1b]0;pwned\x07\x1b[2J"


def _store(db: Database, label: str, source: str, metadata: dict[str, str],
           file_name: str = "m.csv") -> None:
    m = postural_map(ARM, [[0.05, 0.40], [0.10, 0.35]], source=source)
    m = type(m)(kind=m.kind, positions_m=m.positions_m, values=m.values, frame=m.frame,
                sign=m.sign, source=source, metadata=metadata)
    data = m.to_csv().encode()
    db.ingest_files("X-1", label, [IncomingFile(file_name, hashlib.sha256(data).hexdigest(),
                                                "csv", data, (m,))])


@pytest.fixture
def dbu(tmp_path: Path):  # type: ignore[no-untyped-def]
    url = f"sqlite:///{tmp_path / 'db' / 'x.sqlite3'}"
    db = Database.open(url)
    db.add_patient("X-1", 75, 1.75, "right")
    yield db, url
    db.close()


def _cli(*args: str):  # type: ignore[no-untyped-def]
    from fieldbank.cli.main import cli

    return CliRunner().invoke(cli, list(args))


def _files(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*")}


@pytest.mark.parametrize("label", ["x/../../escaped", "../../../../tmp/escaped", "..", ".",
                                   "/etc/cron.d/x", "a\\..\\..\\b", ".hidden", "x\x00y",
                                   "é/../ü"])
def test_session_labels_cannot_leave_the_export_directory(dbu, tmp_path: Path,
                                                          label: str) -> None:
    db, url = dbu
    _store(db, label, "lab", {})
    before = _files(tmp_path)
    out = tmp_path / "exp" / "dir"
    r = _cli("export", "--db", url, "-o", str(out), "--json")
    assert r.exit_code == 0, r.output
    written = [Path(p) for p in json.loads(r.stdout)["files"]]
    assert len(written) == 1 and written[0].parent == out
    assert not written[0].name.startswith(".") and "/" not in written[0].name
    assert _files(tmp_path) - before == {"exp", "exp/dir", f"exp/dir/{written[0].name}"}


def test_file_component_is_one_safe_name() -> None:
    for label in ("../..", "a/b", "..", ".", "", "x" * 500, "\x1b[2J", "CON", "ü"):
        name = file_component(label)
        assert name and name not in (".", "..") and "/" not in name and "\\" not in name
        assert not name.startswith(".") and len(name) <= 80 and name.isprintable()


def test_no_overwrite_without_force_and_never_through_a_link(dbu, tmp_path: Path) -> None:
    db, url = dbu
    _store(db, "s", "lab", {})
    out = tmp_path / "maps.h5"
    out.write_bytes(b"precious")
    r = _cli("export", "--db", url, "-o", str(out))
    assert r.exit_code == 1 and "exists; give --force" in r.output and str(out) in r.output
    assert out.read_bytes() == b"precious"
    assert _cli("export", "--db", url, "-o", str(out), "--force").exit_code == 0
    assert read_file("maps.h5", out.read_bytes(), None)[1] == []
    # a link at the output: refused even with --force; its target untouched
    target = tmp_path / "target.txt"
    target.write_bytes(b"not yours")
    link = tmp_path / "link.h5"
    link.symlink_to(target)
    for extra in ([], ["--force"]):
        r = _cli("export", "--db", url, "-o", str(link), *extra)
        assert r.exit_code == 1 and "symbolic link" in r.output
    assert target.read_bytes() == b"not yours" and link.is_symlink()
    # the raw source file too
    sha = db.list_maps()[0].source_sha256
    r = _cli("export", "--db", url, "--raw", sha, "-o", str(link), "--force")
    assert r.exit_code == 1 and target.read_bytes() == b"not yours"
    raw = tmp_path / "raw.csv"
    assert _cli("export", "--db", url, "--raw", sha, "-o", str(raw)).exit_code == 0
    r = _cli("export", "--db", url, "--raw", sha, "-o", str(raw))
    assert r.exit_code == 1 and "exists" in r.output
    # a directory export refuses to replace any file it would write
    d = tmp_path / "d"
    assert _cli("export", "--db", url, "-o", str(d)).exit_code == 0
    r = _cli("export", "--db", url, "-o", str(d))
    assert r.exit_code == 1 and "--force" in r.output


def test_the_format_follows_the_suffix_or_is_refused(dbu, tmp_path: Path) -> None:
    db, url = dbu
    _store(db, "s1", "lab", {})
    one = tmp_path / "one.csv"
    assert _cli("export", "--db", url, "-o", str(one)).exit_code == 0
    assert one.read_text().startswith("# kind: postural")  # CSV, not HDF5 under a CSV name
    for name, fmt, reason in (("x.csv", "hdf5", "disagrees"), ("x.h5", "csv", "disagrees"),
                              ("x.txt", None, "unknown export suffix"),
                              ("x.mat", None, "unknown export suffix")):
        args = ["export", "--db", url, "-o", str(tmp_path / name)]
        r = _cli(*args, *(["--format", fmt] if fmt else []))
        assert r.exit_code == 1 and reason in r.output, r.output
        assert not (tmp_path / name).exists()
    _store(db, "s2", "lab 2", {})
    r = _cli("export", "--db", url, "-o", str(tmp_path / "two.csv"))
    assert r.exit_code == 1 and "holds one map and 2 match" in r.output
    assert not (tmp_path / "two.csv").exists()


@pytest.mark.parametrize("formula", FORMULAS)
def test_formulas_are_neutralised_in_every_csv_written(dbu, tmp_path: Path,
                                                       formula: str) -> None:
    db, url = dbu
    _store(db, "s", f"lab,{formula}", {"operator": formula, "note": f"a;{formula}"})
    out = tmp_path / "m.csv"
    assert _cli("export", "--db", url, "-o", str(out)).exit_code == 0
    text = out.read_text()
    for dialect in (",", ";", "\t"):  # however a spreadsheet splits it
        for row in csv.reader(io.StringIO(text), delimiter=dialect):
            for cell in row:
                stripped = cell.strip()
                assert not (stripped.startswith(("=", "+", "@")) or (
                    stripped.startswith("-") and not stripped[1:2].isdigit())), (cell, text)
    # the map is still a valid map file
    inc, problems = read_file("m.csv", out.read_bytes(), None)
    assert problems == [] and inc is not None


def test_csv_cell_and_comment_rules() -> None:
    for f in FORMULAS:
        cell = str(csv_cell(f))
        assert not cell.startswith(("=", "+", "-", "@", "\t", "\r")), cell
        assert cell.startswith("'") or cell.startswith("\\x")  # quoted, or a shown escape
        for piece in csv_comment(f"x, {f}").split(","):
            assert not piece.strip(" ").startswith(("=", "+", "-", "@", "\t", "\r")), piece
    for ok in ("-1.5", "+2e3", "3", "SYN-001", "pre-BoNT", "a=b"):
        assert csv_cell(ok) == ok
    assert csv_cell(1.5) == 1.5


def test_metrics_csv_neutralises_labels() -> None:
    from fieldbank.interventions.report.build import metrics_csv
    from fieldbank.interventions.report.compute import COLUMNS, CaseResult

    row = {k: None for k, _ in COLUMNS}
    row.update({"patient": "X-1", "plan_id": 3, "plan_label": FORMULAS[0],
                "static_diff_rms_n": -0.25})
    text = metrics_csv([CaseResult(None, row, {}, ())])  # type: ignore[arg-type]
    cells = list(csv.reader(io.StringIO(text)))[1]
    assert cells[[k for k, _ in COLUMNS].index("plan_label")] == "'" + FORMULAS[0]
    assert cells[[k for k, _ in COLUMNS].index("static_diff_rms_n")] == "-0.25"


def test_printed_labels_carry_no_terminal_escapes(dbu) -> None:
    db, url = dbu
    _store(db, f"s{ESCAPE}", "lab", {}, file_name=f"evil{ESCAPE}.csv")
    db.add_model(ArmParams.from_anthropometry(), "synthetic", f"m{ESCAPE}", "X-1")
    for args in (("maps", "list"), ("patient", "show", "X-1"), ("models", "list")):
        r = _cli(*args, "--db", url)
        assert r.exit_code == 0, r.output
        assert "\x1b" not in r.output and "\x07" not in r.output
        assert "\\x1b" in r.output, (args, r.output)  # shown, visibly
    # an error message quoting a file name from outside is escaped as well
    r = _cli("ingest", f"/nonexistent/{ESCAPE}.csv", "--db", url, "--patient", "X-1",
             "--session", "s")
    assert r.exit_code == 1 and "\x1b" not in r.output and "\\x1b" in r.output
    assert printable("a\u202eb") == "a\\u202eb" and printable("ok: ü") == "ok: ü"
