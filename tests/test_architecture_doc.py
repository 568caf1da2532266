"""docs/architecture.md's module tables kept true: every module they name exists, and every
module of the project is named.

The page has one section per layer (``### fieldbank (core)``, ``### fieldbank.interventions``,
``### fieldbank.haptic``, ``### fieldbank.cli``). A table row names top-level modules in its
first cell (```maps.py```, or a sub-package ```evaluate/```); a sub-package's row names the
modules inside it in backticks (```design/```, ```score.py```). The command line's section is
prose naming each module in backticks, with or without ``.py``; the migrations row names
their folder. Package ``__init__.py``,
``__main__.py`` and the migrations' revisions are not listed.
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOC = Path("docs") / "architecture.md"
#: section heading's start -> the layer's folder
SECTIONS = {"### fieldbank (core)": "fieldbank", "### fieldbank.interventions": "interventions",
            "### fieldbank.haptic": "haptic", "### fieldbank.cli": "cli"}
TICKED = re.compile(r"`([A-Za-z_][\w/.]*)`")


def _sections(text: str) -> dict[str, str]:
    out: dict[str, str] = {}
    current = None
    for line in text.splitlines():
        if line.startswith("#"):
            current = next((f for h, f in SECTIONS.items() if line.startswith(h)), None)
            continue
        if current is not None:
            out[current] = out.get(current, "") + line + "\n"
    return out


def _rows(section: str) -> list[tuple[list[str], list[str]]]:
    """(names in the first cell, names in the rest) of each table row."""
    out = []
    for line in section.splitlines():
        cells = line.strip().strip("|").split("|")
        if not line.startswith("|") or len(cells) < 2 or set(cells[0].strip()) <= {"-"}:
            continue
        out.append((TICKED.findall(cells[0]), TICKED.findall("|".join(cells[1:]))))
    return out


def _modules(root: Path, folder: str) -> list[Path]:
    return sorted(p.relative_to(root / folder) for p in (root / folder).rglob("*.py")
                  if "__pycache__" not in p.parts and not p.name.startswith("__"))


def doc_problems(root: Path) -> list[str]:
    sections = _sections((root / DOC).read_text(encoding="utf-8"))
    out = []
    for folder in SECTIONS.values():
        text = sections.get(folder, "")
        modules = _modules(root, folder)
        if folder == "cli":
            named = {n.removesuffix(".py") for n in TICKED.findall(text)}
            out += [f"{DOC}: cli/{m} is not listed" for m in modules if m.stem not in named]
            out += [f"{DOC}: lists cli/{n}, which does not exist"
                    for n in sorted(set(TICKED.findall(text)))
                    if n.endswith(".py") and not (root / "cli" / n).is_file()]
            continue
        top: dict[str, list[str]] = {}  # a first-cell name -> the names in its row
        for first, rest in _rows(text):
            for name in first:
                top[name] = top.get(name, []) + rest
        for name, rest in sorted(top.items()):
            where = root / folder / name
            if name.rstrip("/") == "migrations":  # its own folder beside the core's
                where = root / name
            if not (where.is_dir() if name.endswith("/") or name == "migrations"
                    else where.is_file()):
                out.append(f"{DOC}: lists {folder}/{name}, which does not exist")
                continue
            if name.endswith("/"):
                inside = {p.name for p in where.rglob("*.py")} | {
                    p.name + "/" for p in where.rglob("*") if p.is_dir()
                    and p.name != "__pycache__"}
                out += [f"{DOC}: the {folder}/{name} row names {n}, which is not in it"
                        for n in sorted(set(rest)) if n.endswith((".py", "/"))
                        and "/" not in n.rstrip("/") and n not in inside]
        for m in modules:
            head = m.parts[0] + ("/" if len(m.parts) > 1 else "")
            if head not in top:
                out.append(f"{DOC}: {folder}/{m} is not listed (no row for {head})")
            elif len(m.parts) > 1 and m.name not in top[head]:
                out.append(f"{DOC}: {folder}/{m} is not named in the {head} row")
    return out


def test_the_module_tables_are_true() -> None:
    found = doc_problems(ROOT)
    assert not found, "\n".join(found)


def test_a_missing_and_an_unlisted_module_are_caught(tmp_path: Path) -> None:
    for folder in [*SECTIONS.values(), "docs", "migrations"]:
        shutil.copytree(ROOT / folder, tmp_path / folder,
                        ignore=shutil.ignore_patterns("__pycache__"))
    assert doc_problems(tmp_path) == []
    (tmp_path / "fieldbank" / "grading.py").write_text("x = 1\n", encoding="utf-8")
    (tmp_path / "fieldbank" / "evaluate" / "tally.py").write_text("x = 1\n", encoding="utf-8")
    (tmp_path / "interventions" / "spread.py").unlink()
    assert sorted(doc_problems(tmp_path)) == sorted([
        f"{DOC}: fieldbank/grading.py is not listed (no row for grading.py)",
        f"{DOC}: fieldbank/evaluate/tally.py is not named in the evaluate/ row",
        f"{DOC}: lists interventions/spread.py, which does not exist",
    ])
