"""The seed's training protocol run on the loop as an activity (:class:`Training`): its
familiarisation (a legend names each arm) and its blinded assessment (which arm is felt is
hidden until the protocol ends).

The protocol itself - plan, trial records, results - is :mod:`haptic.training`; this module is
what the loop does with it:

* ``start`` keeps the patient's pair of models aside (refused while pushed models are still
  being swapped in: they would be lost) and draws the plan;
* ``next`` renders the next trial's arm: compiled in the caller's thread (:meth:`Training.prepare`,
  never in the loop) and swapped in behind the push fade; after the last trial it closes the
  protocol;
* ``answer`` records an assessment answer ('shoulder', 'elbow' or 'both') with its response time
  and its window's verdict (:mod:`haptic.activities.window`);
* ``stop`` ends it early, the trials so far kept (marked abandoned).

When it ends, the patient's pair comes back behind the same fade. It renders its own arms, so a
push is refused while it runs, and so is a switch (it chooses what is felt); it pauses on a
fault (every step is refused until the robot is re-armed).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from fieldbank.haptic.activities.base import Activity, ActivityHost
from fieldbank.haptic.activities.window import TrialWindow
from fieldbank.haptic.errors import CommandError
from fieldbank.haptic.pair import SimPair
from fieldbank.haptic.training import TrainingProtocol, TrainingSession, probe_paths
from fieldbank.model import Arm
from fieldbank.params import ArmParams
from fieldbank.probepath import ProbePath


@dataclass(frozen=True)
class NextTrial:
    """The next trial prepared outside the loop: its arm compiled and its probes drawn
    (``index`` -1: no trial is left, the protocol closes)."""

    index: int
    params: ArmParams | None = None
    sims: SimPair | None = None
    paths: tuple[ProbePath, ...] = ()


class Training(Activity):
    """A training protocol run on the loop.

    Parameters
    ----------
    protocol : TrainingProtocol
    """

    kind: ClassVar[str] = "training"
    title: ClassVar[str] = "a training protocol"
    owns_models: ClassVar[bool] = True
    kept_when_done: ClassVar[bool] = True

    def __init__(self, protocol: TrainingProtocol) -> None:
        self.protocol = protocol
        self.session = TrainingSession(protocol)
        self.window = TrialWindow()
        #: the patient's pair, put back when the protocol ends
        self._home: tuple[SimPair, tuple[ArmParams, ArmParams]] | None = None

    @property
    def done(self) -> bool:
        return self.session.done

    @property
    def blinded(self) -> bool:
        return self.session.blinded

    def start(self, host: ActivityHost) -> dict[str, Any]:
        host.safety.require_armed("training start")
        try:
            self._home = host.pair.current()
        except CommandError as exc:
            raise CommandError(f"training start refused: {exc}; start it once they are "
                               "rendered") from None
        tr = self.session
        host.log_event("train_start", n_trials=len(tr.trials),
                       instruction=self.protocol.instruction, seed=self.protocol.seed)
        return tr.state(host.t_s)

    def prepare(self, host: ActivityHost) -> NextTrial:
        """The next trial's arm compiled and its probes drawn (the caller's thread)."""
        tr = self.session
        nxt = tr.next_trial
        if nxt is None or tr.done:  # nothing left to present: the protocol's final state
            return NextTrial(-1)
        host.safety.require_armed("next trial")
        if tr.awaiting_answer:
            raise CommandError("training: answer this trial first (shoulder, elbow or both)")
        p = nxt.params(tr.protocol.base())
        paths: tuple[ProbePath, ...] = ()
        if tr.protocol.instruction == "instructed":
            paths = probe_paths(Arm.from_params(p), tr.protocol.probes,
                                tr.protocol.extra_probes)
        return NextTrial(nxt.index, p, host.pair.compile(p, p), paths)

    def next(self, host: ActivityHost, trial: NextTrial) -> dict[str, Any]:
        """Render the prepared trial's arm; after the last trial, close the protocol."""
        tr = self.session
        if trial.index == -1:
            if not tr.done:
                tr.finish(host.t_s, window=self.judge_window(host))
                if tr.done:
                    self._end(host)
            return tr.state(host.t_s)
        assert trial.sims is not None and trial.params is not None
        host.safety.require_armed("next trial")
        t = tr.begin(trial.index, host.t_s, trial.paths, window=self.judge_window(host))
        self.open_window(host)
        host.queue_models(trial.sims, (trial.params, trial.params), None, None, session=False)
        host.log_event("train_trial", trial=t.index, phase=t.phase, condition=t.condition)
        return tr.state(host.t_s)

    def answer(self, host: ActivityHost, answer: str) -> dict[str, Any]:
        tr = self.session
        host.safety.require_armed("training answer")  # no answer counts while nothing is felt
        rec = tr.answer(answer, host.t_s, window=self.judge_window(host))
        host.log_event("train_answer", trial=rec["trial"], answer=rec["answer"],
                       flagged=rec["flagged"])
        out: dict[str, Any] = {"trial": rec["trial"] + 1, "recorded": True, "done": tr.done,
                       "flagged": rec["flagged"], "flags": rec["flags"]}
        if tr.done:
            self._end(host)
            out["result"] = tr.result()
        return out

    def stop(self, host: ActivityHost) -> dict[str, Any]:
        tr = self.session
        if not tr.done:
            tr.finish(host.t_s, abandon=True, window=self.judge_window(host))
            self._end(host)
        return tr.state(host.t_s)

    def close(self, t_s: float) -> None:
        if not self.session.done:
            self.session.finish(t_s, abandon=True)

    def result(self) -> dict[str, Any]:
        return self.session.result()

    def state(self, t_s: float) -> dict[str, Any]:
        return self.session.state(t_s)

    def _end(self, host: ActivityHost) -> None:
        """The protocol ended: the patient's pair back, the end logged."""
        if self._home is not None:
            sims, params = self._home
            self._home = None
            host.queue_models(sims, params, None, None, session=False)
            host.log_event("training_pair_restored")
        tr = self.session
        host.log_event("train_end", abandoned=tr.abandoned,
                       answered=len([r for r in tr.records if r["answer"] is not None]))
