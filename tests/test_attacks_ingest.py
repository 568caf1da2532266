"""Attacks on ingest, as a hostile or careless user would try them.

Every case is a file generated here by code. Each must end with a clear message that names the
file (and the row, dataset or variable) and the reason, a non-zero exit status, and nothing
stored: no map, no session, no store file, no audit entry.

The bombs (files that declare or inflate to gigabytes, /dev/zero behind a link, a FIFO with no
writer, a file with too many rows) run the real command line in a subprocess under
``RLIMIT_AS`` (:data:`MEMORY_LIMIT`, a fraction of what the bombs would allocate) and a
timeout, so a regression fails the test instead of exhausting the machine or hanging it.
"""

from __future__ import annotations

import json
import os
import resource
import struct
import subprocess
import sys
import zlib
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
import pytest

from fieldbank.errors import ParameterError, ValidationError
from fieldbank.ingest import IngestLimits, ingest_paths, write_hdf5, write_mat5, write_mat73
from fieldbank.maps import postural_map
from fieldbank.model import Arm
from fieldbank.params import ArmParams
from fieldbank.storage import Database

ROOT = Path(__file__).resolve().parents[1]
PATIENT = "ATK-1"
#: Address-space limit of a bomb's subprocess: the whole ingest stack needs < 600 MiB.
MEMORY_LIMIT = 1 << 30
TIMEOUT_S = 60
HEAD = "# kind: postural\n# frame: shoulder\n# sign: arm-on-handle\n# source: lab\n"
ARM = Arm.from_params(ArmParams.from_anthropometry(75, 1.75, "right"))


def _good_map():  # type: ignore[no-untyped-def]
    return postural_map(ARM, [[0.05, 0.40], [0.10, 0.35]])


# --- the bombs: generated files ---------------------------------------------------------------
def _zeros_chunk(n_bytes: int) -> bytes:
    return zlib.compress(b"\0" * n_bytes, 9)


def _h5_gzip_bomb(path: Path, userblock: int = 0, name: str = "maps/000/positions") -> None:
    """A dataset of 4 GiB of float64 zeros in gzip chunks written directly: a few MB on disk."""
    rows, chunk_rows = 1 << 28, 1 << 16  # (2^28, 2) float64 = 4 GiB
    chunk = _zeros_chunk(chunk_rows * 2 * 8)
    with h5py.File(path, "w", userblock_size=userblock or None) as f:
        if not userblock:
            f.attrs["format"] = "fieldbank.maps"
            g = f.create_group("maps/000")
            for k, v in {"kind": "postural", "frame": "shoulder",
                         "sign": "arm-on-handle"}.items():
                g.attrs[k] = v
        ds = f.create_dataset(name, shape=(rows, 2), dtype="f8", chunks=(chunk_rows, 2),
                              compression="gzip")
        ds.attrs["unit"] = "m"
        for i in range(0, 64):  # enough written chunks to make it a real compressed file
            ds.id.write_direct_chunk((i * chunk_rows, 0), chunk)
        if userblock:
            ds.attrs["MATLAB_class"] = np.bytes_("double")
    if userblock:
        head = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, HDF5 schema 1.00 ."
        with open(path, "r+b") as fh:
            fh.write((head.ljust(116, b" ") + b"\0" * 8 + b"\x00\x02IM").ljust(512, b"\0"))


def _h5_declared_bomb(path: Path) -> None:
    """Chunks never written: the file is kB, h5py would allocate the declared 8 GB."""
    write_hdf5(path, [_good_map()])
    with h5py.File(path, "r+") as f:
        del f["maps/000/values"]
        d = f["maps/000"].create_dataset("values", shape=(500_000_000, 2), dtype="f8",
                                         chunks=(1 << 16, 2), compression="gzip")
        d.attrs["unit"] = "N"


