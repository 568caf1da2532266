"""What the renderer is told about a model: one typed record from the command line to the trace."""

from __future__ import annotations

import pytest

from fieldbank.haptic import commands as C
from fieldbank.haptic.errors import CommandError
from fieldbank.haptic.modelinfo import MAX_LABEL_CHARS, ModelInfo, model_info_pair, to_wire
from tests.haptic_util import severe_shoulder, unimpaired


def test_the_product_shortens_its_own_long_descriptions_the_wire_refuses_them() -> None:
    long = "botulinum " * 40
    rec = ModelInfo.describe(f"after: {long}", 7, "P-001", long)
    assert rec.label is not None and rec.plan is not None
    assert len(rec.label) == MAX_LABEL_CHARS and rec.label.endswith("…")
    assert rec.plan.startswith("botulinum") and len(rec.plan) == MAX_LABEL_CHARS
    assert ModelInfo.describe("short", None).label == "short"  # short text is kept whole
    # what the command line sends is accepted as sent
    assert model_info_pair(to_wire({"A": rec, "B": rec})) == {"A": rec, "B": rec}
    # the wire never shortens: over-long text from another process is refused, naming it
    with pytest.raises(CommandError, match=r"model_info B\.plan must be text of at most 200"):
        model_info_pair({"B": {"plan": long}}, "push")
    with pytest.raises(CommandError, match="at most 200"):
        ModelInfo(label=long)
    with pytest.raises(CommandError, match="positive integer"):
        ModelInfo.describe("x", model_id=0)


def test_a_push_carries_records_to_the_renderer() -> None:
    a, b = severe_shoulder(), unimpaired()
    info = {"A": ModelInfo.describe("fitted", 4, "P-001"),
            "B": ModelInfo.describe("after: botulinum", None, "P-001", "botulinum")}
    built = C.Push(a, b, {"A": 4, "B": None}, info)
    parsed = C.parse_request({"cmd": "push", "before": a.to_dict(), "after": b.to_dict(),
                              "model_ids": {"A": 4, "B": None}, "model_info": to_wire(info)})
    assert isinstance(parsed, C.Push)
    assert parsed.model_info == built.model_info == info
    # built in process from wire dictionaries, a push holds records too
    assert C.Push(a, b, None, to_wire(info)).model_info == info
