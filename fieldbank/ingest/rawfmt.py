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
from dataclasses import replace

import numpy as np

from fieldbank.errors import MapError, Problem
from fieldbank.ingest.limits import IngestLimits
from fieldbank.ingest.options import ReadOptions
from fieldbank.ingest.parsed import ParsedMap
from fieldbank.maps import FieldMap
from fieldbank.measure.budget import ReadBudget
from fieldbank.measure.c3draw import read_c3d_recording
from fieldbank.measure.channels import check_channels
from fieldbank.measure.estimate import estimate
from fieldbank.measure.kinarm import exam_kind, read_kinarm_zip
from fieldbank.measure.kinarmbin import read_kinarm_binary
from fieldbank.measure.nwbraw import read_recording
from fieldbank.measure.recording import ChannelProblems, Recording, in_convention
from fieldbank.measure.segment import find_holds
from fieldbank.model import Arm
from fieldbank.nwbexport import has_nwb_maps, read_nwb_maps

RAW_FORMATS = ("nwb", "c3d", "kinarm")
#: Fewest postures a map from a raw recording may have: one posture is a single point, not a
#: field (lab maps hold 9–100; fieldbank's shortest protocol measures a 2-posture row).
MIN_POSTURES = 2


def problems_of(name: str, exc: MapError) -> list[Problem]:
    """A reader's refusal as located problems: every channel problem at once."""
    reasons = exc.reasons if isinstance(exc, ChannelProblems) else [str(exc)]
    return [Problem(name, r.removeprefix(f"{name}: ")) for r in reasons]


def _parsed(name: str, m: FieldMap, k: int) -> ParsedMap:
    postures = json.loads(m.metadata.get("postures", "[]"))
    what = m.kind if m.speed_m_per_s == 0 else f"{m.kind} at {m.speed_m_per_s:g} m/s"
    loc = f"{name}: {what} map {k}"

    def point(i: int) -> str:
        return f"{loc}, posture {postures[i] if i < len(postures) else i}"

    return ParsedMap(loc, m.kind, m.frame, m.sign, m.source, dict(m.metadata),
                     np.array(m.positions_m), np.array(m.values),
                     None if m.sd is None else np.array(m.sd), m.velocity_m_per_s, point)


def _parsed_at(where: str, m: FieldMap) -> ParsedMap:
    return ParsedMap(where, m.kind, m.frame, m.sign, m.source, dict(m.metadata),
                     np.array(m.positions_m), np.array(m.values),
                     None if m.sd is None else np.array(m.sd), m.velocity_m_per_s,
                     lambda i: f"{where}: row {i}")


def maps_from_recording(name: str, fmt: str, rec: Recording, arm: Arm | None,
                        postures: np.ndarray | None, provenance: Mapping[str, str],
                        options: ReadOptions | None = None,
                        limits: IngestLimits | None = None
                        ) -> tuple[list[ParsedMap], list[Problem]]:
    """The estimator's maps of ``rec`` as parsed maps with provenance, or the problems.

    Refused before the estimator, each naming its channel (:func:`check_channels`): a flat
    channel, values the unit contradicts, a channel without a number. Refused after it: a map
    of fewer than :data:`MIN_POSTURES` postures, a standard deviation of exactly 0.

    ``options``: ``--shoulder`` and ``--sign`` put the file's coordinates and force into the
    shoulder frame and the arm-on-handle sign; a recording without trials gets its holds found
    by stillness (:func:`fieldbank.measure.segment.find_holds`)."""
    opts = options or ReadOptions()
    lim = limits or IngestLimits()
    bad = check_channels(rec, lim.max_force_n)
    if bad:
        return [], [Problem(name, r) for r in bad]
    prov = dict(provenance)
    sign = opts.defaults.get("sign", "arm-on-handle")
    rec = in_convention(rec, opts.shoulder_m or (0.0, 0.0), sign == "handle-on-arm")
    if opts.shoulder_m is not None:
        prov["shoulder_in_file_m"] = f"{opts.shoulder_m[0]:g}, {opts.shoulder_m[1]:g}"
    prov["sign_in_file"] = sign
    if not rec.trials:
        found = find_holds(rec)
        if not found:
            return [], [Problem(name, "no trials: the file marks none (an NWB trials table, "
                                "C3D events) and no hold of the hand was found in it")]
        rec = replace(rec, trials=tuple(found))
        prov["trials_found_by"] = ("stillness: holds under 5 mm/s for 0.25 s or more, roles "
                                   "by position (fieldbank.measure.segment)")
    provenance = prov
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
    refused = _unfit(name, est.maps, rec)
    if refused:
        return [], refused
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


