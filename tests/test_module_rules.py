"""The module rules of docs/architecture.md, kept by tests: no module over 600 lines outside
the tests; matplotlib imported by one module only (``fieldbank/figures/raster.py``); no private
name imported from another module; no name passed on by a module that does not define it; no
cycle between the parts of a package. The last tests show each check failing on a deliberate
violation."""

from __future__ import annotations

import ast
import functools
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
        for node in ast.walk(_tree(p)):
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


# --- seams: private names, re-exports, package cycles -----------------------------------------
#
# Where the installed package lives in the repository (pyproject's ``package-dir``).
PACKAGES = {"fieldbank": "fieldbank", "migrations": "fieldbank.migrations",
            "interventions": "fieldbank.interventions", "haptic": "fieldbank.haptic",
            "cli": "fieldbank.cli"}


@functools.cache
def _parse(source: str) -> ast.Module:
    """A module's tree, parsed once per text (the checks below read the same files often)."""
    return ast.parse(source)


def _tree(path: Path) -> ast.Module:
    return _parse(path.read_text(encoding="utf-8"))


def _library(root: Path) -> dict[str, tuple[Path, bool]]:
    """Installed module name -> (file, is a package's ``__init__``) for every project module."""
    out = {}
    for folder, package in PACKAGES.items():
        for p in sorted((root / folder).rglob("*.py")):
            if "__pycache__" in p.parts:
                continue
            inner = [s for s in p.relative_to(root / folder).with_suffix("").parts
                     if s != "__init__"]
            out[".".join([package, *inner])] = (p, p.name == "__init__.py")
    return out


def _from_target(node: ast.ImportFrom, module: str, is_package: bool) -> str:
    if not node.level:
        return node.module or ""
    base = module.split(".") if is_package else module.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join([*base, node.module] if node.module else base)


def _imports(root: Path, tests: bool = False):
    """(module, file, line, source module, name) for every ``from source import name`` of a
    project module, and (module, file, line, target module, None) for every plain import;
    with ``tests``, the imports of the test modules as well."""
    modules = _library(root)
    importers = dict(modules)
    if tests:
        importers |= {f"tests.{p.stem}": (p, False) for p in sorted((root / "tests").glob("*.py"))}
    for module, (path, is_package) in importers.items():
        tree = _tree(path)
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                source = _from_target(node, module, is_package)
                if source in modules:
                    for alias in node.names:
                        yield module, path, node.lineno, source, alias.name
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name in modules:
                        yield module, path, node.lineno, alias.name, None


#: Private names imported across modules that are allowed, with why (none outside haptic/).
PRIVATE_ALLOWED: dict[tuple[str, str, str], str] = {}


def private_imports(root: Path) -> list[str]:
    """Every ``from module import _name`` of a private name (one underscore, not a dunder)
    from another project module: a private name is private to the module that defines it; a
    neighbour that needs it needs a public seam."""
    out = []
    for module, path, line, source, name in _imports(root):
        if (name and name.startswith("_") and not name.startswith("__") and source != module
                and (module, source, name) not in PRIVATE_ALLOWED):
            out.append(f"{path.relative_to(root)}:{line}: imports the private name {name} "
                       f"from {source} (give it a public name where it is defined)")
    return out


def _defined(tree: ast.Module) -> set[str]:
    """Names a module defines itself: functions, classes, assignments at module level."""
    out: set[str] = set()
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            out.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign, ast.AugAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for t in targets:
                out |= {n.id for n in ast.walk(t) if isinstance(n, ast.Name)}
    return out


def _all(tree: ast.Module) -> list[str]:
    for node in tree.body:
        if (isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "__all__"
                                                 for t in node.targets)
                and isinstance(node.value, (ast.List, ast.Tuple))):
            return [e.value for e in node.value.elts
                    if isinstance(e, ast.Constant) and isinstance(e.value, str)]
    return []


#: Names passed on that are allowed, with why (none: each caller imports a name from the module
#: that defines it).
REEXPORT_ALLOWED: dict[tuple[str, str], str] = {}


def reexports(root: Path) -> list[str]:
    """Every name a module passes on without defining it. A module M re-exports a name N when
    N is imported into M from another project module and either M lists N in ``__all__`` or
    another module imports N from M. A package's ``__init__`` is the package's public face and
    may pass on the names of the modules inside it (nothing from outside the package); a
    sub-module imported by name (``from package import module``) is a module, not a name."""
    modules = _library(root)
    imported_into: dict[tuple[str, str], str] = {}  # (module, name) -> its source module
    takers: dict[tuple[str, str], list[tuple[str, Path, int]]] = {}
    for module, path, line, source, name in _imports(root, tests=True):
        if name is None or name == "*" or f"{source}.{name}" in modules:
            continue
        if not module.startswith("tests."):
            imported_into[(module, name)] = source
        takers.setdefault((source, name), []).append((module, path, line))
    out = []
    for module, (path, is_package) in modules.items():
        tree = _tree(path)
        defined = _defined(tree)
        passed = {(n, "lists it in __all__") for n in _all(tree)}
        passed |= {(name, f"{taker} imports it from there ({where.relative_to(root)}:{line})")
                   for (src, name), ts in takers.items() if src == module
                   for taker, where, line in ts}
        for name, how in sorted(passed):
            source = imported_into.get((module, name))
            if source is None or name in defined:
                continue
            if is_package and source.startswith(module + "."):
                continue  # a package's face: its own modules' names
            if (module, name) in REEXPORT_ALLOWED:
                continue
            out.append(f"{path.relative_to(root)}: passes on {name} from {source} without "
                       f"defining it: {how} (import it from {source})")
    return out


