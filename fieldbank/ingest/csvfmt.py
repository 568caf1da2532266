"""Reader of the map CSV (BRIEF §11), converting known units to SI.

Layout: ``# key: value`` metadata lines, then a header row, then one row per position. Rows are
located by their line number in the file (``file.csv:row 12``). Columns carry their unit in
their name; see :mod:`fieldbank.ingest.units`.

Cells are split by the standard library's :mod:`csv` module, whose :class:`csv.Sniffer` finds
the dialect from the header and the first rows: comma, semicolon or tab delimiters and quoted
cells (R's ``write.csv`` quotes every header and writes an unnamed first column of row names,
which is dropped). A file whose delimiter is a semicolon or a tab may write decimal commas
(``0,05``; R's ``write.csv2``, spreadsheets in many locales); such a file must then use them
throughout, since ``1.000`` would be ambiguous there.

Text is UTF-8; a file in another encoding (a spreadsheet's Windows-1252, UTF-16) is decoded
with the encoding ``charset-normalizer`` detects, said in the map's ``text_encoding``, or
refused with "save it as UTF-8" when the encoding cannot be told apart (:func:`decode_text`).

Numbers are parsed strictly: ASCII digits, an optional sign, one decimal separator and an
exponent (``-1.5e-3``); ``nan`` and ``inf`` are read so that the validation can name them. No
``1_000``, no thousands separators, no Arabic-Indic or other non-ASCII digits — Python's
``float()`` accepts those, a lab file must not. A header with problems is reported once; its
rows are not parsed (they would each repeat it).
"""

from __future__ import annotations

import csv
import re
from collections.abc import Mapping

import numpy as np

from fieldbank.errors import Problem
from fieldbank.ingest.limits import DEFAULT_LIMITS, IngestLimits
from fieldbank.ingest.parsed import RESERVED_KEYS, ParsedMap, parse_velocity
from fieldbank.ingest.units import QUANTITIES, split_column
from fieldbank.units import factor

VALUE_QUANTITIES = {
    "postural": ("fx", "fy"),
    "stiffness": ("kxx", "kxy", "kyx", "kyy"),
}
DELIMITERS = ",;\t"
#: Lines given to the sniffer (the header and the first rows).
SNIFF_LINES = 6

_NUMBER = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?", re.ASCII)
_NUMBER_COMMA = re.compile(r"[+-]?(?:[0-9]+(?:,[0-9]*)?|,[0-9]+)(?:[eE][+-]?[0-9]+)?",
                           re.ASCII)
_DECIMAL_COMMA = re.compile(r"[+-]?[0-9]*,[0-9]+(?:[eE][+-]?[0-9]+)?", re.ASCII)
_SPECIAL = re.compile(r"[+-]?(?:nan|inf|infinity)", re.ASCII | re.IGNORECASE)


def parse_number(cell: str, decimal_comma: bool = False) -> float | None:
    """``cell`` as a float under the strict grammar above, else None."""
    text = cell.strip()
    if _SPECIAL.fullmatch(text):
        return float(text)
    if decimal_comma:
        return float(text.replace(",", ".")) if _NUMBER_COMMA.fullmatch(text) else None
    return float(text) if _NUMBER.fullmatch(text) else None


def _dialect(lines: list[str]) -> type[csv.Dialect] | csv.Dialect:
    sample = "\n".join(lines[:SNIFF_LINES])
    try:
        dialect = csv.Sniffer().sniff(sample, delimiters=DELIMITERS)
    except csv.Error:
        dialect = None
    if dialect is None or dialect.delimiter not in DELIMITERS:
        # a single-line file or a header alone: the delimiter the header uses most
        head = lines[0] if lines else ""
        delim = max(DELIMITERS, key=head.count) if any(d in head for d in DELIMITERS) else ","

        class Fallback(csv.excel):
            delimiter = delim

        return Fallback
    dialect.skipinitialspace = True
    return dialect