def _zlib_zeros(prefix: bytes, n_zeros: int, block: int = 8 << 20) -> bytes:
    """A zlib stream of ``prefix`` then ``n_zeros`` zero bytes, built in a moment: after a full
    flush the compressor emits the same bytes for every block of zeros, so one block is
    compressed and repeated; the Adler-32 of a run of zeros is computed directly."""
    c = zlib.compressobj(9)
    out = [c.compress(prefix) + c.flush(zlib.Z_FULL_FLUSH)]
    piece = c.compress(b"\0" * block) + c.flush(zlib.Z_FULL_FLUSH)
    out += [piece] * (n_zeros // block)
    a = zlib.adler32(prefix)
    lo, hi = a & 0xFFFF, (a >> 16) + (a & 0xFFFF) * (n_zeros // block * block)
    out.append(b"\x01\x00\x00\xff\xff" + struct.pack(">I", ((hi % 65521) << 16) | lo))
    return b"".join(out)


def test_zlib_zeros_is_a_valid_stream() -> None:
    data = zlib.decompress(_zlib_zeros(b"head", 5 << 16, 1 << 16))
    assert data == b"head" + b"\0" * (5 << 16)


def _mat5_zlib_bomb(path: Path) -> None:
    """A MATLAB v5 file whose one compressed variable inflates to 2.4 GB of zeros."""
    write_mat5(path, _good_map())
    rows, cols = 150_000_000, 2
    n = rows * cols * 8
    flags = struct.pack("<II", 6, 8) + struct.pack("<II", 6, 0)  # double, no flags
    dims = struct.pack("<II", 5, 8) + struct.pack("<ii", rows, cols)
    name = b"extra"
    body = flags + dims + struct.pack("<II", 1, len(name)) + name + b"\0" * 3
    body += struct.pack("<II", 9, n)
    comp = _zlib_zeros(struct.pack("<II", 14, len(body) + n) + body, n)
    with open(path, "ab") as fh:
        fh.write(struct.pack("<II", 15, len(comp)) + comp)


def _many_rows(path: Path) -> None:
    rng = np.random.default_rng(0)
    xy = rng.uniform([-0.2, 0.3], [0.2, 0.5], (150_000, 2))
    rows = "\n".join(f"{x:.6f},{y:.6f},1,1" for x, y in xy)
    path.write_text(HEAD + "x_m,y_m,fx_n,fy_n\n" + rows + "\n")


def _symlink_to_zero(path: Path) -> None:
    path.symlink_to("/dev/zero")


def _fifo(path: Path) -> None:
    os.mkfifo(path)


#: case -> (builder, file name, text the located message must contain)
BOMBS: dict[str, tuple[Callable[[Path], None], str, str]] = {
    "hdf5 gzip bomb": (_h5_gzip_bomb, "gz.h5", "gz.h5:/maps/000/positions: declares"),
    "hdf5 unwritten chunks": (_h5_declared_bomb, "decl.h5", "decl.h5:/maps/000/values: declares"),
    "mat v7.3 gzip bomb": (lambda p: _h5_gzip_bomb(p, 512, "positions"), "gz73.mat",
                           "gz73.mat:positions: declares"),
    "mat v5 zlib bomb": (_mat5_zlib_bomb, "zip5.mat", "zip5.mat: variable 'extra' inflates"),
    "csv with too many rows": (_many_rows, "rows.csv", "more than 100,000 data rows"),
    "symlink to /dev/zero": (_symlink_to_zero, "zero.csv", "a character device"),
    "fifo without writer": (_fifo, "pipe.csv", "a named pipe (FIFO)"),
}


@pytest.fixture
def home(tmp_path: Path) -> Path:
    h = tmp_path / "home"
    db = Database.open(f"sqlite:///{h / 'fieldbank.sqlite3'}")
    db.add_patient(PATIENT, 75, 1.75, "right")
    db.close()
    return h


def _nothing_stored(home: Path) -> None:
    db = Database.open(f"sqlite:///{home / 'fieldbank.sqlite3'}")
    try:
        assert db.list_maps() == [] and db.list_sessions() == []
        assert [e.action for e in db.audit_entries()] == ["add"]  # the patient only
        assert list(db.store.keys()) == [] and db.store.stray_temporaries() == []
    finally:
        db.close()


def _limited() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


@pytest.mark.slow
@pytest.mark.parametrize("case", list(BOMBS))
def test_bomb_is_refused_within_memory_and_time(case: str, home: Path, tmp_path: Path) -> None:
    build, name, expected = BOMBS[case]
    path = tmp_path / name
    build(path)
    env = {**os.environ, "PYTHONPATH": str(ROOT), "FIELDBANK_HOME": str(home)}
    r = subprocess.run([sys.executable, "-m", "fieldbank.cli", "ingest", str(path),
                        "--patient", PATIENT, "--session", "s"], cwd=ROOT, env=env, text=True,
                       capture_output=True, timeout=TIMEOUT_S, preexec_fn=_limited)
    assert r.returncode == 1, r.stderr[-2000:]
    assert "Nothing was stored" in r.stderr and expected in r.stderr, r.stderr[-2000:]
    assert "Traceback" not in r.stderr and len(r.stderr) < 5000
    _nothing_stored(home)


@pytest.mark.slow
def test_without_the_readers_limits_the_memory_limit_is_hit(home: Path, tmp_path: Path) -> None:
    # the bombs are real: with the decompression limits lifted, the same file needs more than
    # MEMORY_LIMIT and only the address-space limit stops it (still a message, no traceback)
    path = tmp_path / "gz.h5"
    _h5_gzip_bomb(path)
    env = {**os.environ, "PYTHONPATH": str(ROOT), "FIELDBANK_HOME": str(home)}
    r = subprocess.run([sys.executable, "-m", "fieldbank.cli", "ingest", str(path),
                        "--patient", PATIENT, "--session", "s",
                        "--limit", f"max_decompressed_bytes={1 << 40}",
                        "--limit", "max_compression_ratio=1e12"], cwd=ROOT, env=env, text=True,
                       capture_output=True, timeout=TIMEOUT_S, preexec_fn=_limited)
    assert r.returncode == 1 and "in the memory available" in r.stderr, r.stderr[-2000:]
    _nothing_stored(home)


def test_problems_listed_are_bounded(home: Path, tmp_path: Path) -> None:
    # 20,000 bad rows: each is a problem, the message lists max_problems and counts the rest
    bad = tmp_path / "bad.csv"
    bad.write_text(HEAD + "x_m,y_m,fx_n,fy_n\n" + "0.05,0.40,abc,1\n" * 20_000)
    db = Database.open(f"sqlite:///{home / 'fieldbank.sqlite3'}")
    try:
        with pytest.raises(ValidationError) as info:
            ingest_paths(db, [bad], PATIENT, "s")
        text = str(info.value)
        assert len(text.splitlines()) <= 103 and "more problem(s)" in text
        assert "bad.csv:row 6: column 'fx_n': 'abc' is not a number" in text
        with pytest.raises(ValidationError) as info:
            ingest_paths(db, [bad], PATIENT, "s", limits=IngestLimits(max_problems=5))
        assert len(str(info.value).splitlines()) <= 8
    finally:
        db.close()
    _nothing_stored(home)


# --- malformed and misleading files: every one a located message ------------------------------
def _h5(tmp: Path, edit: Callable[[h5py.File], None], name: str = "f.h5") -> Path:
    p = tmp / name
    write_hdf5(p, [_good_map()])
    with h5py.File(p, "r+") as f:
        edit(f)
    return p


def _replace(f: h5py.File, key: str, make: Callable[[h5py.Group, str], object]) -> None:
    g = f[key.rsplit("/", 1)[0]]
    leaf = key.rsplit("/", 1)[1]
    del g[leaf]
    make(g, leaf)


def _mat73(tmp: Path, edit: Callable[[h5py.File], None], name: str = "m73.mat") -> Path:
    p = tmp / name
    write_mat73(p, _good_map())
    with h5py.File(p, "r+") as f:
        edit(f)
    return p


def _mat73_logical(f: h5py.File) -> None:
    v = f["values"][()]
    del f["values"]
    d = f.create_dataset("values", data=(v != 0).astype("u1"))
    d.attrs["MATLAB_class"] = np.bytes_("logical")


def _mat73_reference(f: h5py.File) -> None:
    target = f.create_dataset("#refs#/a", data=np.zeros(3))
    del f["frame"]
    d = f.create_dataset("frame", data=np.array([[target.ref]], dtype=h5py.ref_dtype))
    d.attrs["MATLAB_class"] = np.bytes_("cell")


def _mat73_text_as_bytes(f: h5py.File) -> None:
    del f["sign"]
    d = f.create_dataset("sign", data=np.bytes_("pushing"))
    d.attrs["MATLAB_class"] = np.bytes_("char")


def _mat5_logical(tmp: Path) -> Path:
    import scipy.io

    p = tmp / "log5.mat"
    write_mat5(p, _good_map())
    v = {k: x for k, x in scipy.io.loadmat(p).items() if not k.startswith("__")}
    v["values"] = np.array([[True, False], [False, True]])
    scipy.io.savemat(p, v)
    return p


def _csv(tmp: Path, text: str, name: str = "f.csv") -> Path:
    p = tmp / name
    p.write_text(text, encoding="utf-8")
    return p


#: case -> (builder of the file, the location the message starts with, the reason it contains)
MALFORMED: dict[str, tuple[Callable[[Path], Path], str, str]] = {
    "hdf5 string velocity": (
        lambda t: _h5(t, lambda f: f["maps/000"].attrs.__setitem__("velocity_m_per_s", "fast")),
        "f.h5:/maps/000", "velocity_m_per_s must hold 1 or 2 numbers"),
    "hdf5 dangling soft link": (
        lambda t: _h5(t, lambda f: _replace(f, "maps/000/values", lambda g, k: g.__setitem__(
            k, h5py.SoftLink("/nowhere")))),
        "f.h5:/maps/000/values", "a soft link to /nowhere"),
    "hdf5 external link": (
        lambda t: _h5(t, lambda f: _replace(f, "maps/000/positions", lambda g, k: g.__setitem__(
            k, h5py.ExternalLink("/etc/passwd", "/x")))),
        "f.h5:/maps/000/positions", "an external link to /etc/passwd"),
    "hdf5 logical values": (
        lambda t: _h5(t, lambda f: _replace(f, "maps/000/values", lambda g, k: g.create_dataset(
            k, data=np.ones((2, 2), bool)).attrs.__setitem__("unit", "N"))),
        "f.h5:/maps/000/values", "logical"),
    "mat v7.3 logical forces": (lambda t: _mat73(t, _mat73_logical), "m73.mat:values",
                                "is a logical (true/false) array"),
    "mat v7.3 cell reference as text": (lambda t: _mat73(t, _mat73_reference), "m73.mat:frame",
                                        "must be a char array; it is a MATLAB cell array"),
    "mat v7.3 text stored as bytes": (lambda t: _mat73(t, _mat73_text_as_bytes), "m73.mat",
                                      "unknown sign 'pushing'"),
    "mat v5 logical forces": (_mat5_logical, "log5.mat:values", "is a logical (true/false)"),
    "csv underscore digits": (
        lambda t: _csv(t, HEAD + "x_m,y_m,fx_n,fy_n\n0.05,0.40,1_000,1\n"),
        "f.csv:row 6", "'1_000' is not a number"),
    "csv arabic-indic digits": (
        lambda t: _csv(t, HEAD + "x_m,y_m,fx_n,fy_n\n0.05,0.40,\u0661\u0662,1\n"),
        "f.csv:row 6", "is not a number"),
    "csv 1e300 newtons": (
        lambda t: _csv(t, HEAD + "x_m,y_m,fx_n,fy_n\n0.05,0.40,1e300,1\n"),
        "f.csv:row 6", "force value 1e+300 N is implausible"),
    "csv 1.6 meganewtons in kgf": (
        lambda t: _csv(t, HEAD + "x_m,y_m,fx_kgf,fy_kgf\n0.05,0.40,163000,1\n"),
        "f.csv:row 6", "is implausible: above 1000 N"),
    "csv stiffness 1e7 N/m": (
        lambda t: _csv(t, "# kind: stiffness\n# frame: shoulder\n# sign: arm-on-handle\n"
                       "# velocity_m_per_s: 0\nx_m,y_m,kxx_n_per_m,kxy_n_per_m,kyx_n_per_m,"
                       "kyy_n_per_m\n0.05,0.40,1e7,0,0,300\n"),
        "f.csv:row 6", "stiffness value 1e+07 N/m is implausible"),
    "csv names another patient": (
        lambda t: _csv(t, "# patient: SYN-002\n" + HEAD + "x_m,y_m,fx_n,fy_n\n0.05,0.40,1,1\n"),
        "f.csv", "the file's 'patient' is 'SYN-002', but it is being ingested for patient "
                 "'ATK-1'"),
    "hdf5 export of another patient": (
        lambda t: _h5(t, lambda f: f["maps/000"].attrs.__setitem__("patient", "SYN-002")),
        "f.h5:/maps/000", "ingested for patient 'ATK-1'"),
    "csv semicolon header with a bad unit: one problem, not one per row": (
        lambda t: _csv(t, HEAD + "x_m;y_m;fx_stone;fy_n\n" + "0,05;0,40;1;1\n" * 500),
        "f.csv:row 5", "unknown unit 'stone'"),
    "csv mixed decimal separators": (
        lambda t: _csv(t, HEAD + "x_m;y_m;fx_n;fy_n\n0,05;0,40;1,5;1\n0,10;0,35;2.5;1\n"),
        "f.csv:row 7", "decimal point is ambiguous"),
}


@pytest.fixture
def db(home: Path):  # type: ignore[no-untyped-def]
    d = Database.open(f"sqlite:///{home / 'fieldbank.sqlite3'}")
    yield d
    d.close()


@pytest.mark.parametrize("case", list(MALFORMED))
def test_malformed_file_is_a_located_message(case: str, db: Database, home: Path,
                                             tmp_path: Path) -> None:
    build, where, reason = MALFORMED[case]
    path = build(tmp_path)
    with pytest.raises(ValidationError) as info:
        ingest_paths(db, [path], PATIENT, "s")
    err = info.value
    hits = [p for p in err.problems if p.location.startswith(where) and reason in p.reason]
    assert hits, "\n".join(map(str, err.problems))
    assert "Nothing was stored" in str(err)
    if "one problem" in case:
        assert len(err.problems) == 1, "\n".join(map(str, err.problems))
    _nothing_stored(home)


def test_cli_exit_status_and_message_for_a_malformed_file(home: Path, tmp_path: Path) -> None:
    path = MALFORMED["hdf5 external link"][0](tmp_path)
    env = {**os.environ, "PYTHONPATH": str(ROOT), "FIELDBANK_HOME": str(home)}
    r = subprocess.run([sys.executable, "-m", "fieldbank.cli", "ingest", str(path),
                        "--patient", PATIENT, "--session", "s", "--json"], cwd=ROOT, env=env,
                       text=True, capture_output=True, timeout=TIMEOUT_S)
    assert r.returncode == 1 and r.stdout == ""
    assert "f.h5:/maps/000/positions: an external link to /etc/passwd" in r.stderr
    assert "Traceback" not in r.stderr
    _nothing_stored(home)


# --- what must keep working: the dialects labs really write -----------------------------------
def _rows(sep: str, dec: str = ".") -> str:
    rows = [("0.05", "0.40", "1.0", "-0.5"), ("0.10", "0.35", "0.5", "0.2")]
    return "".join(sep.join(c.replace(".", dec) for c in r) + "\n" for r in rows)


DIALECTS = {
    "R write.csv (quoted header, row names)": HEAD + '"","x_m","y_m","fx_n","fy_n"\n'
    + '"1",0.05,0.40,1.0,-0.5\n"2",0.10,0.35,0.5,0.2\n',
    "quoted header": HEAD + '"x_m","y_m","fx_n","fy_n"\n' + _rows(","),
    "semicolons": HEAD + "x_m;y_m;fx_n;fy_n\n" + _rows(";"),
    "semicolons and decimal commas (R write.csv2)": HEAD + "x_m;y_m;fx_n;fy_n\n"
    + _rows(";", ","),
    "tabs": HEAD + "x_m\ty_m\tfx_n\tfy_n\n" + _rows("\t"),
    "spaces after commas": HEAD + "x_m, y_m, fx_n, fy_n\n" + _rows(", "),
}


@pytest.mark.parametrize("case", list(DIALECTS))
def test_csv_dialects_are_read(case: str, db: Database, tmp_path: Path) -> None:
    path = _csv(tmp_path, DIALECTS[case])
    rep = ingest_paths(db, [path], PATIENT, "s")
    m = db.get_map(rep.outcomes[0].map_ids[0])
    np.testing.assert_allclose(m.positions_m, [[0.05, 0.40], [0.10, 0.35]])
    np.testing.assert_allclose(m.values, [[1.0, -0.5], [0.5, 0.2]])


def test_limits_are_configurable(db: Database, tmp_path: Path,
                                 monkeypatch: pytest.MonkeyPatch) -> None:
    big = _csv(tmp_path, HEAD + "x_m,y_m,fx_n,fy_n\n0.05,0.40,1500,1\n")
    with pytest.raises(ValidationError, match="limit max_force_n = 1000"):
        ingest_paths(db, [big], PATIENT, "s")
    monkeypatch.setenv("FIELDBANK_INGEST_LIMITS", "max_force_n=2000, max_rows=10")
    limits = IngestLimits.from_environment()
    assert (limits.max_force_n, limits.max_rows) == (2000, 10)
    assert ingest_paths(db, [big], PATIENT, "s", limits=limits).n_stored == 1
    # the command line wins over the environment; bad names and values are refused
    assert IngestLimits.from_environment(["max_rows=5"]).max_rows == 5
    with pytest.raises(ParameterError, match="max_rowz"):
        IngestLimits.from_environment(["max_rowz=5"])
    with pytest.raises(ParameterError, match="'max_rows' ingest limit must be a whole number"):
        IngestLimits.from_items(["max_rows=2.5"])
    with pytest.raises(ParameterError, match="max_force_n"):
        IngestLimits.from_items(["max_force_n=-1"])


def test_patient_code_with_control_characters_is_refused(db: Database) -> None:
    for code in ("ATK-2\n", "ATK\x1b[2J", "ATK-3\r", "ATK\u202e3"):
        with pytest.raises(ParameterError, match="pseudonym"):
            db.add_patient(code, 75, 1.75, "right")
    assert [p.code for p in db.list_patients()] == [PATIENT]


def test_deeply_nested_plan_and_parameter_files(tmp_path: Path) -> None:
    from fieldbank.interventions.errors import InterventionError
    from fieldbank.interventions.plan import Plan

    deep = tmp_path / "deep.json"
    deep.write_text("[" * 200_000 + "]" * 200_000)
    with pytest.raises(InterventionError, match="nested too deeply"):
        Plan.from_file(deep)
    with pytest.raises(ParameterError, match="nested too deeply"):
        ArmParams.from_file(deep)
    with pytest.raises(InterventionError, match="a character device"):
        Plan.from_file("/dev/zero")


def test_cli_plan_file_from_a_fifo_is_refused(tmp_path: Path) -> None:
    fifo = tmp_path / "plan.json"
    os.mkfifo(fifo)
    env = {**os.environ, "PYTHONPATH": str(ROOT), "FIELDBANK_HOME": str(tmp_path / "h")}
    r = subprocess.run([sys.executable, "-m", "fieldbank.cli", "whatif", "--severity",
                        "elbow=severe", "--plan", str(fifo), "--json"], cwd=ROOT, env=env,
                       text=True, capture_output=True, timeout=TIMEOUT_S)
    assert r.returncode != 0 and "named pipe" in r.stderr and "Traceback" not in r.stderr
    assert r.stdout == "" or json.loads(r.stdout) is None
