"""The remote panels of the clinician's station: the link's figures and the supervised
assessment. Runs in the station's process (:mod:`haptic.station.server`), never in the loop's.

Each poll reads the rows the clinician's port appended to the link's tap since the last
(:mod:`haptic.remote.tap`) and keeps

* **the link**: one-way delay (half the measured round trip), loss over the last second, the
  passivity controller's activity (share of ticks it acted on over the last second, energy
  dissipated), whether the link is up and engaged, the patient's robot's fault flag — and a
  history at 10 Hz for the page's small plots; a warning when the delay passes what the
  judgement at hand tolerates (:mod:`haptic.remote.tolerance`);
* **the patient's side as received** — the patient's handle and the force of the patient's hand
  on it, each sample at the patient's own tick time — cut into probes: a probe starts when the
  patient's hand moves faster than :data:`START_SPEED` and ends once it has been slower than
  :data:`REST_SPEED` for :data:`REST_S`. Each probe ends with a classification of every probe so
  far (:func:`fieldbank.evaluate.classify.classify`: the candidates are the severity scale's
  groups × levels on the patient's body, the prior is the clinician's), whose posterior, the
  next probe it draws (the stroke that best separates what remains) and verdict go to the page
  and, as one JSON line, to the assessment log beside the trace; the clinician's own answers
  go to the same log (:func:`haptic.remote.clinician_site.assessment_rows` pairs them).

The classifier is the public API of :mod:`fieldbank.evaluate.classify`; how confident its
posterior is rests on its noise model (``force_sd_n``, correlation time).
"""

from __future__ import annotations

import json
import math
import os
import time
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fieldbank.evaluate.classify import Classification, classify, predict_all
from fieldbank.evaluate.design import NoiseModel, severity_candidates
from fieldbank.evaluate.observation import Observation
from fieldbank.haptic.errors import AssessError, HapticError
from fieldbank.haptic.remote.tap import TapReader
from fieldbank.haptic.remote.tolerance import judgement_at_hand, table, warnings
from fieldbank.haptic.remote.wire import FLAG_ARMED, FLAG_FAULT
from fieldbank.params import ArmParams

#: The longest note the clinician may add to an answer, characters.
MAX_NOTE_CHARS = 2000
#: A probe starts when the patient's hand moves faster than this, m/s.
START_SPEED = 0.03
#: … and ends when it has been slower than this for REST_S, m/s.
REST_SPEED = 0.01
REST_S = 0.4
#: Kept before a probe's start and counted in it, s.
PRE_ROLL_S = 0.15
#: A movement shorter than this, or whose hand travels less than MIN_TRAVEL_M, is no probe.
MIN_PROBE_S = 0.15
MIN_TRAVEL_M = 0.01
#: History of the link's figures kept for the page, s, and its sampling, Hz.
HISTORY_S = 30.0
HISTORY_HZ = 10.0
#: Group labels as the page shows them (the training's answers).
GROUP_ANSWERS = {"shoulder": "shoulder", "elbow": "elbow", "biarticular": "both"}


@dataclass
class Probe:
    """One probe's samples (patient's side, shoulder frame) and when it ran (session time)."""

    index: int
    started_s: float
    ended_s: float
    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    f: np.ndarray

    def observation(self) -> Observation:
        return Observation.from_arrays(f"probe {self.index}", self.t, self.x, self.f, self.v,
                                       source=f"remote probe {self.index}")