def read_csv(name: str, data: bytes, limits: IngestLimits = DEFAULT_LIMITS,
             defaults: Mapping[str, str] | None = None,
             columns: Mapping[str, str] | None = None
             ) -> tuple[list[ParsedMap], list[Problem]]:
    """Parse one CSV map file; returns the map (if the structure allows) and file problems.

    ``defaults``: metadata the file may lack (kind, frame, sign, velocity; a file that states
    another value is a problem); ``columns``: our column name → the file's header
    (:class:`fieldbank.ingest.options.ReadOptions`).
    """
    problems: list[Problem] = []
    text, encoding, why = decode_text(data)
    if text is None:
        return [], [Problem(name, why)]
    meta: dict[str, str] = {}
    body: list[tuple[int, str]] = []  # (line number, text) of the header and data rows
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line:
            continue
        if line.startswith("#"):
            key, sep, value = line[1:].strip().partition(":")
            if sep and not body:
                k = key.strip().lower()
                if k in meta:
                    problems.append(Problem(f"{name}:row {lineno}", f"metadata key {k!r} given "
                                            "twice"))
                meta[k] = value.strip()
            continue
        if len(body) >= limits.max_rows + 1:
            problems.append(Problem(f"{name}:row {lineno}", f"more than {limits.max_rows:,} "
                                    f"data rows {limits.hint('max_rows')}"))
            return [], problems
        body.append((lineno, raw))
    if not body:
        return [], [*problems, Problem(name, "no header row (expected e.g. x_m,y_m,fx_n,fy_n)")]
    for key, value in (defaults or {}).items():
        stated = meta.get(key)
        if stated is None:
            meta[key] = value
        elif stated.strip().lower() != value.strip().lower() and key != "velocity_m_per_s":
            problems.append(Problem(name, f"the file says {key}: {stated!r}, the command "
                                    f"line says {value!r}; remove one"))
    dialect = _dialect([t for _, t in body])
    rows = list(csv.reader([t for _, t in body], dialect))
    header_line = body[0][0]
    header = [c.strip() for c in rows[0]]
    cells_of = [(body[i][0], r) for i, r in enumerate(rows[1:], start=1)]
    row_names = bool(header) and header[0] == "" and len(header) > 1
    if row_names:  # R's write.csv: an unnamed first column of row names
        header = header[1:]
        cells_of = [(ln, r[1:]) for ln, r in cells_of]
    for ours, theirs in (columns or {}).items():
        if theirs in header:
            header[header.index(theirs)] = ours
        else:
            problems.append(Problem(f"{name}:row {header_line}", f"--column {ours}={theirs}: "
                                    f"the file has no column {theirs!r} (columns: "
                                    f"{', '.join(header)})"))
    if encoding:
        meta.setdefault("text_encoding", f"{encoding} (detected; the file is not UTF-8)")
    kind = meta.get("kind")
    hloc = f"{name}:row {header_line}"
    # Which value columns to expect: from the kind when valid, else guessed from the header.
    shape_kind = kind if kind in VALUE_QUANTITIES else (
        "stiffness" if any((split_column(c) or ("",))[0].startswith("k") for c in header)
        else "postural")
    wanted = ("x", "y", *VALUE_QUANTITIES[shape_kind])
    hprobs: list[Problem] = []
    col: dict[tuple[str, bool], tuple[int, float]] = {}
    for j, c in enumerate(header):
        parts = split_column(c)
        if parts is None:
            hprobs.append(Problem(hloc, f"unknown column {c!r}; a {shape_kind} map has "
                                  f"{', '.join(_names(shape_kind))} (units in the names; "
                                  f"cells split at {_delimiter_name(dialect.delimiter)})"))
            continue
        q, is_sd, unit = parts
        dim, table = QUANTITIES[q]
        if q not in wanted or (is_sd and q in ("x", "y")):
            hprobs.append(Problem(hloc, f"column {c!r} does not belong to a {shape_kind} map"))
            continue
        f = factor(unit, table)
        if f is None:
            hprobs.append(Problem(hloc, f"unknown unit {unit!r} in column {c!r}; known "
                                  f"{dim} units: {', '.join(table)}"))
            continue
        if (q, is_sd) in col:
            hprobs.append(Problem(hloc, f"column {c!r} repeats quantity "
                                  f"{'sd_' if is_sd else ''}{q}"))
            continue
        col[(q, is_sd)] = (j, f)
    for q in wanted:
        if (q, False) not in col and not any(
            p.reason.startswith(("unknown unit", "column")) and f"'{q}_" in p.reason.lower()
            for p in hprobs
        ):
            hprobs.append(Problem(hloc, f"missing column for {q} (e.g. "
                                  f"{_names(shape_kind)[wanted.index(q)]})"))
    vq = VALUE_QUANTITIES[shape_kind]
    sd_present = [q for q in vq if (q, True) in col]
    if sd_present and len(sd_present) != len(vq):
        missing = [f"sd_{q}" for q in vq if q not in sd_present]
        hprobs.append(Problem(hloc, f"standard deviations incomplete: missing "
                              f"{', '.join(missing)}"))
    problems += hprobs
    mprobs: list[Problem] = []
    velocity, vmissing = parse_velocity(meta.get("velocity_m_per_s"),
                                        meta.get("velocity_vector_m_per_s"), name, kind, mprobs)
    if any(p.reason.startswith(("unknown column", "missing column", "unknown unit", "column"))
           for p in hprobs):
        cells_of = []  # the rows cannot be read against this header; it is reported once
    decimal_comma = dialect.delimiter != "," and any(
        _DECIMAL_COMMA.fullmatch(r[j].strip()) for _, r in cells_of for j, _f in col.values()
        if j < len(r))
    n = len(cells_of)
    pos = np.full((n, 2), np.nan)
    vals = np.full((n, len(vq)), np.nan)
    sd = np.full((n, len(vq)), np.nan) if sd_present and len(sd_present) == len(vq) else None
    reported: set[int] = set()
    lines = [ln for ln, _ in cells_of]
    for i, (lineno, cells) in enumerate(cells_of):
        loc = f"{name}:row {lineno}"
        if len(cells) != len(header):
            problems.append(Problem(loc, f"{len(cells)} fields, the header has {len(header)}"))
            reported.add(i)
            continue
        for (q, is_sd), (j, f) in col.items():
            cell = cells[j].strip()
            v = parse_number(cell, decimal_comma)
            if v is None:
                why = "is not a number"
                if decimal_comma and "." in cell:
                    why = ("is not a number here: this file writes decimal commas, so a "
                           "decimal point is ambiguous")
                elif not decimal_comma and "," in cell:
                    why = "is not a number (a decimal comma needs a ';' or tab delimiter)"
                problems.append(Problem(loc, f"column {header[j]!r}: {cell!r} {why}"))
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
    other = {k: v for k, v in meta.items() if k not in RESERVED_KEYS}
    pm = ParsedMap(
        location=name, kind=kind, frame=meta.get("frame"), sign=meta.get("sign"),
        source=meta.get("source", ""), metadata=other, positions_m=pos,
        values=vals.reshape(vshape), sd=None if sd is None else sd.reshape(vshape),
        velocity_m_per_s=velocity, velocity_missing=vmissing,
        point_location=lambda i: f"{name}:row {lines[i]}", problems=mprobs, reported=reported,
        rows_unread=bool(hprobs) and not cells_of,
    )
    return [pm], problems


