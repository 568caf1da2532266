"""What every activity is built on: the :class:`Activity` base, the loop as activities see it
(:class:`ActivityHost`), and the renderer's record of them (:class:`Activities`).

An activity's life, every step at a tick boundary in the loop's thread (the renderer's commands,
:mod:`haptic.commands`, call these and nothing else)::

    Activities.start(activity, host)  -> activity.start(host)     the first state, or refused
    activity.<its own steps>(host, …)                              A/B/X present; training next
    activity.answer(host, answer)                                  an answer and its verdict
    activity.tick(fx, fy, armed)                                   every tick while it runs
    activity.stop(host)                                            ended early (answers kept)
    Activities.finished(activity)     -> activity.result()         kept for the session's trace

While one runs, its :attr:`Activity.blinded` says whether the display must hide which model is
felt; :attr:`Activity.owns_blend` refuses a switch, :attr:`Activity.owns_models` a push.
"""

from __future__ import annotations

from typing import Any, ClassVar, Protocol

from fieldbank.haptic.activities.window import TrialWindow
from fieldbank.haptic.errors import CommandError
from fieldbank.haptic.modelinfo import ModelIds, ModelInfoPair
from fieldbank.haptic.pair import ModelPair, SimPair
from fieldbank.haptic.safety import Safety
from fieldbank.params import ArmParams


class ActivityHost(Protocol):
    """The loop as its activities see it (:class:`haptic.renderer.Renderer`).

    ``t_s`` and ``dt_s`` are the session's time and period; ``safety`` its latched state
    machine (mode, fault log: a protocol pauses on a fault, :meth:`Safety.require_armed`);
    ``pair`` the models rendered (:class:`~haptic.pair.ModelPair`: crossfade, compile, the pair
    now); :meth:`queue_models` swaps compiled models in (behind the fade while the loop runs);
    :meth:`log_event` records an event in the session's trace.
    """

    t_s: float
    dt_s: float
    safety: Safety
    pair: ModelPair

    def queue_models(self, sims: SimPair, params: tuple[ArmParams, ArmParams],
                     model_ids: ModelIds | None,
                     model_info: ModelInfoPair | None = None, session: bool = True) -> None: ...
    def log_event(self, kind: str, **data: Any) -> dict[str, Any]: ...


class Activity:
    """Base of every activity.

    Attributes
    ----------
    kind : str
        Its name in the session's results (the trace's metadata key: 'abx', 'training').
    title : str
        What it is called in a message ("an A/B/X block").
    restartable : bool
        Starting another of the same kind while it runs closes it (its answers kept) instead of
        being refused.
    owns_blend, owns_models : bool
        While it runs, a switch (it chooses what is felt) or a push (it renders its own
        models) is refused.
    kept_when_done : bool
        Once finished it is still addressed (its steps answer its final state) until another
        of its kind starts; otherwise a finished one is gone.
    window : TrialWindow
        The current trial's window, fed by :meth:`tick`.
    """

    kind: ClassVar[str]
    title: ClassVar[str]
    restartable: ClassVar[bool] = False
    owns_blend: ClassVar[bool] = True
    owns_models: ClassVar[bool] = False
    kept_when_done: ClassVar[bool] = False
    window: TrialWindow

    @property
    def done(self) -> bool:
        """Every trial answered (or the activity stopped)."""
        raise NotImplementedError

    @property
    def blinded(self) -> bool:
        """True while nothing may say which model is felt."""
        raise NotImplementedError

    def start(self, host: ActivityHost) -> dict[str, Any]:
        """Begin (refused unless armed); the state a display shows."""
        raise NotImplementedError

    def answer(self, host: ActivityHost, answer: str) -> dict[str, Any]:
        """Record the answer to the current trial with its window's verdict; the next trial,
        and the result once the last is answered."""
        raise NotImplementedError

    def tick(self, fx: float, fy: float, armed: bool) -> None:
        """Every tick while it runs: the force the loop commanded and whether it was armed."""
        self.window.tick(fx, fy, armed)

    def stop(self, host: ActivityHost) -> dict[str, Any]:
        """End early; the trials so far are kept."""
        raise NotImplementedError

    def close(self, t_s: float) -> None:
        """The session ends while it runs: keep what it has (nothing is asked of the loop)."""
        del t_s

    def result(self) -> dict[str, Any]:
        """What the session keeps of it (the trace's metadata, the database's trials)."""
        raise NotImplementedError

    def state(self, t_s: float) -> dict[str, Any]:
        """What a display may show now (nothing that names the model while blinded)."""
        raise NotImplementedError

    def open_window(self, host: ActivityHost) -> None:
        """A trial starts: judge the coming window from here."""
        self.window.open(host.safety)

    def judge_window(self, host: ActivityHost) -> dict[str, Any]:
        """The verdict on the window since :meth:`open_window`: flagged, flags, peak force."""
        return self.window.judge(host.safety, host.dt_s)


class Activities:
    """The activity running on a renderer (one at a time), the newest of each kind (a display
    still shows a finished training protocol), and the results of those that finished.

    Owned by the loop's thread; other threads only read.
    """

    def __init__(self, kinds: tuple[str, ...] = ("abx", "training")) -> None:
        #: the activity running now, None when none is
        self.running: Activity | None = None
        self.newest: dict[str, Activity] = {}
        #: results of the finished ones by kind, oldest first (the trace's metadata)
        self.results: dict[str, list[dict[str, Any]]] = {k: [] for k in kinds}

    @property
    def blinded(self) -> bool:
        """True while the running activity hides which model is felt."""
        run = self.running
        return run is not None and run.blinded

    def addressed(self, kind: str) -> Activity | None:
        """The activity of ``kind`` that commands address: the running one, or the newest
        finished one if its kind is :attr:`~Activity.kept_when_done`; None when there is none."""
        act = self.newest.get(kind)
        if act is None or (act.done and not act.kept_when_done):
            return None
        return act

    def after_step(self, activity: Activity) -> None:
        """A command stepped ``activity``: keep its result once it is done (once)."""
        if activity.done and self.running is activity:
            self.finished(activity)

    def start(self, activity: Activity, host: ActivityHost) -> dict[str, Any]:
        """Start ``activity`` (refused while another runs, unless it is restartable and of the
        same kind: then that one is closed first, its answers kept)."""
        run = self.running
        if run is not None:
            if run.kind != activity.kind or not activity.restartable:
                raise CommandError(
                    f"{activity.title} cannot start while {run.title} runs" if run.kind
                    != activity.kind else f"{run.title} is already running: stop it first")
        out = activity.start(host)
        if run is not None:
            run.close(host.t_s)
            self.finished(run)
        self.running = activity
        self.newest[activity.kind] = activity
        return out

    def finished(self, activity: Activity) -> dict[str, Any]:
        """Keep ``activity``'s result; it no longer runs. The result."""
        res = activity.result()
        self.results.setdefault(activity.kind, []).append(res)
        if self.running is activity:
            self.running = None
        return res

    def close(self, t_s: float) -> None:
        """The session ends: the running activity's result is kept as it stands."""
        run = self.running
        if run is not None:
            run.close(t_s)
            self.finished(run)
