"""Reads that never inflate: an NWB gzip bomb and a KINARM ZIP of many members, by attack.

* a ≈ 3.5 MB NWB recording whose ``hand_force`` is a gzip dataset of 200 M × 2 zeros (3.2 GB
  declared): refused by its declared size before a byte of it is inflated;
* a ≈ 46 MB KINARM exam ZIP of 40 members, each within the per-member limits (100 MB unpacked,
  a ratio of ≈ 95), 4 GB in all: refused by the total of the members' declared sizes before
  any member is inflated.

Each runs ``fieldbank ingest`` in a child process that reports its own peak resident memory
(``VmHWM`` of ``/proc/self/status``: the high-water mark of this program's memory alone -
``ru_maxrss`` also keeps the parent's resident size at the fork, which a long test run makes
larger than the limit); the test asserts it stays under 1 GB, and that the refusal names the
dataset or the archive and the limit. No wall-clock bound is asserted. The chunked read with a
running total, and a member that holds more than it declares, are checked in-process.
"""

from __future__ import annotations

import io
import json
import os
import struct
import subprocess
import sys
import zipfile
import zlib
from pathlib import Path

import h5py
import numpy as np
import pytest

from fieldbank.errors import MapError
from fieldbank.measure.budget import BudgetExceeded, ReadBudget
from fieldbank.measure.nwbraw import RecordingInfo, write_recording
from fieldbank.measure.recording import Recording, Trial
from fieldbank.storage import Database

ROOT = Path(__file__).resolve().parents[1]
PEAK_LIMIT_KB = 1 << 20          # 1 GB, in the kB that /proc/self/status counts
RUN = """
import json, sys
from fieldbank.cli.main import cli
try:
    cli.main(sys.argv[1:], prog_name="fieldbank", standalone_mode=False)
    code = 0
except SystemExit as e:
    code = e.code
except Exception as e:
    code = 1
    print(f"Error: {e}", file=sys.stderr)
with open("/proc/self/status") as status:
    peak = next(int(line.split()[1]) for line in status if line.startswith("VmHWM:"))
print(json.dumps({"exit": code, "maxrss_kb": peak}))
"""


def _recording(n: int = 2000) -> Recording:
    t = np.arange(n) / 1000.0
    pos = np.column_stack([0.1 + 0.01 * np.sin(t), 0.4 + 0.01 * np.cos(t)])
    return Recording(t, pos, np.gradient(pos, t, axis=0), np.ones((n, 2)),
                     (Trial(0, "base", 0, 0.0, 1.0, (0.2, 1.0)),))


def nwb_gzip_bomb(path: Path, rows: int = 200_000_000) -> None:
    """A raw NWB recording whose hand_force data is a gzip dataset of rows × 2 zeros, its
    chunks written compressed (one zero chunk compressed once, written everywhere)."""
    path.write_bytes(write_recording(_recording(), RecordingInfo("ATK-2", "s")))
    chunk_rows = 1 << 20
    zero_chunk = zlib.compress(b"\0" * (chunk_rows * 2 * 8), 9)
    with h5py.File(path, "a") as f:
        del f["acquisition/hand_force/data"]
        ds = f.create_dataset("acquisition/hand_force/data", shape=(rows, 2), dtype="f8",
                              chunks=(chunk_rows, 2), compression="gzip")
        for k in range(0, rows, chunk_rows):
            ds.id.write_direct_chunk((k, 0), zero_chunk)


def many_member_zip(path: Path, members: int = 40, unpacked: int = 100_000_000) -> None:
    """A Dexterit-E-looking ZIP of ``members`` C3D members, each ``unpacked`` bytes inflated
    from ≈ 1 MB (a ratio of ≈ 95: within a per-member limit), written by hand so that the
    one deflated member is compressed once."""
    rng = np.random.default_rng(30)
    body = rng.integers(0, 256, 1 << 20, dtype=np.uint8).tobytes()
    data = body + b"\0" * (unpacked - len(body))
    comp = zlib.compressobj(6, zlib.DEFLATED, -15)
    deflated = comp.compress(data) + comp.flush()
    crc = zlib.crc32(data)
    del data
    out = io.BytesIO()
    central = []
    names = ["raw/common.c3d"] + [f"raw/trial_{k:02d}.c3d" for k in range(1, members)]
    for name in names:
        off = out.tell()
        nb = name.encode()
        out.write(struct.pack("<IHHHHHIIIHH", 0x04034B50, 20, 0, 8, 0, 0, crc, len(deflated),
                              unpacked, len(nb), 0) + nb)
        out.write(deflated)
        central.append(struct.pack("<IHHHHHHIIIHHHHHII", 0x02014B50, 20, 20, 0, 8, 0, 0, crc,
                                   len(deflated), unpacked, len(nb), 0, 0, 0, 0, 0, off) + nb)
    cd_off = out.tell()
    cd = b"".join(central)
    out.write(cd)
    out.write(struct.pack("<IHHHHIIH", 0x06054B50, 0, 0, len(names), len(names), len(cd),
                          cd_off, 0))
    path.write_bytes(out.getvalue())


