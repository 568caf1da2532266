"""The layer rule (fieldbank/__init__.py), enforced on the source tree.

    fieldbank (core)  <-  fieldbank.interventions, fieldbank.haptic  <-  fieldbank.cli

Every import in every module counts - at module level, inside functions, under
``TYPE_CHECKING`` - and so does ``importlib.import_module`` with a literal name. The library
layers (core, interventions, haptic) may not import project modules inside functions at all:
that is how cycles were dodged before, and a layer rule that looks only at module level could be
dodged the same way. The last tests show the check failing on deliberately misplaced imports.
"""

from __future__ import annotations

import ast
import shutil
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: repository folder -> (installed package, layer)
FOLDERS = {"fieldbank": ("fieldbank", "core"), "migrations": ("fieldbank.migrations", "core"),
           "interventions": ("fieldbank.interventions", "interventions"),
           "haptic": ("fieldbank.haptic", "haptic"), "cli": ("fieldbank.cli", "cli")}
#: layer -> layers it may import from
ALLOWED = {"core": {"core"}, "interventions": {"core", "interventions"},
           "haptic": {"core", "haptic"}, "cli": {"core", "interventions", "haptic", "cli"}}
#: top-level names that exist only as repository folders, never as installed modules
GENERIC = {"cli", "haptic", "interventions", "migrations"}


def layer_of(module: str) -> str | None:
    """The layer of an installed module name, None for third-party and standard modules."""
    parts = module.split(".")
    if parts[0] != "fieldbank":
        return None
    if len(parts) > 1 and parts[1] in ("interventions", "haptic", "cli"):
        return parts[1]
    return "core"


def _module_name(path: Path, root: Path) -> tuple[str, str]:
    rel = path.relative_to(root)
    package, layer = FOLDERS[rel.parts[0]]
    inner = [p for p in rel.with_suffix("").parts[1:] if p != "__init__"]
    return ".".join([package, *inner]), layer


def _imported(node: ast.AST, module: str, is_package: bool) -> list[str]:
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    if isinstance(node, ast.ImportFrom):
        if node.level:  # relative: resolve against this module's package
            base = module.split(".") if is_package else module.split(".")[:-1]
            base = base[: len(base) - (node.level - 1)]
            target = ".".join([*base, node.module] if node.module else base)
        else:
            target = node.module or ""
        return [target] + [f"{target}.{a.name}" for a in node.names]
    if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
            and node.func.attr == "import_module" and node.args
            and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)):
        return [node.args[0].value]
    return []


def violations(source: str, module: str, layer: str, where: str,
               is_package: bool = False) -> list[str]:
    """Every import in ``source`` (the module ``module`` of ``layer``) that breaks the rule."""
    out: list[str] = []
    tree = ast.parse(source)

    def visit(node: ast.AST, in_function: bool) -> None:
        for name in _imported(node, module, is_package):
            top = name.split(".")[0]
            target = layer_of(name)
            line = getattr(node, "lineno", 0)
            if top in GENERIC:
                out.append(f"{where}:{line}: imports {name!r}, which is not installed; "
                           f"use 'fieldbank.{name}'")
            elif target is not None and target not in ALLOWED[layer]:
                out.append(f"{where}:{line}: {layer} module imports {name} ({target} layer)")
            elif target is not None and in_function and layer != "cli":
                out.append(f"{where}:{line}: imports {name} inside a function "
                           "(library layers import project modules at module level)")
            if target is not None:
                break  # one finding per statement is enough
        inner = in_function or isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef,
                                                 ast.Lambda))
        for child in ast.iter_child_nodes(node):
            visit(child, inner)

    visit(tree, False)
    return out


def check_tree(root: Path) -> list[str]:
    out: list[str] = []
    for folder in FOLDERS:
        for path in sorted((root / folder).rglob("*.py")):
            module, layer = _module_name(path, root)
            out += violations(path.read_text(encoding="utf-8"), module, layer,
                              str(path.relative_to(root)), path.name == "__init__.py")
    return out


def test_the_source_tree_keeps_the_layer_rule() -> None:
    found = check_tree(ROOT)
    assert not found, "\n".join(found)


def test_the_rule_is_written_where_the_package_starts() -> None:
    doc = ast.get_docstring(ast.parse((ROOT / "fieldbank" / "__init__.py").read_text()))
    assert doc and "interventions" in doc and "haptic" in doc and "never" in doc


# --- the check fails on misplaced imports -----------------------------------------------------

def test_a_misplaced_import_in_a_copy_of_the_tree_is_caught(tmp_path: Path) -> None:
    for folder in FOLDERS:
        shutil.copytree(ROOT / folder, tmp_path / folder,
                        ignore=shutil.ignore_patterns("__pycache__"))
    assert check_tree(tmp_path) == []
    target = tmp_path / "haptic" / "__init__.py"
    target.write_text(target.read_text() + "\nfrom fieldbank.interventions import Plan\n")
    found = check_tree(tmp_path)
    assert len(found) == 1
    assert found[0].startswith("haptic/__init__.py:") and "haptic module imports" in found[0]


