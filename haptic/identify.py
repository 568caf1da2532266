"""Simulated identification trials: the simulated operator probes arms of known impaired group
and severity, the classifier names the group, and a confusion matrix says how often it is right
(the seed's assessment protocol - 3 groups × 4 severities × repetitions - with the classifier
in the clinician's place).

Each trial renders the true arm (:func:`fieldbank.evaluate.severity.synthesize`) on the simulated
robot in lockstep (faster than real time) while the operator performs every probe of a set:

1. the operator executes the probe with motion noise - direction, length and speed drawn from
   the noise model (:func:`fieldbank.evaluate.design.draw_execution`) and a smooth wander of
   the hand (:func:`haptic.motions.wander`) - through the hand's own impedance, so the arm's
   field pushes the handle off the path;
2. the recorded trace becomes an observation (:func:`haptic.probe.observation_from_trace`)
   with sensor noise added (:func:`fieldbank.evaluate.classify.with_force_noise`);
3. the classifier scores every candidate on all the set's observations; its most probable
   group is the answer.

Each executed set is met with ``noise_draws`` independent draws of the sensor noise (the
candidates' predictions for the executed motion are made once), so a trial is one execution
and one noise draw. Every set meets the same arms with the same seeds, so the sets differ only
in their probes. :func:`designed_vs_seed` designs a set for the candidates and runs it against
the seed's pull and semi-ellipse.

The arms need not be the candidates: :class:`Patient` is any simulated arm with its true group.
:func:`between_patients` draws arms whose severity lies between and around the candidates'
levels, each muscle group and component off by up to half a Weber step from the others (a
patient is not on the scale's steps, nor equally severe in flexors and extensors);
:func:`flexor_patients` makes only the flexor group of a joint hypertonic, an arm outside a set
of joint-group candidates. :func:`reliability` sets the probability each answer was given with
against how often such answers were right (:mod:`fieldbank.evaluate.classify`: calibration).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from fieldbank.errors import ParameterError
from fieldbank.evaluate.classify import classify, predict_all
from fieldbank.evaluate.design import (
    Candidate,
    DesignReport,
    NoiseModel,
    Perception,
    design_report,
    draw_execution,
    seed_probes,
)
from fieldbank.evaluate.observation import with_force_noise
from fieldbank.evaluate.probing import ProbeMotion
from fieldbank.evaluate.reliability import ReliabilityBin, reliability_bins
from fieldbank.evaluate.severity import (
    group_name,
    level_name,
    ratio_of_score,
    synthesize,
    synthesize_ratios,
)
from fieldbank.haptic.probe import observation_from_trace, probe_path
from fieldbank.params import JOINT_GROUPS, ArmParams

#: Called after each trial with (trials done, trials in all).
Progress = Callable[[int, int], None]


@dataclass(frozen=True)
class Patient:
    """A simulated arm: its impaired joint group, a label (its level, or how it was made) and
    its parameters."""

    group: str
    level: str
    params: ArmParams


def grid_patients(groups: Sequence[str], levels: Sequence[str]) -> tuple[Patient, ...]:
    """Each group at each level of the scale (the severity candidates themselves)."""
    return tuple(Patient(group_name(g), level_name(lvl), synthesize({group_name(g): lvl}))
                 for g in groups for lvl in levels)


def between_patients(groups: Sequence[str], n: int, seed: int = 0, low: float = 0.5,
                     high: float = 4.5, spread: float = 0.5) -> tuple[Patient, ...]:
    """``n`` arms, the groups in turn: a severity score uniform in [low, high] (1 very mild …
    4 severe; the default reaches half a step beyond either end), each muscle group and
    component of the joint group off by a uniform ±``spread`` (in Weber steps) from it -
    between and around the scale's steps."""
    rng = np.random.default_rng(seed)
    gs = [group_name(g) for g in groups]
    out = []
    for k in range(n):
        g = gs[k % len(gs)]
        score = float(rng.uniform(low, high))
        ratios = {f"{m}:{c}": ratio_of_score(max(0.0, score + float(rng.uniform(-spread,
                                                                                  spread))), c)
                  for m in JOINT_GROUPS[g] for c in ("passive", "dynamic")}
        out.append(Patient(g, f"score {score:.2f}", synthesize_ratios(ratios)))
    return tuple(out)


def flexor_patients(groups: Sequence[str], levels: Sequence[str]) -> tuple[Patient, ...]:
    """The flexor group of each joint group alone at each level, the extensors unimpaired:
    arms outside a set of joint-group candidates."""
    out = []
    for g in (group_name(x) for x in groups):
        for lvl in (level_name(x) for x in levels):
            out.append(Patient(g, f"{lvl}, flexors only",
                               synthesize({JOINT_GROUPS[g][0]: lvl})))
    return tuple(out)