def _unfit(name: str, maps: tuple[FieldMap, ...], rec: Recording) -> list[Problem]:
    """Maps the estimator made that must not be stored: too few postures, an sd of 0."""
    out = []
    for m in maps:
        what = m.kind if m.speed_m_per_s == 0 else f"{m.kind} at {m.speed_m_per_s:g} m/s"
        if m.n < MIN_POSTURES:
            out.append(Problem(name, f"the {what} map has {m.n} posture(s), fewer than the "
                               f"{MIN_POSTURES} a map needs to show a field (holds found at "
                               f"{m.n} place(s) in the recording)"))
        elif m.sd is not None and np.any(m.sd == 0):
            chans = ", ".join(rec.channels.get(r, r) for r in ("fx", "fy"))
            out.append(Problem(name, f"the {what} map has a standard deviation of exactly 0 "
                               f"at {int(np.sum(np.any(m.sd.reshape(m.n, -1) == 0, axis=1)))} "
                               f"posture(s): the force channels ({chans}) did not vary at "
                               "all, so they measured nothing"))
    return out


def read_nwb(name: str, data: bytes, limits: IngestLimits, arm: Arm | None,
             options: ReadOptions | None = None) -> tuple[list[ParsedMap], list[Problem]]:
    """Maps from a raw NWB recording."""
    opts = options or ReadOptions()
    budget = _budget(limits, data)
    try:
        if has_nwb_maps(data):  # a fieldbank export: its maps as they were stored
            found = read_nwb_maps(name, data, budget)
            return [_parsed_at(where, m) for m, where in found], []
        rec, postures, prov = read_recording(name, data, opts.columns, opts.units, budget)
    except MapError as exc:
        return [], problems_of(name, exc)
    return maps_from_recording(name, "NWB", rec, arm, postures, prov, options, limits)


def read_c3d(name: str, data: bytes, limits: IngestLimits, arm: Arm | None,
             options: ReadOptions | None = None) -> tuple[list[ParsedMap], list[Problem]]:
    """Maps from a raw C3D recording."""
    opts = options or ReadOptions()
    try:
        rec, postures, prov = read_c3d_recording(name, data, opts.columns, opts.trial_events,
                                                 opts.units, limits.max_decompressed_bytes)
    except MapError as exc:
        return [], problems_of(name, exc)
    return maps_from_recording(name, "C3D", rec, arm, postures, prov, options, limits)


def read_kinarm(name: str, data: bytes, limits: IngestLimits, arm: Arm | None,
                options: ReadOptions | None = None) -> tuple[list[ParsedMap], list[Problem]]:
    """Maps from a KINARM (Dexterit-E) exam ZIP; the shoulder and the sign must be given."""
    opts = options or ReadOptions()
    missing = [f for f, ok in (("--shoulder X,Y (the shoulder in KINARM's coordinates)",
                                opts.shoulder_m is not None),
                               ("--sign (whose force KINARM's sensor channel holds)",
                                "sign" in opts.defaults)) if not ok]
    options_problem = [Problem(name, "a KINARM exam is in the robot's own frame and sign: "
                               "give " + " and ".join(missing))] if missing else []
    budget = _budget(limits, data)
    try:
        if exam_kind(data) == "binary":
            rec, prov = read_kinarm_binary(name, data, opts.columns, budget)
        else:
            rec, prov = read_kinarm_zip(name, data, opts.columns, budget)
    except MapError as exc:
        return [], problems_of(name, exc) + options_problem
    if options_problem:
        return [], options_problem
    return maps_from_recording(name, "KINARM", rec, arm, None, prov, opts, limits)


def _budget(limits: IngestLimits, data: bytes) -> ReadBudget:
    return ReadBudget(limits.max_decompressed_bytes, len(data), limits.max_compression_ratio,
                      limits.hint("max_decompressed_bytes"), limits.hint("max_compression_ratio"))