#: Bytes of a file the encoding detector looks at.
DETECT_BYTES = 1 << 20
#: Largest "mess" (charset-normalizer's measure of implausible characters, 0–1) of a decoding
#: that is accepted; above it the encoding is not told apart with confidence.
MAX_CHAOS = 0.1


def decode_text(data: bytes) -> tuple[str | None, str, str]:
    """(text, encoding if not UTF-8 else '', reason if refused).

    UTF-8 (with or without BOM) is read as it is; otherwise ``charset-normalizer`` names the
    encoding (a spreadsheet's Latin-1/Windows-1252, UTF-16 with BOM …) and the text is decoded
    with it, strictly; a file whose encoding it cannot tell apart is refused in words."""
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        try:
            return data.decode("utf-16"), "UTF-16", ""
        except UnicodeDecodeError:
            pass
    try:
        return data.decode("utf-8-sig"), "", ""
    except UnicodeDecodeError as exc:
        first = exc.start
    from charset_normalizer import from_bytes

    sample = data[:DETECT_BYTES]
    readings: dict[str, str] = {}
    for match in from_bytes(sample):
        if match.encoding in ("utf_8", "ascii") or match.chaos > MAX_CHAOS:
            continue
        try:
            readings[match.encoding] = data.decode(match.encoding)
        except (UnicodeDecodeError, LookupError):
            continue
    texts = set(readings.values())
    if len(texts) == 1:
        enc = next(iter(readings))
        return readings[enc], enc, ""
    why = f"not UTF-8 text (byte {first})"
    if len(texts) > 1:   # plausible encodings that read it differently: name what they read
        a, b = list(readings)[:2]
        wa, wb = _first_difference(readings[a], readings[b])
        why += (f", and its encoding cannot be told apart ({a} reads {wa!r}, {b} reads "
                f"{wb!r})")
    else:
        why += ", and its encoding cannot be told"
    return None, "", why + "; save it as UTF-8 (in a spreadsheet: CSV UTF-8)"


def _first_difference(a: str, b: str) -> tuple[str, str]:
    """The first word two readings of a file disagree on."""
    for wa, wb in zip(a.split(), b.split(), strict=False):
        if wa != wb:
            return wa[:40], wb[:40]
    return a[:40], b[:40]


def _delimiter_name(d: str) -> str:
    return {",": "commas", ";": "semicolons", "\t": "tabs"}.get(d, repr(d))


def _names(kind: str) -> list[str]:
    if kind == "postural":
        return ["x_m", "y_m", "fx_n", "fy_n"]
    return ["x_m", "y_m", "kxx_n_per_m", "kxy_n_per_m", "kyx_n_per_m", "kyy_n_per_m"]