#: Package cycles allowed, each a pair of parts, with why (none).
CYCLES_ALLOWED: dict[frozenset[str], str] = {}


def package_cycles(root: Path) -> list[str]:
    """Cycles between the parts of every package. Inside each package the parts are its own
    modules and its sub-packages (a sub-package standing for every module inside it); an import
    from one part of a package to another is an arrow, and the arrows form no cycle. So
    ``interventions/plot.py`` and ``interventions/report/`` may not import each other, nor
    ``haptic/station/`` and ``haptic/remote/``; the layers themselves are tests/test_layers.py's."""
    modules = _library(root)
    packages = {m for m, (_, is_package) in modules.items() if is_package}
    edges: dict[str, dict[str, set[str]]] = {}  # package -> part -> parts

    def part(package: str, module: str) -> str | None:
        if not module.startswith(package + "."):
            return None
        return ".".join(module.split(".")[: package.count(".") + 2])

    for module, _path, _line, source, name in _imports(root):
        target = f"{source}.{name}" if name and f"{source}.{name}" in modules else source
        for package in packages:
            here, there = part(package, module), part(package, target)
            if here and there and here != there:
                edges.setdefault(package, {}).setdefault(here, set()).add(there)
    out = []
    for package in sorted(edges):
        graph = edges[package]
        for a in sorted(graph):
            for b in sorted(graph[a]):
                if a < b and frozenset((a, b)) not in CYCLES_ALLOWED and _reaches(graph, b, a):
                    out.append(f"{package}: {a} and {b} import each other (directly or "
                               "through other parts): a cycle")
    return out


def _reaches(graph: dict[str, set[str]], start: str, goal: str) -> bool:
    seen, todo = set(), [start]
    while todo:
        n = todo.pop()
        if n == goal:
            return True
        if n not in seen:
            seen.add(n)
            todo += graph.get(n, ())
    return False


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


def test_no_private_name_is_imported_from_another_module() -> None:
    found = private_imports(ROOT)
    assert not found, "\n".join(found)


def test_no_module_passes_on_a_name_it_does_not_define() -> None:
    found = reexports(ROOT)
    assert not found, "\n".join(found)


def test_no_package_has_a_cycle_between_its_parts() -> None:
    found = package_cycles(ROOT)
    assert not found, "\n".join(found)


def test_a_private_import_a_passed_on_name_and_a_cycle_are_caught(tmp_path: Path) -> None:
    root = _copy(tmp_path)
    shutil.copytree(ROOT / "tests", root / "tests", ignore=shutil.ignore_patterns("__pycache__"))
    assert private_imports(root) == [] and reexports(root) == [] and package_cycles(root) == []
    core = root / "fieldbank"
    (core / "leaf.py").write_text("def _helper() -> int:\n    return 1\n\n\n"
                                  "def public() -> int:\n    return 2\n", encoding="utf-8")
    # a private name taken across modules, absolute or relative
    for source in ("from fieldbank.leaf import _helper\n", "from .leaf import _helper, public\n"):
        (core / "user.py").write_text(source, encoding="utf-8")
        found = private_imports(root)
        assert len(found) == 1 and found[0].startswith("fieldbank/user.py:1: imports the "
                                                       "private name _helper"), found
        assert reexports(root) == []
    (core / "user.py").write_text("from fieldbank.leaf import public\n", encoding="utf-8")
    assert private_imports(root) == [] and reexports(root) == []
    # a name passed on: listed in __all__, or imported from the module that only imported it
    (core / "user.py").write_text("from fieldbank.leaf import public\n\n__all__ = ['public']\n",
                                  encoding="utf-8")
    found = reexports(root)
    assert len(found) == 1 and "fieldbank/user.py: passes on public from fieldbank.leaf" in \
        found[0] and "__all__" in found[0], found
    (core / "user.py").write_text("from fieldbank.leaf import public\n", encoding="utf-8")
    (root / "tests" / "test_taker.py").write_text("from fieldbank.user import public\n",
                                                  encoding="utf-8")
    found = reexports(root)
    assert len(found) == 1 and "tests.test_taker imports it from there" in found[0], found
    (root / "tests" / "test_taker.py").unlink()
    # ... but a package's face may pass on its own modules' names, and a module its own
    (core / "figures" / "__init__.py").write_text(
        (core / "figures" / "__init__.py").read_text() + "\nfrom fieldbank.figures.scene "
        "import Scene as Scene\n", encoding="utf-8")
    (core / "user.py").write_text("from fieldbank.figures import Scene\n", encoding="utf-8")
    assert reexports(root) == []
    # a cycle between two parts of a package: a module and a sub-package of the same layer
    common = root / "interventions" / "report" / "figures" / "common.py"
    common.write_text(common.read_text() + "\nfrom fieldbank.interventions.plot import "
                      "NOTE_CHARS\n", encoding="utf-8")
    found = package_cycles(root)
    assert found == ["fieldbank.interventions: fieldbank.interventions.plot and "
                     "fieldbank.interventions.report import each other (directly or through "
                     "other parts): a cycle"], found


def test_one_class_is_named_plan() -> None:
    """A plan is a treatment (fieldbank.interventions.plan.Plan); the measuring protocol's
    timetable is a ProtocolPlan."""
    named = [str(path.relative_to(ROOT))
             for path, _ in _library(ROOT).values()
             for node in ast.walk(_tree(path))
             if isinstance(node, ast.ClassDef) and node.name == "Plan"]
    assert named == ["interventions/plan.py"], named
