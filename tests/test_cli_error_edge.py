"""The command line's one error edge (cli/main.py): every library error becomes a message with
exit status 1, and no message carries a terminal escape from a name it quotes."""

from __future__ import annotations

import ast
from pathlib import Path

from click.testing import CliRunner

from fieldbank.cli.main import cli

ESCAPE = "\x1b]0;pwned\x07\x1b[2J"
ROOT = Path(__file__).resolve().parents[1]


def test_a_plan_file_named_with_an_escape_sequence_is_shown_escaped(tmp_path: Path) -> None:
    plan = tmp_path / f"plan{ESCAPE}.json"
    plan.write_text("{not json", encoding="utf-8")
    r = CliRunner().invoke(cli, ["whatif", "--severity", "elbow=severe", "--plan", str(plan)])
    assert r.exit_code == 1, r.output
    assert "not valid JSON" in r.stderr
    assert "\x1b" not in r.output and "\x07" not in r.output and "\\x1b" in r.stderr


def test_a_usage_error_quoting_what_was_typed_is_shown_escaped(tmp_path: Path) -> None:
    proto = tmp_path / f"proto{ESCAPE}.json"
    proto.write_text("[1, 2", encoding="utf-8")
    r = CliRunner().invoke(cli, ["haptic", "serve", "--robot", "sim://", "--training-protocol",
                                 str(proto), "--station", "--no-db"])
    assert r.exit_code == 2, r.output
    assert "not valid JSON" in r.output
    assert "\x1b" not in r.output and "\x07" not in r.output and "\\x1b" in r.output


def test_no_command_turns_library_errors_into_click_errors_itself() -> None:
    """Commands let FieldbankError through to the edge (which escapes the message)."""
    found = []
    for path in sorted((ROOT / "cli").glob("*.py")):
        if path.name == "main.py":
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ExceptHandler) and node.type is not None:
                names = {n.id for n in ast.walk(node.type) if isinstance(n, ast.Name)}
                if names & {"FieldbankError", "InterventionError", "HapticError"}:
                    found.append(f"{path.name}:{node.lineno}")
    assert not found, found
