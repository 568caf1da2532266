"""The lock files: complete, hashed, consistent, and what this environment was installed from.

Installs come only from ``requirements/dev.lock`` (scripts/test, CI) and
``requirements/main.lock`` (scripts/demo), refreshed by ``scripts/lock``. These tests fail when a
dependency is added to pyproject.toml without re-locking, when a pin lacks its hashes, when the
two locks disagree, or when the running environment is not the locked one.
"""

from __future__ import annotations

import importlib.metadata
import importlib.util
import re
import tomllib
from pathlib import Path

import pytest
from packaging.markers import Marker
from packaging.requirements import Requirement

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("lock_report", ROOT / "scripts" / "lock_report.py")
assert _spec is not None and _spec.loader is not None
lock_report = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(lock_report)


def _norm(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def _entries(path: Path) -> list[tuple[str, str, str, list[str]]]:
    """``(name, version, marker, hashes)`` of every requirement in a lock file."""
    out = []
    block: list[str] = []
    for line in [*path.read_text(encoding="utf-8").splitlines(), ""]:
        if line and not line.startswith((" ", "#")):
            block = [line]
        elif block and line.startswith("    --hash"):
            block.append(line)
        elif block:
            m = lock_report._PIN.match(block[0].strip())
            assert m, f"{path.name}: unreadable pin line {block[0]!r}"
            hashes = re.findall(r"sha256:([0-9a-f]{64})", " ".join(block))
            out.append((_norm(m.group(1)), m.group(2), (m.group(3) or "").strip(), hashes))
            block = []
    return out


def _project() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]


def _pinned_names(path: Path) -> set[str]:
    return {name for name, *_ in _entries(path)}


@pytest.mark.parametrize("lock", ["dev.lock", "main.lock"])
def test_every_pin_carries_its_hashes(lock: str) -> None:
    entries = _entries(ROOT / "requirements" / lock)
    assert len(entries) > 20
    for name, version, _marker, hashes in entries:
        assert hashes, f"{lock}: {name}=={version} has no --hash"


def test_every_declared_dependency_is_locked() -> None:
    project = _project()
    extras = project["optional-dependencies"]
    dev = _pinned_names(ROOT / "requirements" / "dev.lock")
    main = _pinned_names(ROOT / "requirements" / "main.lock")
    for text in project["dependencies"] + extras.get("postgres", []):
        name = _norm(Requirement(text).name)
        assert name in main, f"{name} is in pyproject.toml but not in main.lock: run scripts/lock"
        assert name in dev, f"{name} is in pyproject.toml but not in dev.lock: run scripts/lock"
    for text in extras["dev"]:
        name = _norm(Requirement(text).name)
        assert name in dev, f"{name} (dev extra) is not in dev.lock: run scripts/lock"
    assert "setuptools" in main and "setuptools" in dev, "the build backend must be locked"


def test_main_lock_pins_the_same_versions_as_the_dev_lock() -> None:
    dev = {(n, m): v for n, v, m, _ in _entries(ROOT / "requirements" / "dev.lock")}
    for name, version, marker, _ in _entries(ROOT / "requirements" / "main.lock"):
        assert dev.get((name, marker)) == version, (
            f"main.lock pins {name}=={version} [{marker}], dev.lock {dev.get((name, marker))}")


def test_this_environment_was_installed_from_the_dev_lock() -> None:
    wrong = []
    for name, version, marker, _ in _entries(ROOT / "requirements" / "dev.lock"):
        if marker and not Marker(marker).evaluate():
            continue
        try:
            installed = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            wrong.append(f"{name} not installed (lock: {version})")
            continue
        if installed != version:
            wrong.append(f"{name} {installed} installed, lock pins {version}")
    assert not wrong, "run scripts/setup:\n" + "\n".join(wrong)


def test_the_lock_report_names_each_pin_a_fresh_resolution_moves() -> None:
    current = ("numpy==2.4.6 ; python_full_version < '3.12' \\\n    --hash=sha256:" + "a" * 64 +
               "\nscipy==1.17.1 \\\nclick==8.5.1 \\\nold-thing==1.0 \\\n")
    fresh = ("numpy==2.4.7 ; python_full_version < '3.12' \\\nscipy==1.17.1 \\\n"
             "click==8.6.0 \\\nnew-thing==0.1 \\\n")
    lines = lock_report.differences(current, fresh)
    assert len(lines) == 4
    joined = "\n".join(lines)
    assert re.search(r"numpy\s+2\.4\.6 -> 2\.4\.7\s+\[python_full_version < '3\.12'\]", joined)
    assert re.search(r"click\s+8\.5\.1 -> 8\.6\.0", joined)
    assert "old-thing" in joined and "(dropped)" in joined
    assert "new-thing" in joined and "(absent)" in joined
    assert "scipy" not in joined
    assert lock_report.differences(current, current) == []
