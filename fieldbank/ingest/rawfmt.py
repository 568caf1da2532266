"""Raw recordings into maps at ingest: NWB and C3D files through the one estimator.

A raw file is read into a :class:`~fieldbank.measure.recording.Recording`
(:mod:`fieldbank.measure.nwbraw`, :mod:`fieldbank.measure.c3draw`), the estimator
(:mod:`fieldbank.measure.estimate`) turns it into maps, and each map carries its provenance in
its metadata: the raw format, the channels used with their units, the sample rate, the trials
kept and every trial dropped with its reason. The raw file itself is stored unchanged (its
SHA-256 is the source's), like every ingested file.
"""

from __future__ import annotations

import json
from collections.abc import Mapping

import numpy as np

from fieldbank.errors import MapError, Problem
from fieldbank.ingest.limits import IngestLimits
from fieldbank.ingest.parsed import ParsedMap
from fieldbank.maps import FieldMap
from fieldbank.measure.c3draw import read_c3d_recording
from fieldbank.measure.estimate import estimate
from fieldbank.measure.nwbraw import read_recording
from fieldbank.measure.recording import Recording
from fieldbank.model import Arm

RAW_FORMATS = ("nwb", "c3d")


def _parsed(name: str, m: FieldMap, k: int) -> ParsedMap:
    postures = json.loads(m.metadata.get("postures", "[]"))
    what = m.kind if m.speed_m_per_s == 0 else f"{m.kind} at {m.speed_m_per_s:g} m/s"
    loc = f"{name}: {what} map {k}"

    def point(i: int) -> str:
        return f"{loc}, posture {postures[i] if i < len(postures) else i}"

    return ParsedMap(loc, m.kind, m.frame, m.sign, m.source, dict(m.metadata),
                     np.array(m.positions_m), np.array(m.values),
                     None if m.sd is None else np.array(m.sd), m.velocity_m_per_s, point)


def maps_from_recording(name: str, fmt: str, rec: Recording, arm: Arm | None,
                        postures: np.ndarray | None,
                        provenance: Mapping[str, str]) -> tuple[list[ParsedMap], list[Problem]]:
    """The estimator's maps of ``rec`` as parsed maps with provenance, or the problems."""
    if not rec.trials:
        return [], [Problem(name, "no trials: the file marks no holds or passes (an NWB "
                            "trials table, C3D events) for the estimator to read")]
    dropped_by_source = [t for t in rec.trials if t.status]
    prov = {"raw_format": fmt, "raw_file": name,
            "channels": json.dumps(dict(rec.channels), ensure_ascii=False),
            "sample_rate_hz": f"{rec.rate_hz:.6g}", **dict(provenance)}
    if rec.velocity_derived:
        prov["velocity"] = "differentiated from the position (the file has no velocity)"
    try:
        est = estimate(rec, arm, postures, source=f"{rec.source or name}", provenance=prov)
    except MapError as exc:
        return [], [Problem(name, str(exc))]
    if not est.maps:
        reasons = "; ".join(f"{d.what}: {d.reason}" for d in est.dropped[:5])
        return [], [Problem(name, f"no map could be estimated ({len(rec.trials)} trials, "
                            f"{len(est.dropped)} dropped{': ' + reasons if reasons else ''})")]
    kept = json.dumps(list(est.kept))
    dropped = json.dumps([d.to_json_dict() for d in est.dropped], ensure_ascii=False)
    out = []
    for k, m in enumerate(est.maps):
        meta = dict(m.metadata)
        meta["trials_kept"] = kept
        meta["trials_dropped"] = dropped
        meta["trials_dropped_by_source"] = str(len(dropped_by_source))
        fm = FieldMap(m.kind, m.positions_m, m.values, m.sd, m.frame, m.sign,
                      m.velocity_m_per_s, m.source, meta)
        out.append(_parsed(name, fm, k))
    return out, []


def read_nwb(name: str, data: bytes, limits: IngestLimits, arm: Arm | None,
             channels: Mapping[str, str] | None = None
             ) -> tuple[list[ParsedMap], list[Problem]]:
    """Maps from a raw NWB recording."""
    del limits  # the file size was bounded before; the arrays are the file's own
    try:
        rec, postures, prov = read_recording(name, data, channels)
    except MapError as exc:
        return [], [Problem(name, str(exc))]
    return maps_from_recording(name, "NWB", rec, arm, postures, prov)


def read_c3d(name: str, data: bytes, limits: IngestLimits, arm: Arm | None,
             channels: Mapping[str, str] | None = None
             ) -> tuple[list[ParsedMap], list[Problem]]:
    """Maps from a raw C3D recording."""
    del limits
    try:
        rec, postures, prov = read_c3d_recording(name, data, channels)
    except MapError as exc:
        return [], [Problem(name, str(exc))]
    return maps_from_recording(name, "C3D", rec, arm, postures, prov)
