"""Durable writes: all or nothing, no temporary files left behind."""

from __future__ import annotations

import math
import os
import stat
from pathlib import Path

import pytest

from fieldbank.files import json_finite, write_atomic


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


def test_json_finite() -> None:
    doc = {"a": [1.0, math.nan, {"b": math.inf}], "c": (2, -math.inf), "d": "x"}
    assert json_finite(doc) == {"a": [1.0, None, {"b": None}], "c": [2, None], "d": "x"}
