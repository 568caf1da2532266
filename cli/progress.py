"""Progress on the terminal for commands that run longer than a few seconds.

A bar on stderr (tqdm), shown only on a terminal: a pipe or a log file gets the command's
messages, not a redrawn line. :func:`robot_time` counts the robot's time - done, the whole and
what is left - for a measurement whose length is the protocol's, not the machine's speed;
:func:`counted` counts steps (trials, simulated patients).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import click


def robot_time_text(done_s: float, total_s: float) -> str:
    """'2.1 of 7.5 min of robot time, 5.4 min left'."""
    unit, scale = ("min", 60.0) if total_s >= 120 else ("s", 1.0)
    left = max(0.0, total_s - done_s)
    return (f"{done_s / scale:.1f} of {total_s / scale:.1f} {unit} of robot time, "
            f"{left / scale:.1f} {unit} left")


@contextmanager
def robot_time(desc: str) -> Iterator[Callable[[float, float], None]]:
    """A callback ``(done_s, total_s)`` that moves a bar of robot time (module docstring)."""
    from tqdm import tqdm

    bar: Any = None
    try:
        def update(done_s: float, total_s: float) -> None:
            nonlocal bar
            if bar is None:
                bar = tqdm(total=round(total_s, 1), desc=desc, leave=False, disable=None,
                           bar_format="{desc}: {percentage:3.0f}%|{bar}| {postfix}")
                if bar.disable:  # no terminal to redraw a bar on: the length, said once
                    click.echo(f"{desc}: {robot_time_text(0.0, total_s)}", err=True)
            bar.n = min(round(done_s, 1), bar.total)
            bar.set_postfix_str(robot_time_text(done_s, total_s), refresh=True)

        yield update
    finally:
        if bar is not None:
            bar.close()


@contextmanager
def counted(desc: str, unit: str) -> Iterator[Callable[[int, int], None]]:
    """A callback ``(done, total)`` that moves a bar of ``unit`` (trials, patients)."""
    from tqdm import tqdm

    bar: Any = None
    try:
        def update(done: int, total: int) -> None:
            nonlocal bar
            if bar is None:
                bar = tqdm(total=total, desc=desc, unit=unit, leave=False, disable=None)
            bar.n = min(done, total)
            bar.refresh()

        yield update
    finally:
        if bar is not None:
            bar.close()