def _ingest(path: Path, home: Path, *extra: str) -> tuple[dict[str, int], str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "FIELDBANK_HOME": str(home)}
    r = subprocess.run([sys.executable, "-c", RUN, "ingest", str(path), "--patient", "ATK-2",
                        "--session", "s", *extra], cwd=ROOT, env=env, text=True,
                       capture_output=True, timeout=600)
    return json.loads(r.stdout.strip().splitlines()[-1]), r.stderr


@pytest.fixture
def home(tmp_path: Path) -> Path:
    h = tmp_path / "home"
    with Database.open(f"sqlite:///{h / 'fieldbank.sqlite3'}") as db:
        db.add_patient("ATK-2", 75, 1.75, "right")
    return h


def test_an_nwb_gzip_bomb_is_refused_by_its_declared_size(home: Path, tmp_path: Path) -> None:
    path = tmp_path / "bomb.nwb"
    nwb_gzip_bomb(path)
    assert 2_000_000 < path.stat().st_size < 5_000_000        # ≈ 3.5 MB on disk
    res, err = _ingest(path, home)
    assert res["exit"] == 1, err
    assert "bomb.nwb" in err and "acquisition/hand_force" in err and "3,200,000,000" in err
    assert "max_decompressed_bytes" in err and "Traceback" not in err
    assert res["maxrss_kb"] < PEAK_LIMIT_KB, res
    with Database.open(f"sqlite:///{home / 'fieldbank.sqlite3'}") as db:
        assert db.list_maps() == []


def test_a_zip_of_many_members_each_within_limits_is_refused_by_its_total(
        home: Path, tmp_path: Path) -> None:
    path = tmp_path / "exam.zip"
    many_member_zip(path)
    assert 30_000_000 < path.stat().st_size < 50_000_000        # ≈ 46 MB on disk
    with zipfile.ZipFile(path) as z:                             # a valid archive
        infos = z.infolist()
        assert len(infos) == 40 and all(i.file_size == 100_000_000 for i in infos)
    res, err = _ingest(path, home, "--shoulder", "0,0", "--sign", "arm-on-handle")
    assert res["exit"] == 1, err
    assert "exam.zip" in err and "40 members declare 4,000,000,000 bytes" in err, err
    assert "max_decompressed_bytes" in err and "Traceback" not in err
    assert res["maxrss_kb"] < PEAK_LIMIT_KB, res


def test_a_dataset_is_read_a_slab_at_a_time_with_a_running_total(tmp_path: Path) -> None:
    path = tmp_path / "d.h5"
    rows = 3_000_000                                   # 48 MB as float64: several slabs
    with h5py.File(path, "w") as f:
        f.create_dataset("x", data=np.arange(2 * rows, dtype="f8").reshape(rows, 2),
                         chunks=(1 << 16, 2), compression="gzip")
    with h5py.File(path, "r") as f:
        b = ReadBudget(100 << 20, path.stat().st_size, 1e6)
        arr = b.read_dataset(f["x"], "d.h5:/x")
        assert arr.shape == (rows, 2) and arr[-1, 1] == 2 * rows - 1
        assert b.used == 48_000_000
        with pytest.raises(BudgetExceeded, match=r"d\.h5:/x.*more than the 40,000,000"):
            ReadBudget(40_000_000, 1, 1e9).read_dataset(f["x"], "d.h5:/x")
        small = ReadBudget(60_000_000, path.stat().st_size, 1e9)
        small.read_dataset(f["x"], "d.h5:/x")
        with pytest.raises(BudgetExceeded, match="with what was read before"):
            small.read_dataset(f["x"], "d.h5:/x")


def test_a_member_holding_more_than_it_declares_is_stopped() -> None:
    b = ReadBudget(1 << 30, 1000)
    with pytest.raises(BudgetExceeded, match=r"more than the 10 bytes its header declares"):
        b.inflate(io.BytesIO(b"x" * 11), 10, "a.zip:raw/t.c3d")
    assert b.inflate(io.BytesIO(b"x" * 10), 10, "a.zip:raw/t.c3d") == b"x" * 10
    assert issubclass(BudgetExceeded, MapError)
