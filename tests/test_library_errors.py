"""Errors in the tree and configurations checked (docs/architecture.md, "Errors and
configurations"):

* every error the library raises for a caller to see is a :class:`FieldbankError` (the command
  line turns those into a message and exit 1). A bare ``raise ValueError`` / ``TypeError``
  is allowed only where it is part of a protocol and caught in the same package (the listed
  ones), never as the error a user sees;
* every frozen configuration - a frozen dataclass named ``…Config``, ``…Options``,
  ``…Limits``, ``…Settings`` or ``Rules``, or the probe design's ``Perception`` and
  ``NoiseModel``, with a number among its fields - checks its fields against its bounds table
  through :func:`fieldbank.validation.check_fields` when it is made, and so refuses a number
  that is not one.
"""

from __future__ import annotations

import ast
import dataclasses
import importlib
import math
import re
import shutil
from pathlib import Path

import pytest

from fieldbank.errors import FieldbankError

ROOT = Path(__file__).resolve().parents[1]
#: repository folder -> installed package
PACKAGES = {"fieldbank": "fieldbank", "interventions": "fieldbank.interventions",
            "haptic": "fieldbank.haptic"}
BARE = ("ValueError", "TypeError")

#: (module, line's text) of the bare errors that stay, and why.
BARE_ALLOWED = {
    # the settings' parsers: caught in config.setting() and raised as ConfigError
    "fieldbank/config.py": "parsers whose ValueError setting() turns into a ConfigError",
    # a channel's unit: caught by the raw readers (nwbraw, c3draw, kinarm) and raised with
    # the file's name
    "fieldbank/measure/channels.py": "caught by the raw readers, raised naming the file",
    # json.loads(parse_constant=...) must raise ValueError; caught into an ApiError 400
    "fieldbank/web/routes.py": "json's parse_constant protocol, caught into ApiError",
    # json.dumps(default=...) must raise TypeError; write_directory's names come from code
    "fieldbank/files.py": "json's default protocol; a programming error in file names",
    # the figure writers: formats and markers come from code (figure_format checks the user's)
    "fieldbank/figures/raster.py": "a programming error: the format was checked before",
    "fieldbank/figures/scene.py": "a programming error: markers are named in code",
}

CONFIG_NAME = re.compile(r"(Config|Options|Limits|Settings|Rules|Perception|NoiseModel)$")
#: Frozen configurations not checked through check_fields, and why (none).
CONFIG_ALLOWED: dict[str, str] = {}
#: Number fields a configuration leaves out of its bounds table, and why (none).
FIELDS_ALLOWED: dict[tuple[str, str], str] = {}


def _modules(root: Path) -> list[tuple[str, Path]]:
    out = []
    for folder, package in PACKAGES.items():
        for p in sorted((root / folder).rglob("*.py")):
            inner = [s for s in p.relative_to(root / folder).with_suffix("").parts
                     if s != "__init__"]
            out.append((".".join([package, *inner]), p))
    return out


def bare_errors(root: Path = ROOT) -> list[str]:
    """``raise ValueError(...)`` / ``raise TypeError(...)`` outside the allowed places."""
    out = []
    for _module, path in _modules(root):
        rel = path.relative_to(root).as_posix()
        if rel in BARE_ALLOWED:
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Raise) and node.exc is not None:
                exc = node.exc.func if isinstance(node.exc, ast.Call) else node.exc
                if isinstance(exc, ast.Name) and exc.id in BARE:
                    out.append(f"{rel}:{node.lineno}: raise {exc.id} (raise a FieldbankError "
                               "subclass: the command line shows those as messages)")
    return out


def _number_field(f: ast.AnnAssign) -> bool:
    text = ast.unparse(f.annotation)
    return bool(re.fullmatch(r"(float|int)( \| None)?", text))


