"""Limits of an ingest: how much a file may hold and what values are plausible.

Lab files come from outside, so every reader is bounded before it allocates: a file larger than
``max_file_bytes`` is refused before it is read; HDF5 and MATLAB v7.3 datasets are refused by
their *declared* shape and type before they are read (a few kB of compressed zeros can declare
gigabytes); MATLAB v5 compressed variables are inflated by a bounded decompressor; CSV rows are
counted as they are read. A batch reports at most ``max_problems`` problems (then how many
more), so a broken 100 MB file yields a readable message, not millions of lines.

Plausibility: a force or stiffness value above ``max_force_n`` / ``max_stiffness_n_per_m`` is
refused with its file and row; it means a wrong unit (mN read as N is 1000× too large) or a
broken recording, not a patient. The defaults are assumptions, set well above anything an arm
puts on a handle: the MAS-4 elbow's peak resistive torque, 9.8 N·m (Pei et al. 2021, BRIEF §3),
is ≈ 30 N at the hand; the sample patients of ``fieldbank samples`` reach 47 N and 4,200 N/m;
the model's most severe arm (every group at MAS 4) reaches ≈ 500 N and ≈ 84,000 N/m only at
the edge of its workspace, where the arm is nearly straight. The healthy co-contracted arm's
endpoint stiffness is ≈ 285 × 73 N/m (Mussa-Ivaldi, Hogan & Bizzi 1985; BRIEF §3).

Every limit is overridable: ``fieldbank ingest --limit NAME=VALUE`` (repeatable) or the
environment variable ``FIELDBANK_INGEST_LIMITS="NAME=VALUE,NAME=VALUE"``; the command line
wins. Messages name the limit that was hit, so the user knows which one to raise.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable
from dataclasses import dataclass, fields, replace

from fieldbank.errors import ParameterError
from fieldbank.validation import Interval, check_fields

ENV_LIMITS = "FIELDBANK_INGEST_LIMITS"
MIB = 1 << 20

#: Allowed range of every limit (messages are generated from it).
LIMIT_BOUNDS: dict[str, Interval] = {
    "max_file_bytes": Interval.whole(1, None, "bytes"),
    "max_decompressed_bytes": Interval.whole(1, None, "bytes"),
    "max_compression_ratio": Interval(1, None, ""),
    "max_rows": Interval.whole(1, None, "rows"),
    "max_maps": Interval.whole(1, None, "maps"),
    "max_problems": Interval.whole(1, None, "problems"),
    "max_force_n": Interval(0, None, "N", low_closed=False),
    "max_stiffness_n_per_m": Interval(0, None, "N/m", low_closed=False),
}


@dataclass(frozen=True)
class IngestLimits:
    """Bounds of one ingest; ranges in :data:`LIMIT_BOUNDS`.

    Attributes
    ----------
    max_file_bytes : int
        Largest file read, bytes (64 MiB; maps files are kB).
    max_decompressed_bytes : int
        Largest total of the arrays and variables read from one file after decompression,
        bytes, as declared by the file (256 MiB).
    max_compression_ratio : float
        Largest ratio of that total to the file's size once it exceeds 1 MiB (1000; lab data
        compress 2-50×, a decompression bomb 10⁶×).
    max_rows : int
        Most points (rows) in one map (100,000; lab maps hold 9-100).
    max_maps : int
        Most maps in one file (1,000).
    max_problems : int
        Most problems listed per file and per batch; the rest are counted (100).
    max_force_n : float, N
        Largest plausible force component or standard deviation (1,000 N).
    max_stiffness_n_per_m : float, N/m
        Largest plausible stiffness entry or standard deviation (100,000 N/m).
    """

    max_file_bytes: int = 64 * MIB
    max_decompressed_bytes: int = 256 * MIB
    max_compression_ratio: float = 1000.0
    max_rows: int = 100_000
    max_maps: int = 1000
    max_problems: int = 100
    max_force_n: float = 1000.0
    max_stiffness_n_per_m: float = 100_000.0

    def __post_init__(self) -> None:
        check_fields(self, LIMIT_BOUNDS, what="ingest limit")

    @classmethod
    def from_items(cls, items: Iterable[str], base: IngestLimits | None = None,
                   where: str = "--limit") -> IngestLimits:
        """``base`` (defaults) with ``NAME=VALUE`` items applied; ParameterError naming the
        item and the known limits otherwise."""
        known = [f.name for f in fields(cls)]
        changes: dict[str, float | int] = {}
        for item in items:
            name, sep, text = item.partition("=")
            name = name.strip()
            if not sep or name not in known:
                raise ParameterError(f"{where} {item!r}: expected NAME=VALUE with NAME one of "
                                     f"{', '.join(known)}.")
            try:
                value = float(text.strip())
            except ValueError:
                raise ParameterError(f"{where} {item!r}: {text.strip()!r} is not a number.") \
                    from None
            if LIMIT_BOUNDS[name].integer and math.isfinite(value) and value == int(value):
                changes[name] = int(value)
            else:
                changes[name] = value
        return replace(base or cls(), **changes)  # type: ignore[arg-type]

    @classmethod
    def from_environment(cls, items: Iterable[str] = ()) -> IngestLimits:
        """The defaults, then ``FIELDBANK_INGEST_LIMITS``, then ``items`` (the command line)."""
        env = os.environ.get(ENV_LIMITS, "")
        base = cls.from_items([p for p in env.split(",") if p.strip()], where=ENV_LIMITS)
        return cls.from_items(items, base)

    def hint(self, name: str) -> str:
        """``(limit NAME = VALUE; raise it with --limit NAME=…)`` for messages."""
        value = getattr(self, name)
        shown = f"{value:,}" if isinstance(value, int) else f"{value:g}"
        return f"(limit {name} = {shown}; raise it with --limit {name}=…)"


DEFAULT_LIMITS = IngestLimits()


class LimitExceeded(Exception):
    """A reader hit a limit; its message is the located problem (internal to ingest)."""
