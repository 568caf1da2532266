"""A click group whose commands are imported only when one of them runs.

Each command is registered by name with the module and attribute that define it and its
one-line help, so ``fieldbank --help`` lists every command without importing any, and
``fieldbank haptic switch B`` imports the control client and nothing else. A test
(tests/test_cli_lazy.py) checks that each registered help line is the command's own.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import click


@dataclass(frozen=True)
class LazyCommand:
    """Where a command lives: ``module`` defines it as ``attribute``; ``help`` is its line."""

    module: str
    attribute: str
    help: str

    def load(self) -> click.Command:
        cmd = getattr(importlib.import_module(self.module), self.attribute)
        if not isinstance(cmd, click.Command):
            raise TypeError(f"{self.module}.{self.attribute} is not a click command")
        return cmd


class LazyGroup(click.Group):
    """A group with commands given by name → :class:`LazyCommand`, loaded on first use."""

    def __init__(self, *args: Any, lazy: Mapping[str, LazyCommand] | None = None,
                 **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.lazy: dict[str, LazyCommand] = dict(lazy or {})

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted({*super().list_commands(ctx), *self.lazy})

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name in self.lazy and cmd_name not in self.commands:
            self.add_command(self.lazy[cmd_name].load(), cmd_name)
        return super().get_command(ctx, cmd_name)

    def resolve_command(self, ctx: click.Context,
                        args: list[str]) -> tuple[str | None, click.Command | None, list[str]]:
        """As click's, but a mistyped name is compared with every registered command, not
        only those loaded so far: ``fieldbank modles`` says "Did you mean 'models'?"."""
        name = args[0] if args else ""
        if (not ctx.resilient_parsing and name and not name.startswith("-")
                and self.get_command(ctx, name) is None):
            raise click.exceptions.NoSuchCommand(name, possibilities=self.list_commands(ctx),
                                                 ctx=ctx)
        return super().resolve_command(ctx, args)

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        """The command list from the registered help lines: no command module is imported."""
        rows = []
        for name in self.list_commands(ctx):
            if name in self.commands:
                cmd = self.commands[name]
                if cmd.hidden:
                    continue
                rows.append((name, cmd.get_short_help_str(formatter.width)))
            else:
                rows.append((name, self.lazy[name].help))
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)