def configurations(root: Path = ROOT) -> list[tuple[str, bool]]:
    """(``module.Class``, whether its ``__post_init__`` calls check_fields) of every frozen
    configuration with a number among its fields."""
    out = []
    for module, path in _modules(root):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not (isinstance(node, ast.ClassDef) and CONFIG_NAME.search(node.name)):
                continue
            frozen = any(isinstance(d, ast.Call) and any(
                k.arg == "frozen" and isinstance(k.value, ast.Constant) and k.value.value is True
                for k in d.keywords) for d in node.decorator_list)
            if not frozen or not any(isinstance(s, ast.AnnAssign) and _number_field(s)
                                     for s in node.body):
                continue
            post = [s for s in node.body
                    if isinstance(s, ast.FunctionDef) and s.name == "__post_init__"]
            calls = bool(post) and any(
                isinstance(n, ast.Call) and getattr(n.func, "id", None) == "check_fields"
                for n in ast.walk(post[0]))
            out.append((f"{module}.{node.name}", calls))
    return out


def test_every_library_error_is_in_the_tree() -> None:
    found = bare_errors()
    assert not found, "\n".join(found)


def test_every_frozen_configuration_checks_its_fields() -> None:
    found = configurations()
    # the ones the review found unchecked are among those found
    names = {n for n, _ in found}
    assert {"fieldbank.measure.estimate.EstimatorConfig", "fieldbank.measure.segment."
            "SegmentConfig", "fieldbank.sim.CouplingConfig", "fieldbank.interventions."
            "realised.Rules", "fieldbank.measure.protocol.ProtocolConfig"} <= names
    unchecked = [n for n, calls in found if not calls and n not in CONFIG_ALLOWED]
    assert not unchecked, unchecked


def _default(name: str) -> object | None:
    module, cls = name.rsplit(".", 1)
    try:
        return getattr(importlib.import_module(module), cls)()
    except TypeError:  # fields without defaults: made by their own tests
        return None


#: The configurations a default can be made of, and the defaults.
DEFAULTS = {n: v for n, calls in configurations() if calls
            and (v := _default(n)) is not None}


def test_most_configurations_are_tried() -> None:
    assert len(DEFAULTS) >= 12, sorted(DEFAULTS)


@pytest.mark.parametrize("name", sorted(DEFAULTS))
def test_each_configuration_refuses_a_number_that_is_not_one(name: str) -> None:
    """Every number field, set to NaN, is refused with a FieldbankError naming it."""
    value = DEFAULTS[name]
    numbers = [f.name for f in dataclasses.fields(value)  # type: ignore[arg-type]
               if type(getattr(value, f.name)) in (int, float)
               and (name, f.name) not in FIELDS_ALLOWED]
    assert numbers, name
    for field in numbers:
        with pytest.raises(FieldbankError, match=re.escape(field)):
            dataclasses.replace(value, **{field: math.nan})  # type: ignore[type-var]


# --- the checks fail on deliberate violations -------------------------------------------------

def test_a_bare_error_and_an_unchecked_configuration_are_caught(tmp_path: Path) -> None:
    src = ("from dataclasses import dataclass\n\n\n@dataclass(frozen=True)\nclass DrawConfig:\n"
           "    width_m: float = 1.0\n\n\ndef f(x):\n    if x:\n"
           "        raise ValueError('bad')\n")
    for folder in PACKAGES:
        shutil.copytree(ROOT / folder, tmp_path / folder,
                        ignore=shutil.ignore_patterns("__pycache__"))
    assert bare_errors(tmp_path) == []
    assert all(calls or n in CONFIG_ALLOWED for n, calls in configurations(tmp_path))
    (tmp_path / "fieldbank" / "drawing.py").write_text(src, encoding="utf-8")
    assert bare_errors(tmp_path) == [
        "fieldbank/drawing.py:11: raise ValueError (raise a FieldbankError subclass: the "
        "command line shows those as messages)"]
    assert ("fieldbank.drawing.DrawConfig", False) in configurations(tmp_path)
