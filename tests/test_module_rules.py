"""The module rules of docs/architecture.md, kept by tests: no module over 600 lines outside
the tests, and matplotlib imported by one module only (``fieldbank/figures/raster.py``). The
last tests show each check failing on a deliberate violation."""

from __future__ import annotations

import ast
import shutil
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: Folders of the project's own code (tests excluded).
FOLDERS = ("fieldbank", "interventions", "haptic", "cli", "migrations", "benchmarks", "scripts")
MAX_LINES = 600
#: The one module that imports matplotlib (the PNG and PDF writer of every figure).
RASTER = Path("fieldbank") / "figures" / "raster.py"


def _modules(root: Path) -> list[Path]:
    return sorted(p for folder in FOLDERS for p in (root / folder).rglob("*.py")
                  if "__pycache__" not in p.parts)


def oversized(root: Path) -> list[str]:
    """Every module of more than :data:`MAX_LINES` lines, with its length."""
    out = []
    for p in _modules(root):
        n = len(p.read_text(encoding="utf-8").splitlines())
        if n > MAX_LINES:
            out.append(f"{p.relative_to(root)}: {n} lines (at most {MAX_LINES}: split it along "
                       "its seams)")
    return out


def matplotlib_imports(root: Path) -> list[str]:
    """Every import of matplotlib (any form, anywhere in a module) outside :data:`RASTER`."""
    out = []
    for p in _modules(root):
        rel = p.relative_to(root)
        if rel == RASTER:
            continue
        for node in ast.walk(ast.parse(p.read_text(encoding="utf-8"))):
            names: list[str] = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and not node.level:
                names = [node.module or ""]
            elif (isinstance(node, ast.Call) and node.args
                  and isinstance(node.args[0], ast.Constant)
                  and isinstance(node.args[0].value, str)
                  and (getattr(node.func, "attr", None) == "import_module"
                       or getattr(node.func, "id", None) == "__import__")):
                names = [node.args[0].value]
            if any(n.split(".")[0] == "matplotlib" for n in names):
                out.append(f"{rel}:{node.lineno}: imports matplotlib (only {RASTER} may: draw "
                           "with fieldbank.figures and save with fieldbank.figures.save)")
    return out


def test_no_module_is_over_600_lines() -> None:
    found = oversized(ROOT)
    assert not found, "\n".join(found)


def test_matplotlib_is_imported_by_the_raster_writer_only() -> None:
    found = matplotlib_imports(ROOT)
    assert not found, "\n".join(found)
    source = (ROOT / RASTER).read_text(encoding="utf-8")
    tree = ast.parse(source)
    # and there only inside the functions that draw: importing the module loads nothing
    top = [n for n in tree.body if isinstance(n, (ast.Import, ast.ImportFrom))]
    assert not any("matplotlib" in ast.unparse(n) for n in top)
    assert "import matplotlib" in source


# --- the checks fail on deliberate violations -------------------------------------------------

def _copy(tmp_path: Path) -> Path:
    for folder in FOLDERS:
        if (ROOT / folder).exists():
            shutil.copytree(ROOT / folder, tmp_path / folder,
                            ignore=shutil.ignore_patterns("__pycache__"))
    return tmp_path


def test_a_long_module_and_a_second_matplotlib_import_are_caught(tmp_path: Path) -> None:
    root = _copy(tmp_path)
    assert oversized(root) == [] and matplotlib_imports(root) == []
    (root / "fieldbank" / "grown.py").write_text("x = 1\n" * (MAX_LINES + 1), encoding="utf-8")
    assert oversized(root) == [f"fieldbank/grown.py: {MAX_LINES + 1} lines (at most "
                               f"{MAX_LINES}: split it along its seams)"]
    for source in ("import matplotlib.pyplot as plt\n",
                   "def f():\n    from matplotlib.figure import Figure\n",
                   "import importlib\nimportlib.import_module('matplotlib')\n"):
        (root / "interventions" / "drawing.py").write_text(source, encoding="utf-8")
        found = matplotlib_imports(root)
        assert len(found) == 1 and found[0].startswith("interventions/drawing.py:"), found