@dataclass
class Desk:
    """The station's remote state (see the module docstring).

    Parameters
    ----------
    config : mapping
        :attr:`haptic.station.config.StationConfig.panel` (tap, columns, rate, assessment
        log, the patient's body, the candidates).
    """

    config: Mapping[str, Any]
    link: dict[str, Any] = field(default_factory=dict)
    history: deque[dict[str, float]] = field(default_factory=lambda: deque(
        maxlen=int(HISTORY_S * HISTORY_HZ)))
    probes: list[Probe] = field(default_factory=list)
    posterior: dict[str, Any] | None = None

    def __post_init__(self) -> None:
        cfg = self.config
        self.columns: list[str] = list(cfg["columns"])
        self.col = {c: i for i, c in enumerate(self.columns)}
        self.dt = 1.0 / float(cfg["rate_hz"])
        self.tap: TapReader | None = None
        self.log_path = Path(cfg["assessment_path"])
        a = dict(cfg.get("assess") or {})
        base = ArmParams.from_dict(cfg["drawing"], where="the station's remote settings")
        self.candidates = severity_candidates(tuple(a.get("groups") or ()),
                                              tuple(a.get("levels") or ()),
                                              unimpaired=bool(a.get("unimpaired", True)),
                                              base=base)
        self.groups = list(a.get("groups") or ())
        self.levels = list(a.get("levels") or ())
        self.noise = NoiseModel(force_sd_n=float(a.get("force_sd_n", 2.0)))
        self.predictor = str(a.get("predictor", "rigid"))
        self.weights: dict[str, float] = {c.name: 1.0 for c in self.candidates}
        self._rows: deque[np.ndarray] = deque(maxlen=int(2.0 * cfg["rate_hz"]))
        self._samples: list[np.ndarray] = []      # patient's side of the probe in progress
        self._pre: deque[np.ndarray] = deque(maxlen=max(1, int(PRE_ROLL_S * cfg["rate_hz"])))
        self._moving = False
        self._rest_since = math.inf
        self._last_peer_tick = -1
        self._history_at = -math.inf
        self._predictions: list[tuple[np.ndarray, ...]] = []
        self.answers: list[dict[str, Any]] = []

    # --- reading the tap ----------------------------------------------------------------------
    def _open(self) -> TapReader | None:
        if self.tap is None:
            try:
                self.tap = TapReader(self.config["tap_path"])
            except HapticError:
                return None
        return self.tap

    def poll(self) -> list[Probe]:
        """Read what is new; update the link's figures; return the probes that just ended."""
        tap = self._open()
        if tap is None:
            return []
        rows = tap.read()
        if not len(rows):
            return []
        c = self.col
        for r in rows:
            self._rows.append(r)
        last = rows[-1]
        window = np.array(self._rows)[-int(1.0 / self.dt):]
        ticks = max(1.0, float(window[-1, c["tick"]] - window[0, c["tick"]]) + 1.0)
        lost = float(window[-1, c["lost"]] - window[0, c["lost"]])
        new = float(np.sum(window[:, c["new_state"]]))
        rtt = float(last[c["rtt_s"]])
        flags = int(last[c["peer_flags"]]) if math.isfinite(last[c["peer_flags"]]) else 0
        self.link = {
            "t_s": round(float(last[c["t_s"]]), 3),
            "one_way_ms": None if not math.isfinite(rtt) else round(rtt * 500.0, 1),
            "rtt_ms": None if not math.isfinite(rtt) else round(rtt * 1e3, 1),
            "loss": round(lost / (lost + new), 4) if lost + new else 0.0,
            "controller_share": round(float(np.mean(window[:, c["alpha_n_s_per_m"]] > 0)), 4),
            "dissipated_j": round(float(last[c["dissipated_j"]]), 5),
            "tank_j": round(float(last[c["e_in_j"]] + last[c["e_received_j"]]
                                  - last[c["e_out_j"]] - last[c["e_sent_j"]]), 6),
            "link_ok": bool(last[c["link_ok"]] > 0.5), "engaged": bool(last[c["engaged"]] > 0.5),
            "patient_engaged": bool(flags & FLAG_ARMED),
            "patient_fault": bool(flags & FLAG_FAULT), "rows_missed": tap.missed,
            "ticks": int(ticks),
        }
        t = float(last[c["t_s"]])
        if t - self._history_at >= 1.0 / HISTORY_HZ:
            self._history_at = t
            self.history.append({"t_s": round(t, 2), "one_way_ms": self.link["one_way_ms"],
                                 "loss": self.link["loss"],
                                 "controller_share": self.link["controller_share"]})
        return self._segment(rows)

    def _segment(self, rows: np.ndarray) -> list[Probe]:
        c = self.col
        done = []
        for r in rows:
            if r[c["new_state"]] < 0.5 or r[c["peer_tick"]] <= self._last_peer_tick:
                continue
            self._last_peer_tick = int(r[c["peer_tick"]])
            s = np.array([r[c["peer_tick"]] * self.dt, r[c["peer_x_m"]], r[c["peer_y_m"]],
                          r[c["peer_vx_m_per_s"]], r[c["peer_vy_m_per_s"]], r[c["peer_fx_n"]],
                          r[c["peer_fy_n"]]])
            speed = math.hypot(s[3], s[4])
            if not self._moving:
                self._pre.append(s)
                if speed > START_SPEED:
                    self._moving = True
                    self._samples = list(self._pre)
                    self._rest_since = math.inf
                continue
            self._samples.append(s)
            if speed < REST_SPEED:
                if self._rest_since == math.inf:
                    self._rest_since = s[0]
                elif s[0] - self._rest_since >= REST_S:
                    p = self._close()
                    if p is not None:
                        done.append(p)
            else:
                self._rest_since = math.inf
        return done

    def _close(self) -> Probe | None:
        self._moving = False
        a = np.array(self._samples)
        self._samples = []
        self._pre.clear()
        if len(a) < 10:
            return None
        travel = float(np.max(np.hypot(a[:, 1] - a[0, 1], a[:, 2] - a[0, 2])))
        if a[-1, 0] - a[0, 0] < MIN_PROBE_S or travel < MIN_TRAVEL_M:
            return None
        # lost datagrams leave gaps: fill them on the patient's tick grid (interpolated
        # samples carry the motion through; the likelihood counts only the samples received)
        t = np.round(a[:, 0] / self.dt).astype(int)
        grid = np.arange(t[0], t[-1] + 1)
        full = np.column_stack([np.interp(grid, t, a[:, k]) for k in range(1, 7)])
        p = Probe(len(self.probes) + 1, float(a[0, 0]), float(a[-1, 0]), grid * self.dt,
                  full[:, 0:2], full[:, 2:4], full[:, 4:6])
        self.probes.append(p)
        return p

    # --- the assessment -------------------------------------------------------------------------
    def prior(self) -> np.ndarray:
        w = np.array([self.weights[c.name] for c in self.candidates], dtype=float)
        if w.sum() <= 0:
            raise AssessError("the suspected impairments rule out every candidate: keep at "
                              "least one muscle group and severity, or the unimpaired arm")
        return w / w.sum()

    def set_prior(self, groups: Sequence[str], levels: Sequence[str], unimpaired: bool) -> None:
        """The impairments the clinician suspects: candidates of those groups at those levels
        (and the unimpaired arm if asked) weigh 1, the others 0."""
        g, lv = set(groups), set(levels)
        for c in self.candidates:
            if c.group is None:
                self.weights[c.name] = 1.0 if unimpaired else 0.0
            else:
                self.weights[c.name] = 1.0 if (c.group in g and c.level in lv) else 0.0
        self.prior()  # refuses an empty prior
        self._log({"kind": "prior", "groups": sorted(g), "levels": sorted(lv),
                   "unimpaired": unimpaired, "t_s": self.link.get("t_s")})

    def classify(self, design_next: bool = True) -> Classification | None:
        """Every probe so far scored against the candidates with the clinician's prior."""
        if not self.probes:
            return None
        obs = [p.observation() for p in self.probes]
        while len(self._predictions) < len(obs):  # each probe is predicted once
            k = len(self._predictions)
            self._predictions.append(predict_all([obs[k]], self.candidates, self.predictor))
        preds = tuple(pr[0] for pr in self._predictions)
        return classify(obs, self.candidates, noise=self.noise, prior=self.prior(),
                        predictor=self.predictor, next_probe=design_next, predictions=preds)

    def posterior_message(self, cl: Classification, log: bool = True) -> dict[str, Any]:
        """What the page shows of a classification (and, with ``log``, the assessment log's
        record after the newest probe)."""
        cells: dict[str, dict[str, float]] = {}
        unimpaired = 0.0
        post = {c.name: float(p) for c, p in zip(cl.candidates, cl.posterior, strict=True)}
        for c, p in zip(cl.candidates, cl.posterior, strict=True):
            if c.group is None:
                unimpaired += float(p)
            else:
                cells.setdefault(c.group, {})[str(c.level)] = float(p)
        g = cl.group_posterior
        best_group = next(iter(g))
        lv = {k: v for k, v in cl.level_posterior.items() if k != "unimpaired"}
        best_level = max(lv, key=lambda k: lv[k]) if lv else None
        nxt = None
        if cl.next_probe is not None and cl.next_probe.motions:
            pp = cl.next_probe.motions[0].path()   # shoulder frame of the patient
            nxt = {"name": pp.name, "description": pp.description,
                   "points_m": [list(map(float, q)) for q in pp.points_m],
                   "times_s": list(map(float, pp.times_s))}
        newest = self.probes[-1]
        group_p = float(g[best_group])
        one_way = (self.link.get("one_way_ms") or 0.0) / 1e3
        at_hand = judgement_at_hand(group_p)
        msg = {
            "type": "posterior", "probe": newest.index, "started_s": round(newest.started_s, 3),
            "ended_s": round(newest.ended_s, 3), "probes": len(self.probes),
            "cells": cells, "unimpaired": unimpaired, "groups": self.groups,
            "levels": self.levels, "group_posterior": {k: float(v) for k, v in g.items()},
            "level_posterior": {k: float(v) for k, v in cl.level_posterior.items()},
            "group": best_group, "group_probability": group_p, "level": best_level,
            "level_probability": float(lv[best_level]) if best_level else None,
            "explains": cl.explains, "verdict": cl.verdict(), "next_probe": nxt,
            "next_reason": cl.next_reason, "judgement_at_hand": at_hand,
            "prior": {c.name: float(p) for c, p in zip(cl.candidates, cl.prior, strict=True)},
            "posterior": post,
        }
        self.posterior = msg
        if log:
            self._log({"kind": "posterior", **{k: msg[k] for k in (
                "probe", "started_s", "ended_s", "prior", "posterior", "group",
                "group_probability", "level", "level_probability", "explains", "verdict",
                "next_probe", "group_posterior", "level_posterior")},
                "link": {k: self.link.get(k) for k in ("one_way_ms", "loss",
                                                       "controller_share")},
                "predictor": self.predictor, "at_hand": at_hand,
                "warnings": warnings(one_way, at_hand)})
        return msg

    def answer(self, group: str | None, level: str | None, note: str) -> dict[str, Any]:
        """The clinician's own answer, logged beside the newest posterior."""
        if group is not None and group not in (*self.groups, "unimpaired"):
            raise AssessError(f"the muscle group is one of {', '.join(self.groups)} or "
                              f"unimpaired; got {group!r}")
        if level is not None and level not in self.levels:
            raise AssessError(f"the severity is one of {', '.join(self.levels)}; got {level!r}")
        if len(note) > MAX_NOTE_CHARS:
            raise AssessError(f"the note is at most {MAX_NOTE_CHARS} characters; this one has "
                              f"{len(note)}")
        rec = {"kind": "answer", "group": group, "level": level, "note": note,
               "after_probe": len(self.probes), "t_s": self.link.get("t_s")}
        self._log(rec)
        self.answers.append(rec)
        return rec

    def link_message(self) -> dict[str, Any]:
        at_hand = judgement_at_hand(None if self.posterior is None
                                    else self.posterior["group_probability"])
        one_way = (self.link.get("one_way_ms") or 0.0) / 1e3
        return {"type": "link", **self.link, "history": list(self.history),
                "at_hand": at_hand, "warnings": warnings(one_way, at_hand),
                "tolerances": table()}

    def _log(self, rec: Mapping[str, Any]) -> None:
        """Append one record as a JSON line and make it durable (the session reads the file
        when it ends; a torn last line is skipped there)."""
        line = json.dumps({"wall_time_s": time.time(), **rec}, default=float) + "\n"
        self.log_path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.log_path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o600)
        try:
            os.write(fd, line.encode())
            os.fsync(fd)
        finally:
            os.close(fd)

    def close(self) -> None:
        if self.tap is not None:
            self.tap.close()
            self.tap = None
