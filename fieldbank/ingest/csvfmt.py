"""Reader of the map CSV (BRIEF §11), converting known units to SI.

Layout: ``# key: value`` metadata lines, then a header row, then one row per position. Rows are
located by their line number in the file (``file.csv:row 12``). Columns carry their unit in
their name; see :mod:`fieldbank.ingest.units`.
"""

from __future__ import annotations

import numpy as np

from fieldbank.errors import Problem
from fieldbank.ingest.parsed import RESERVED_KEYS, ParsedMap, parse_velocity
from fieldbank.ingest.units import QUANTITIES, factor, split_column

VALUE_QUANTITIES = {
    "postural": ("fx", "fy"),
    "stiffness": ("kxx", "kxy", "kyx", "kyy"),
}


def read_csv(name: str, data: bytes) -> tuple[list[ParsedMap], list[Problem]]:
    """Parse one CSV map file; returns the map (if the structure allows) and file problems."""
    problems: list[Problem] = []
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        return [], [Problem(name, f"not UTF-8 text (byte {exc.start})")]
    meta: dict[str, str] = {}
    header: list[str] | None = None
    header_line = 0
    rows: list[tuple[int, list[str]]] = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line:
            continue
        if line.startswith("#"):
            body = line[1:].strip()
            key, sep, value = body.partition(":")
            if sep and header is None:
                k = key.strip().lower()
                if k in meta:
                    problems.append(Problem(f"{name}:row {lineno}", f"metadata key {k!r} given "
                                            "twice"))
                meta[k] = value.strip()
            continue
        if header is None:
            header = [c.strip() for c in line.split(",")]
            header_line = lineno
        else:
            rows.append((lineno, line.split(",")))
    if header is None:
        return [], [*problems, Problem(name, "no header row (expected e.g. x_m,y_m,fx_n,fy_n)")]
    kind = meta.get("kind")
    hloc = f"{name}:row {header_line}"
    # Which value columns to expect: from the kind when valid, else guessed from the header.
    shape_kind = kind if kind in VALUE_QUANTITIES else (
        "stiffness" if any((split_column(c) or ("",))[0].startswith("k") for c in header)
        else "postural")
    wanted = ("x", "y", *VALUE_QUANTITIES[shape_kind])
    col: dict[tuple[str, bool], tuple[int, float]] = {}
    for j, c in enumerate(header):
        parts = split_column(c)
        if parts is None:
            problems.append(Problem(hloc, f"unknown column {c!r}; a {shape_kind} map has "
                                    f"{', '.join(_names(shape_kind))} (units in the names)"))
            continue
        q, is_sd, unit = parts
        dim, table = QUANTITIES[q]
        if q not in wanted or (is_sd and q in ("x", "y")):
            problems.append(Problem(hloc, f"column {c!r} does not belong to a {shape_kind} map"))
            continue
        f = factor(unit, table)
        if f is None:
            problems.append(Problem(hloc, f"unknown unit {unit!r} in column {c!r}; known "
                                    f"{dim} units: {', '.join(table)}"))
            continue
        if (q, is_sd) in col:
            problems.append(Problem(hloc, f"column {c!r} repeats quantity "
                                    f"{'sd_' if is_sd else ''}{q}"))
            continue
        col[(q, is_sd)] = (j, f)
    for q in wanted:
        if (q, False) not in col and not any(
            p.reason.startswith(("unknown unit", "column")) and f"'{q}_" in p.reason.lower()
            for p in problems
        ):
            problems.append(Problem(hloc, f"missing column for {q} (e.g. "
                                    f"{_names(shape_kind)[wanted.index(q)]})"))
    vq = VALUE_QUANTITIES[shape_kind]
    sd_present = [q for q in vq if (q, True) in col]
    if sd_present and len(sd_present) != len(vq):
        missing = [f"sd_{q}" for q in vq if q not in sd_present]
        problems.append(Problem(hloc, f"standard deviations incomplete: missing "
                                f"{', '.join(missing)}"))
    n = len(rows)
    pos = np.full((n, 2), np.nan)
    vals = np.full((n, len(vq)), np.nan)
    sd = np.full((n, len(vq)), np.nan) if sd_present and len(sd_present) == len(vq) else None
    reported: set[int] = set()
    lines = [ln for ln, _ in rows]
    for i, (lineno, cells) in enumerate(rows):
        loc = f"{name}:row {lineno}"
        if len(cells) != len(header):
            problems.append(Problem(loc, f"{len(cells)} fields, the header has {len(header)}"))
            reported.add(i)
            continue
        for (q, is_sd), (j, f) in col.items():
            cell = cells[j].strip()
            try:
                v = float(cell)
            except ValueError:
                problems.append(Problem(loc, f"column {header[j]!r}: {cell!r} is not a number"))
                reported.add(i)
                continue
            if q in ("x", "y"):
                pos[i, 0 if q == "x" else 1] = v * f
            elif is_sd:
                if sd is not None:
                    sd[i, vq.index(q)] = v * f
            else:
                vals[i, vq.index(q)] = v * f
    vshape = (n, 2) if shape_kind == "postural" else (n, 2, 2)
    mprobs: list[Problem] = []
    velocity, vmissing = parse_velocity(meta.get("velocity_m_per_s"),
                                        meta.get("velocity_vector_m_per_s"), name, kind, mprobs)
    other = {k: v for k, v in meta.items() if k not in RESERVED_KEYS}
    pm = ParsedMap(
        location=name, kind=kind, frame=meta.get("frame"), sign=meta.get("sign"),
        source=meta.get("source", ""), metadata=other, positions_m=pos,
        values=vals.reshape(vshape), sd=None if sd is None else sd.reshape(vshape),
        velocity_m_per_s=velocity, velocity_missing=vmissing,
        point_location=lambda i: f"{name}:row {lines[i]}", problems=mprobs, reported=reported,
    )
    return [pm], problems


def _names(kind: str) -> list[str]:
    if kind == "postural":
        return ["x_m", "y_m", "fx_n", "fy_n"]
    return ["x_m", "y_m", "kxx_n_per_m", "kxy_n_per_m", "kyx_n_per_m", "kyy_n_per_m"]
