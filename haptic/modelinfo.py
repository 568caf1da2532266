"""What the renderer is told about a model: the one typed record (:class:`ModelInfo`).

A display (the clinician's station, ``fieldbank haptic status``) names the two rendered models
by what the renderer was told about them: a label, the stored model's id, the patient and, for
a what-if result, the plan. The command line builds the record (:meth:`ModelInfo.describe`
shortens over-long text to :data:`MAX_LABEL_CHARS`); the wire carries its dictionary
(``{"A": {"label", "model_id", "patient", "plan"}, "B": {…}}``), read back strictly by
:func:`model_info_pair` (over-long text or a wrong key is refused, never cut). The trace keeps
the same dictionary in its metadata.

Light: the standard library and the exception modules only, so the live command line loads it
without numpy.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from fieldbank.haptic.errors import CommandError

#: Longest text of a model description field.
MAX_LABEL_CHARS = 200
#: Largest model id accepted from the wire (ids are database integers).
MAX_MODEL_ID = 2**63 - 1
#: The fields of a model's description, in wire order.
FIELDS = ("label", "model_id", "patient", "plan")


def check_model_id(value: object, key: str, where: str) -> int | None:
    """A positive integer model id, or None."""
    if value is not None and (isinstance(value, bool) or not isinstance(value, int)
                              or not 1 <= value <= MAX_MODEL_ID):
        raise CommandError(f"{where}: model id {key} must be a positive integer or null; "
                           f"got {value!r}")
    return value


@dataclass(frozen=True)
class ModelInfo:
    """What a display says about one rendered model.

    Attributes
    ----------
    label : str or None
        What the model is ("fitted model 12 of P-001", "after: botulinum ef 200 U").
    model_id : int or None
        The stored model's id (None: not stored).
    patient : str or None
        The patient's code.
    plan : str or None
        The plan's label when the model is a what-if result.
    """

    label: str | None = None
    model_id: int | None = None
    patient: str | None = None
    plan: str | None = None

    def __post_init__(self) -> None:
        _check(self, "", "model info")

    @classmethod
    def describe(cls, label: str | None, model_id: int | None = None,
                 patient: str | None = None, plan: str | None = None) -> ModelInfo:
        """The record of a model described by the product itself: text longer than
        :data:`MAX_LABEL_CHARS` is shortened (ending in an ellipsis) rather than refused."""
        return cls(_shorten(label), model_id, _shorten(patient), _shorten(plan))

    @classmethod
    def from_dict(cls, d: object, key: str, where: str) -> ModelInfo:
        """The record of one wire entry, checked strictly."""
        if not isinstance(d, Mapping) or not set(d) <= set(FIELDS):
            raise CommandError(f"{where}: model_info {key} has the keys label, model_id, "
                               "patient, plan")
        vals = {f: d.get(f) for f in FIELDS}
        for f in ("label", "patient", "plan"):  # before the record is built: with its key
            _check_text(vals[f], f"model_info {key}.{f}", where)
        return cls(vals["label"], check_model_id(vals["model_id"], key, where), vals["patient"],
                   vals["plan"])

    def to_dict(self) -> dict[str, Any]:
        return {"label": self.label, "model_id": self.model_id, "patient": self.patient,
                "plan": self.plan}


#: What the renderer is told about models A and B.
ModelInfoPair = Mapping[str, ModelInfo]
#: Database ids of the rendered models, ``{"A": id, "B": id}`` (None: not stored).
ModelIds = Mapping[str, "int | None"]


def check_model_ids(ids: object, where: str = "push") -> dict[str, int | None] | None:
    """``{"A": id, "B": id}`` with positive integer ids or null; None stays None."""
    if ids is None:
        return None
    if not (isinstance(ids, Mapping) and set(ids) <= {"A", "B"}):
        raise CommandError(f'{where}: "model_ids" must be {{"A": id, "B": id}}')
    return {k: check_model_id(v, k, where) for k, v in ids.items()}


def model_info_pair(info: object, where: str = "push") -> dict[str, ModelInfo] | None:
    """``{"A": …, "B": …}`` of :class:`ModelInfo` records or their wire dictionaries, checked;
    None stays None."""
    if info is None:
        return None
    if not (isinstance(info, Mapping) and set(info) <= {"A", "B"}):
        raise CommandError(f'{where}: "model_info" must be {{"A": {{…}}, "B": {{…}}}}')
    return {k: v if isinstance(v, ModelInfo) else ModelInfo.from_dict(v, k, where)
            for k, v in info.items()}


def to_wire(info: ModelInfoPair | None) -> dict[str, dict[str, Any]] | None:
    """The wire and trace form of a pair of records."""
    return None if info is None else {k: v.to_dict() for k, v in info.items()}


def _check_text(value: object, name: str, where: str) -> None:
    if value is not None and (not isinstance(value, str) or len(value) > MAX_LABEL_CHARS):
        raise CommandError(f"{where}: {name} must be text of at most {MAX_LABEL_CHARS} "
                           "characters")


def _check(info: ModelInfo, key: str, where: str) -> None:
    for f in ("label", "patient", "plan"):
        _check_text(getattr(info, f), f, where)
    check_model_id(info.model_id, key, where)


def _shorten(text: str | None) -> str | None:
    if text is None or len(text) <= MAX_LABEL_CHARS:
        return text
    return text[: MAX_LABEL_CHARS - 1] + "…"