@dataclass(frozen=True)
class Trial:
    """One trial of one probe set: the true arm and what the classifier answered.

    ``probability`` and ``group_probability`` are the calibrated ones (the classifier's
    posterior); ``raw_*`` the posterior of the stated likelihood alone; ``explains``: the
    classifier found a candidate that explains the trace within the noise.
    """

    probe_set: str
    group: str
    level: str
    repetition: int
    draw: int
    answer: str
    answer_group: str
    probability: float
    group_probability: float
    raw_answer_group: str = ""
    raw_group_probability: float = math.nan
    explains: bool = True
    fit_p_value: float = 1.0

    @property
    def correct_group(self) -> bool:
        return self.answer_group == self.group

    def to_dict(self) -> dict[str, object]:
        return {"probe_set": self.probe_set, "group": self.group, "level": self.level,
                "repetition": self.repetition, "draw": self.draw, "answer": self.answer,
                "answer_group": self.answer_group, "probability": round(self.probability, 6),
                "group_probability": round(self.group_probability, 6),
                "correct_group": self.correct_group, "raw_answer_group": self.raw_answer_group,
                "raw_group_probability": round(self.raw_group_probability, 6),
                "explains": self.explains, "fit_p_value": float(f"{self.fit_p_value:.4g}")}


@dataclass(frozen=True)
class TrialResults:
    """Every trial of every probe set, with confusion matrices and accuracies."""

    trials: tuple[Trial, ...]
    sets: tuple[str, ...]
    groups: tuple[str, ...]
    levels: tuple[str, ...]
    answers: tuple[str, ...]
    noise: NoiseModel
    repetitions: int
    noise_draws: int
    seed: int

    def _of(self, probe_set: str, level: str | None = None) -> list[Trial]:
        return [t for t in self.trials if t.probe_set == probe_set
                and (level is None or t.level == level)]

    def confusion(self, probe_set: str, level: str | None = None) -> np.ndarray:
        """Counts, rows the true group (:attr:`groups`), columns the answer (:attr:`answers`)."""
        m = np.zeros((len(self.groups), len(self.answers)), dtype=int)
        for t in self._of(probe_set, level):
            m[self.groups.index(t.group), self.answers.index(t.answer_group)] += 1
        return m

    def accuracy(self, probe_set: str, level: str | None = None) -> float:
        """Fraction of trials whose answered group is the true one."""
        ts = self._of(probe_set, level)
        return sum(t.correct_group for t in ts) / len(ts) if ts else math.nan

    def to_dict(self) -> dict[str, object]:
        return {
            "groups": list(self.groups), "levels": list(self.levels),
            "answers": list(self.answers), "repetitions": self.repetitions,
            "noise_draws": self.noise_draws, "seed": self.seed,
            "noise": self.noise.to_dict(),
            "sets": {s: {
                "accuracy": round(self.accuracy(s), 4),
                "accuracy_per_level": {lvl: round(self.accuracy(s, lvl), 4)
                                       for lvl in self.levels},
                "confusion": self.confusion(s).tolist(),
                "confusion_per_level": {lvl: self.confusion(s, lvl).tolist()
                                        for lvl in self.levels},
            } for s in self.sets},
            "trials": [t.to_dict() for t in self.trials],
        }

    def table(self) -> str:
        """Accuracy per level and the confusion matrix of each set, as text."""
        lines = []
        w = max(len(a) for a in self.answers) + 2
        for s in self.sets:
            acc = ", ".join(f"{lvl} {self.accuracy(s, lvl) * 100:.0f}%" for lvl in self.levels)
            lines.append(f"{s}: group correct {self.accuracy(s) * 100:.1f}% ({acc})")
            lines.append(" " * (w + 4) + "".join(a.rjust(w) for a in self.answers)
                         + "   (answered)")
            for g, row in zip(self.groups, self.confusion(s), strict=True):
                lines.append(f"    {g.ljust(w)}" + "".join(str(v).rjust(w) for v in row))
        return "\n".join(lines)


