"""The Dask settings fieldbank's cluster runs with: ``dask.yaml`` beside its certificates.

A Dask scheduler, worker and nanny each wake up many times a second when they have nothing to
do: an event-loop health check every 20 ms, a system monitor (CPU, memory, network and disk
counters through psutil) every 500 ms, and in the worker a statistical profiler that looks at
every task thread every 10 ms and a memory check every 100 ms (in its nanny too). A fit keeps
a worker busy for under a second of CPU; on a shared or loaded machine that background is
paid for every second of wall time, and it was most of the overhead per task of a cohort
refit (docs/scale-out.md, "Measured"). The settings here make those timers less frequent or
stop the profiler, each for a stated price (:data:`SETTINGS`). One more setting is about
memory, not timers: Dask's nanny starts each worker with glibc's ``MALLOC_TRIM_THRESHOLD_`` at
64 kB, which also fixes glibc's mmap threshold at 128 kB, so every array above 128 kB - the
what-if intervals' and the report's (S, N, 6) arrays - is mapped and unmapped and its pages
faulted in again on every use; the settings here put both thresholds near glibc's own dynamic
ceilings (mallopt(3): M_MMAP_THRESHOLD up to 32 MiB on 64-bit, M_TRIM_THRESHOLD twice that).

``fieldbank cluster certs`` writes them as ``dask.yaml`` into the certificates' directory
(:func:`dask_yaml`), and the commands it prints start the scheduler and the workers with
``DASK_CONFIG=…/dask.yaml``: Dask reads that file after its own defaults and the user's
``~/.config/dask``, and ``DASK_DISTRIBUTED__…`` environment variables still override it. A
cluster started without the variable keeps Dask's defaults: nothing here changes a cluster
that does not ask for it. Measured before/after on idle processes by
``benchmarks/bench_worker_idle.py``. The names and the defaults are Dask's own
(``distributed/distributed-schema.yaml`` documents each key).
"""

from __future__ import annotations

import textwrap
from dataclasses import dataclass

#: The file's name in the certificates' directory.
CONFIG_FILE = "dask.yaml"


@dataclass(frozen=True)
class Setting:
    """One Dask configuration key: the value fieldbank's cluster uses, Dask's default, which
    processes it touches, and what the change costs."""

    key: str
    value: bool | str | int
    dask_default: bool | str | int | None
    applies_to: str
    cost: str

    @property
    def _env_parts(self) -> tuple[list[str], list[str]]:
        """The key's parts an environment variable can name, and the rest: Dask lower-cases
        a variable's name, so a key with capitals (a variable a nanny sets for its worker) is
        reached through its parent mapping, whose value the variable gives as a literal."""
        parts = self.key.split(".")
        cut = next((i for i, p in enumerate(parts) if p != p.lower()), len(parts))
        return parts[:cut], parts[cut:]

    @property
    def env_name(self) -> str:
        """The environment variable that sets the key alone (``DASK_`` + the key's parts
        joined by ``__``, dashes as underscores), as Dask reads it."""
        named, _ = self._env_parts
        return "DASK_" + "__".join(p.upper().replace("-", "_") for p in named)

    @property
    def env_value(self) -> str:
        _, rest = self._env_parts
        value: object = self.value
        for p in reversed(rest):  # Dask merges the mapping into its own
            value = {p: value}
        return value if isinstance(value, str) else repr(value)


SETTINGS: tuple[Setting, ...] = (
    Setting("distributed.worker.profile.enabled", False, True, "workers",
            "no statistical profile: the dashboard's Profile page, Client.profile() and the "
            "profile in a performance report stay empty; the task stream, progress and memory "
            "views are unchanged"),
    Setting("distributed.admin.tick.interval", "500ms", "20ms",
            "scheduler, workers and nannies",
            "the event loop's health is sampled every 0.5 s instead of every 20 ms (the "
            "tick-duration figures of the dashboard and of Prometheus are coarser); a stall "
            "longer than distributed.admin.tick.limit (3 s) is still logged"),
    Setting("distributed.admin.system-monitor.interval", "2s", "500ms",
            "scheduler, workers and nannies",
            "the dashboard's CPU, memory and network plots of each process get a point every "
            "2 s instead of every 0.5 s"),
    Setting("distributed.worker.memory.monitor-interval", "500ms", "100ms",
            "workers and nannies",
            "a worker is paused, spilled or restarted for its memory up to 0.5 s after it "
            "crosses the threshold instead of 0.1 s: a task that allocates faster than that "
            "overshoots by what it allocates in 0.4 s (a fit holds a few MB)"),
    Setting("distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_", 67108864, 65536,
            "workers (their nanny sets it when it starts them)",
            "a worker gives freed memory at the top of its heap back to the system only "
            "beyond 64 MiB instead of 64 kB: its resident size stays up to 64 MiB above what "
            "it holds (Dask's memory view counts that as unmanaged memory)"),
    Setting("distributed.nanny.pre-spawn-environ.MALLOC_MMAP_THRESHOLD_", 33554432, None,
            "workers (their nanny sets it when it starts them)",
            "arrays up to 32 MiB come from the heap and are reused instead of being mapped "
            "afresh for each use; memory freed in the middle of the heap is returned only as "
            "the heap's top is trimmed"),
)


def as_nested(settings: tuple[Setting, ...] = SETTINGS) -> dict[str, object]:
    """The settings as Dask's nested configuration mapping."""
    out: dict[str, object] = {}
    for s in settings:
        *parents, leaf = s.key.split(".")
        node = out
        for p in parents:
            child = node.setdefault(p, {})
            assert isinstance(child, dict)
            node = child
        node[leaf] = s.value
    return out


def dask_yaml(settings: tuple[Setting, ...] = SETTINGS) -> str:
    """The text of ``dask.yaml``: each key with what it costs as a comment above it."""
    lines = ["# Dask settings for a fieldbank cluster (docs/scale-out.md, \"Quieter workers\").",
             "# Read when DASK_CONFIG names this file, after Dask's defaults and ~/.config/dask;",
             "# DASK_DISTRIBUTED__... environment variables still override it.",
             "# Delete a key to keep Dask's default for it."]

    def emit(node: dict[str, object], path: tuple[str, ...], indent: int) -> None:
        for name, value in node.items():
            key = ".".join((*path, name))
            pad = "  " * indent
            if isinstance(value, dict):
                lines.append(f"{pad}{name}:")
                emit(value, (*path, name), indent + 1)
                continue
            s = next(s for s in settings if s.key == key)
            note = f"Dask's default {_yaml_scalar(s.dask_default)}; costs: {s.cost}."
            lines.extend(textwrap.wrap(note, 88, initial_indent=f"{pad}# ",
                                       subsequent_indent=f"{pad}# "))
            lines.append(f"{pad}{name}: {_yaml_scalar(value)}")

    emit(as_nested(settings), (), 0)
    return "\n".join(lines) + "\n"


def _yaml_scalar(value: object) -> str:
    if value is None:
        return "not set"
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)
