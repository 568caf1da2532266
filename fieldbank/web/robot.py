"""The one seam between the workspace and the robot: what "Feel it" asks of whatever renders.

The plan composer (interventions) computes a model after a plan; the robot (haptic) renders
models. The two never import each other: the composer calls a :class:`RobotSeam` it is handed,
and the command line hands it the haptic wing's implementation
(:class:`fieldbank.haptic.workspace.RendererHost`), which starts the configured robot's
renderer - a simulated one where none is configured - pushes the pair, and serves the robot
view at :attr:`RobotSeam.view_path` in the same application. Re-pointing the workspace at
another renderer (a new robot port, new activities) means another implementation of this
Protocol, nothing else.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

from fieldbank.params import ArmParams


@dataclass(frozen=True)
class FeelPair:
    """What the clinician asked to feel: A (before) and B (after), for one patient.

    Attributes
    ----------
    before, after : ArmParams
    model_ids : (int or None, int or None)
        Their stored ids (the session's record refers to them); None for an unsaved after
        model (its parameters go into the session's trace).
    patient_code : str or None
    labels : (str, str)
        What the robot view says of each (hidden while blinded).
    plan_label : str
        The plan, in words (model B's description).
    plan_id : int or None
        The stored plan, when saved.
    actor : str
        Who asked (the renderer records its session as this account).
    """

    before: ArmParams
    after: ArmParams
    model_ids: tuple[int | None, int | None]
    patient_code: str | None
    labels: tuple[str, str]
    plan_label: str = ""
    plan_id: int | None = None
    actor: str = ""


class RobotSeam(Protocol):
    """A renderer the workspace can start and push to."""

    #: Where the robot view is served in the application (``/robot``).
    view_path: str

    def feel(self, pair: FeelPair) -> dict[str, Any]:
        """Make sure a renderer runs for ``pair.patient_code`` (starting the configured robot,
        or a simulated one), push the pair; what the renderer answered, the robot's URL
        (masked), whether it is simulated, and :attr:`view_path`. Blocking: call it from a
        worker thread."""
        ...

    def status(self) -> dict[str, Any]:
        """Whether a renderer runs, for which patient, on which robot, and its state."""
        ...

    def stop(self) -> dict[str, Any]:
        """End the running session (its trace is written and recorded)."""
        ...