def run_trials(probe_sets: Mapping[str, Sequence[ProbeMotion]],
               candidates: Sequence[Candidate], *, groups: Sequence[str],
               levels: Sequence[str], repetitions: int = 3, noise_draws: int = 1,
               noise: NoiseModel | None = None, seed: int = 0, predictor: str = "replay",
               progress: Progress | None = None,
               patients: Sequence[Patient] | None = None) -> TrialResults:
    """Run every probe set on every (group, level) arm ``repetitions`` times.

    Parameters
    ----------
    probe_sets : mapping of name -> probes (shoulder frame, starting at the arm's equilibrium)
    candidates : the arms the classifier chooses among
    groups, levels : the true arms (each group at each level)
    repetitions : executions of each set on each arm
    noise_draws : sensor-noise draws met by each execution
    noise : motion and force noise of the operator and the recording (also the likelihood's)
    patients : the true arms instead of groups × levels (:class:`Patient`)
    """
    if repetitions < 1 or noise_draws < 1:
        raise ParameterError(f"repetitions and noise_draws must be at least 1; got "
                             f"{repetitions} and {noise_draws}.")
    if not probe_sets or any(len(v) == 0 for v in probe_sets.values()):
        raise ParameterError("Give at least one probe set, each with at least one probe.")
    noise = noise or NoiseModel()
    arms = tuple(patients) if patients is not None else grid_patients(groups, levels)
    gs = tuple(dict.fromkeys([group_name(g) for g in groups] + [p.group for p in arms]))
    ls = tuple(dict.fromkeys(p.level for p in arms))
    answers = tuple(dict.fromkeys([c.label for c in candidates] + list(gs)))
    total = len(arms) * repetitions * len(probe_sets) * noise_draws
    done = 0
    out: list[Trial] = []
    for pi, patient in enumerate(arms):
        g, lvl, params = patient.group, patient.level, patient.params
        gi, li = gs.index(g), ls.index(lvl)
        if patients is not None:
            gi, li = pi, 0
        for rep in range(repetitions):
            trial_seed = seed * 1_000_003 + (gi * 97 + li) * 1009 + rep
            for name, motions in probe_sets.items():
                rng = np.random.default_rng(trial_seed)
                obs = []
                for k, m in enumerate(motions):
                    executed = draw_execution(m, noise, rng)
                    res = probe_path(params, executed, seed=trial_seed * 7 + k,
                                     wander_m=noise.wander_m)
                    obs.append(observation_from_trace(res.trace, m.name))
                preds = predict_all(obs, candidates, predictor)
                for draw in range(noise_draws):
                    noisy = [with_force_noise(o, noise, rng) for o in obs]
                    c = classify(noisy, candidates, noise=noise, next_probe=False,
                                 predictions=preds)
                    gp = c.group_posterior
                    raw = _group_marginal(candidates, c.raw_posterior
                                          if c.raw_posterior is not None else c.posterior)
                    raw_group = max(raw, key=raw.__getitem__)
                    out.append(Trial(name, g, lvl, rep, draw, c.best.name, c.group,
                                     c.probability, gp[c.group], raw_group,
                                     raw[raw_group], c.explains, c.fit_p_value))
                    done += 1
                    if progress is not None:
                        progress(done, total)
    return TrialResults(tuple(out), tuple(probe_sets), gs, ls, answers, noise, repetitions,
                        noise_draws, seed)


def _group_marginal(candidates: Sequence[Candidate], posterior: np.ndarray) -> dict[str, float]:
    out: dict[str, float] = {}
    for c, p in zip(candidates, posterior, strict=True):
        out[c.label] = out.get(c.label, 0.0) + float(p)
    return out


#: Bins of the stated probability in :func:`reliability` (the answer's group probability).
RELIABILITY_BINS: tuple[tuple[float, float], ...] = (
    (0.0, 0.6), (0.6, 0.8), (0.8, 0.9), (0.9, 0.99), (0.99, 1.0))


def reliability(trials: Sequence[Trial], raw: bool = False,
                bins: Sequence[tuple[float, float]] = RELIABILITY_BINS
                ) -> tuple[ReliabilityBin, ...]:
    """Stated group probability against observed accuracy, per bin of the stated probability
    (``raw``: the posterior of the stated likelihood, before the classifier's correction;
    :func:`fieldbank.evaluate.reliability.reliability_bins`)."""
    return reliability_bins(
        [t.raw_group_probability if raw else t.group_probability for t in trials],
        [(t.raw_answer_group if raw else t.answer_group) == t.group for t in trials], bins)


def designed_vs_seed(candidates: Sequence[Candidate], *, groups: Sequence[str],
                     levels: Sequence[str], repetitions: int = 3, noise_draws: int = 1,
                     noise: NoiseModel | None = None, perception: Perception | None = None,
                     criterion: str = "information", max_probes: int = 2, seed: int = 0,
                     progress: Progress | None = None) -> tuple[DesignReport, TrialResults]:
    """Design ``max_probes`` probes that tell the candidates' groups apart and run them, and the
    seed's pull and semi-ellipse, through the same trials."""
    noise = noise or NoiseModel()
    rep = design_report(candidates, criterion=criterion, target="group", max_probes=max_probes,
                        stop_when_separated=False, perception=perception, noise=noise)
    sets = {"designed": list(rep.design.motions), "seed": seed_probes(candidates)}
    res = run_trials(sets, candidates, groups=groups, levels=levels, repetitions=repetitions,
                     noise_draws=noise_draws, noise=noise, seed=seed, progress=progress)
    return rep, res
