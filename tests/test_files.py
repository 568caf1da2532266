"""Durable writes: all or nothing, no temporary files left behind."""

from __future__ import annotations

import math
import os
import stat
from pathlib import Path

import pytest

from fieldbank.errors import ParameterError, ValidationError
from fieldbank.files import json_finite, read_json_document, write_atomic, write_directory
from fieldbank.interventions.errors import InterventionError
from fieldbank.interventions.plan import Plan
from fieldbank.params import ArmParams
from fieldbank.probepath import read_probes


def test_write_atomic_replaces_whole_file_with_umask_mode(tmp_path: Path) -> None:
    target = tmp_path / "sub" / "out.csv"
    write_atomic(target, "a,b\n1,2\n")
    write_atomic(target, b"x\n")
    assert target.read_bytes() == b"x\n"
    assert sorted(p.name for p in target.parent.iterdir()) == ["out.csv"]
    mask = os.umask(0o022)
    os.umask(mask)
    assert stat.S_IMODE(target.stat().st_mode) == 0o666 & ~mask


def test_write_atomic_failure_keeps_the_old_file(tmp_path: Path) -> None:
    target = tmp_path / "out.txt"
    target.write_text("old")

    with pytest.raises(TypeError):
        write_atomic(target, 12345)  # type: ignore[arg-type]
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]


def test_write_directory_puts_a_set_in_place_whole_or_not_at_all(tmp_path: Path) -> None:
    out = tmp_path / "set"
    write_directory(out, {"a.txt": "one", "b.key": b"secret"}, modes={"b.key": 0o600},
                    private=True)
    assert sorted(p.name for p in out.iterdir()) == ["a.txt", "b.key"]
    assert stat.S_IMODE(out.stat().st_mode) == 0o700
    assert stat.S_IMODE((out / "b.key").stat().st_mode) == 0o600
    # into a directory that exists: each file replaced, others kept
    (out / "other").write_text("kept")
    write_directory(out, {"a.txt": "two"})
    assert (out / "a.txt").read_text() == "two" and (out / "other").read_text() == "kept"
    # a failure while writing (the second file cannot be encoded): nothing changes, no
    # temporary directory is left beside the target
    for target in (out, tmp_path / "new"):
        with pytest.raises(UnicodeEncodeError):
            write_directory(target, {"a.txt": "three", "c.txt": "\ud800"})
    assert (out / "a.txt").read_text() == "two" and not (tmp_path / "new").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["set"]
    with pytest.raises(ValueError, match="not a file name"):
        write_directory(out, {"../x": "no"})


def test_json_finite() -> None:
    doc = {"a": [1.0, math.nan, {"b": math.inf}], "c": (2, -math.inf), "d": "x"}
    assert json_finite(doc) == {"a": [1.0, None, {"b": None}], "c": [2, None], "d": "x"}


def test_write_atomic_never_touches_the_process_umask(tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """The mode comes from the kernel applying the umask at creation; reading the umask would
    mean setting it, for every thread of the process at once."""
    calls: list[int] = []
    real = os.umask
    monkeypatch.setattr(os, "umask", lambda m: calls.append(m) or real(m))
    old = real(0o027)
    try:
        calls.clear()
        write_atomic(tmp_path / "a.txt", "x")
        assert calls == []
        assert stat.S_IMODE((tmp_path / "a.txt").stat().st_mode) == 0o640
    finally:
        real(old)


def test_one_json_document_reader_refuses_what_json_does_not_allow(tmp_path: Path) -> None:
    ok = tmp_path / "ok.json"
    ok.write_text('{"a": [1, 2.5, null]}', encoding="utf-8")
    assert read_json_document(ok) == {"a": [1, 2.5, None]}
    for name, raw, reason in [("nan.json", b'{"a": NaN}', "not JSON: NaN is not a number"),
                              ("inf.json", b"[-Infinity]", "not JSON: -Infinity"),
                              ("bad.json", b"{", "not valid JSON"),
                              ("latin.json", b'"\xe9"', "not UTF-8 text"),
                              ("deep.json", b"[" * 100_000 + b"]" * 100_000, "nested too deeply")]:
        (tmp_path / name).write_bytes(raw)
        with pytest.raises(ValidationError, match=reason) as err:
            read_json_document(tmp_path / name)
        assert err.value.problems[0].location == str(tmp_path / name)
    # the same rules for every document: parameters, plans and probes files alike
    (tmp_path / "p.json").write_bytes(b'{"schema": "x", "km_n_per_m": NaN}')
    with pytest.raises(ParameterError, match=r"p\.json: not JSON: NaN"):
        ArmParams.from_file(tmp_path / "p.json")
    with pytest.raises(InterventionError, match=r"p\.json: not JSON: NaN"):
        Plan.from_file(tmp_path / "p.json")
    with pytest.raises(ValidationError, match=r"p\.json: not JSON: NaN"):
        read_probes(tmp_path / "p.json")
