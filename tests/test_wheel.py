"""The installed distribution: one top-level name, every package inside it, and it works.

Builds the wheel from this checkout, checks its file list, installs it (without dependencies)
into a fresh virtual environment that borrows the development environment's third-party
packages through a plain path entry, and runs it there from an empty directory, so nothing
from the source tree can be picked up by accident.
"""

from __future__ import annotations

import subprocess
import sys
import sysconfig
import venv
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: Repository folders and the package each installs as (pyproject.toml, package-dir).
FOLDERS = {"fieldbank": "fieldbank", "interventions": "fieldbank.interventions",
           "haptic": "fieldbank.haptic", "cli": "fieldbank.cli",
           "migrations": "fieldbank.migrations"}

pytestmark = pytest.mark.slow


def _packages_in_tree() -> set[str]:
    out = set()
    for folder, name in FOLDERS.items():
        for init in (ROOT / folder).rglob("__init__.py"):
            rel = init.parent.relative_to(ROOT / folder).parts
            out.add(".".join((name, *rel)))
    return out


def _python_dirs_in_tree() -> set[str]:
    """Every folder holding Python files, as the package it installs as."""
    out = set()
    for folder, name in FOLDERS.items():
        for py in (ROOT / folder).rglob("*.py"):
            rel = py.parent.relative_to(ROOT / folder).parts
            if "__pycache__" not in rel:
                out.add(".".join((name, *rel)))
    return out


def test_every_folder_of_python_files_is_a_configured_package() -> None:
    """A folder of modules missing from pyproject's ``packages`` makes setuptools print a
    40-line warning on every install (and a wheel that ships it only as data)."""
    import tomllib

    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    packages = set(config["tool"]["setuptools"]["packages"])
    assert _python_dirs_in_tree() <= packages, _python_dirs_in_tree() - packages


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """The wheel and what the build printed."""
    out = tmp_path_factory.mktemp("wheel")
    # built with the locked setuptools of this environment (requirements/dev.lock), not an
    # isolated build that would fetch whatever setuptools the registry holds today
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation",
                        "-v", "-w", str(out), str(ROOT)], capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, "pip wheel failed:\n" + r.stderr[-3000:]
    (whl,) = out.glob("fieldbank-*.whl")
    return whl, r.stdout + r.stderr


@pytest.fixture(scope="module")
def wheel(built: tuple[Path, str]) -> Path:
    return built[0]


def test_the_build_prints_no_packaging_warning(built: tuple[Path, str]) -> None:
    log = built[1]
    assert "absent from the `packages` configuration" not in log
    assert "SetuptoolsDeprecationWarning" not in log


@pytest.fixture(scope="module")
def installed(wheel: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fresh venv holding only the wheel; third-party packages come from the dev venv."""
    env_dir = tmp_path_factory.mktemp("venv")
    venv.create(env_dir, with_pip=True)
    py = env_dir / "bin" / "python"
    subprocess.run([str(py), "-m", "pip", "install", "-q", "--no-deps", "--no-index",
                    str(wheel)], check=True, capture_output=True, text=True, timeout=600)
    site = subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_path("
                           "'purelib'))"], check=True, capture_output=True, text=True)
    # A bare directory line adds the dev venv's packages without running its .pth files (so
    # the editable install's import hook for this checkout stays off).
    (Path(site.stdout.strip()) / "devdeps.pth").write_text(
        sysconfig.get_path("purelib") + "\n", encoding="utf-8")
    return env_dir


def test_wheel_holds_one_top_level_name_and_every_package(wheel: Path) -> None:
    names = zipfile.ZipFile(wheel).namelist()
    top = {n.split("/", 1)[0] for n in names}
    assert {t for t in top if not t.endswith(".dist-info")} == {"fieldbank"}
    pkgs = {str(Path(n).parent).replace("/", ".") for n in names if n.endswith("__init__.py")}
    assert pkgs == _packages_in_tree()
    assert "fieldbank/migrations/alembic.ini" in names
    assert any(n.startswith("fieldbank/migrations/versions/") for n in names)
    assert "fieldbank/py.typed" in names


def _run(env_dir: Path, cwd: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(list(args), cwd=cwd, text=True, capture_output=True, timeout=300,
                          env={"PATH": f"{env_dir / 'bin'}:/usr/bin:/bin",
                               "FIELDBANK_HOME": str(cwd / "home")})


def test_installed_wheel_imports_every_module_and_runs(installed: Path,
                                                       tmp_path: Path) -> None:
    py = str(installed / "bin" / "python")
    code = (
        "import importlib, pkgutil, fieldbank\n"
        "mods = [m.name for m in pkgutil.walk_packages(fieldbank.__path__, 'fieldbank.')\n"
        "        if not m.name.endswith('__main__')  # would run the command\n"
        "        and m.name != 'fieldbank.migrations.env']  # runs only inside alembic\n"
        "for m in mods:\n"
        "    importlib.import_module(m)\n"
        "assert fieldbank.__file__.startswith(__import__('sysconfig').get_path('purelib'))\n"
        "print(len(mods))\n"
    )
    r = _run(installed, tmp_path, py, "-I", "-c", code)
    assert r.returncode == 0, r.stderr
    assert int(r.stdout) > 50
    for generic in ("cli", "haptic", "interventions", "migrations"):
        r = _run(installed, tmp_path, py, "-I", "-c", f"import {generic}")
        assert r.returncode != 0 and "No module named" in r.stderr, generic
    fb = str(installed / "bin" / "fieldbank")
    r = _run(installed, tmp_path, fb, "--version")
    assert r.returncode == 0 and "fieldbank" in r.stdout
    url = f"sqlite:///{tmp_path / 'w.sqlite3'}"
    r = _run(installed, tmp_path, fb, "db", "upgrade", "--db", url)
    assert r.returncode == 0, r.stderr
    r = _run(installed, tmp_path, fb, "db", "current", "--db", url, "--json")
    assert r.returncode == 0 and '"up_to_date": true' in r.stdout, r.stdout + r.stderr