def test_each_kind_of_misplaced_import_is_caught() -> None:
    def v(src: str, module: str = "fieldbank.maps", layer: str = "core") -> list[str]:
        return violations(src, module, layer, "x.py")

    assert v("import numpy\nfrom fieldbank.model import Arm\n") == []
    assert v("from fieldbank.interventions.plan import Plan\n")  # core -> interventions
    assert v("from fieldbank.cli.options import db_option\n")  # core -> cli
    assert v("def f():\n    from fieldbank.haptic import renderer\n")  # hidden in a function
    assert v("def f():\n    from fieldbank.model import Arm\n")  # core, but inside a function
    assert v("def f():\n    import matplotlib\n") == []  # heavy third party: allowed
    assert v("if TYPE_CHECKING:\n    from fieldbank.haptic.renderer import Renderer\n")
    assert v("import importlib\nimportlib.import_module('fieldbank.haptic.control')\n")
    assert v("from interventions import Plan\n")  # the repository folder name
    hap = "fieldbank.haptic.renderer"
    assert v("from fieldbank.interventions import Plan\n", hap, "haptic")
    assert v("from ..interventions import plan\n", hap, "haptic")  # relative, same target
    assert v("from . import safety\n", hap, "haptic") == []
    assert v("from fieldbank.haptic import control\n", "fieldbank.interventions.x",
             "interventions")
    cli = "fieldbank.cli.demo"
    assert v("from fieldbank.haptic import session\nfrom fieldbank.interventions import "
             "whatif\n", cli, "cli") == []
    assert v("def f():\n    from fieldbank.storage import Database\n", cli, "cli") == []


# --- inside a layer: no arrow runs back up -----------------------------------------------------

def _unit(module: str, package: str) -> str:
    """The unit of a layer's own picture a module of ``package`` belongs to: a sub-package
    (``fieldbank.evaluate``, ``fieldbank.haptic.remote``) or a top-level module
    (``fieldbank.maps``, ``fieldbank.haptic.session``)."""
    return ".".join(module.split(".")[:package.count(".") + 2])


def _core_unit(module: str) -> str:
    return _unit(module, "fieldbank")


def unit_cycles(root: Path, folder: str) -> list[list[str]]:
    """Cycles between the sub-packages and top-level modules of one layer's folder
    (``fieldbank``: the core; ``haptic``) - every import counts."""
    package, layer = FOLDERS[folder]
    edges: dict[str, set[str]] = {}
    for path in sorted((root / folder).rglob("*.py")):
        module, _ = _module_name(path, root)
        here = _unit(module, package)
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            for name in _imported(node, module, path.name == "__init__.py"):
                there = _unit(name, package)
                if (layer_of(name) == layer and name.startswith(package + ".")
                        and there != here):
                    edges.setdefault(here, set()).add(there)
    cycles: list[list[str]] = []
    state: dict[str, int] = {}

    def visit(unit: str, trail: list[str]) -> None:
        state[unit] = 1
        for nxt in sorted(edges.get(unit, ())):
            if state.get(nxt) == 1:
                cycles.append([*trail[trail.index(nxt):], unit, nxt] if nxt in trail
                              else [unit, nxt])
            elif nxt not in state:
                visit(nxt, [*trail, unit])
        state[unit] = 2

    for unit in sorted(edges):
        if unit not in state:
            visit(unit, [])
    return cycles


def core_cycles(root: Path) -> list[list[str]]:
    """Cycles between the core's sub-packages and top-level modules (every import counts)."""
    return unit_cycles(root, "fieldbank")


def test_no_arrow_runs_back_up_inside_the_core() -> None:
    found = core_cycles(ROOT)
    assert not found, "\n".join(" -> ".join(c) for c in found)


def test_an_arrow_back_up_inside_the_core_is_caught(tmp_path: Path) -> None:
    shutil.copytree(ROOT / "fieldbank", tmp_path / "fieldbank",
                    ignore=shutil.ignore_patterns("__pycache__"))
    assert core_cycles(tmp_path) == []
    # the arrow the severity scale once ran: a top-level module built on evaluate, imported
    # back by evaluate
    (tmp_path / "fieldbank" / "grading.py").write_text(
        "from fieldbank.evaluate.probing import stretch_profile\n")
    compare = tmp_path / "fieldbank" / "evaluate" / "compare.py"
    compare.write_text(compare.read_text() + "\nfrom fieldbank.grading import stretch_profile\n")
    found = core_cycles(tmp_path)
    assert found and any("fieldbank.grading" in c and "fieldbank.evaluate" in c for c in found)


def test_no_arrow_runs_back_up_inside_the_haptic_wing() -> None:
    found = unit_cycles(ROOT, "haptic")
    assert not found, "\n".join(" -> ".join(c) for c in found)


def test_an_arrow_back_up_inside_the_haptic_wing_is_caught(tmp_path: Path) -> None:
    shutil.copytree(ROOT / "haptic", tmp_path / "haptic",
                    ignore=shutil.ignore_patterns("__pycache__"))
    assert unit_cycles(tmp_path, "haptic") == []
    # the arrow the station once ran: its server importing the remote desk, while the
    # clinician's site imports the station's launcher
    server = tmp_path / "haptic" / "station" / "server.py"
    server.write_text(server.read_text() + "\nfrom fieldbank.haptic.remote.desk import Desk\n")
    found = unit_cycles(tmp_path, "haptic")
    assert found and any("fieldbank.haptic.station" in c and "fieldbank.haptic.remote" in c
                         for c in found)
