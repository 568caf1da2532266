"""A session's trace put together once the loop has stopped (:func:`assemble_trace`).

The loop keeps one row per tick in a :class:`~haptic.recording.TraceBuffer`; at the end the rows
become a :class:`~haptic.recording.Trace` with everything needed to read it later without the
renderer: both models' parameters, the events and faults, the loop's timing figures, and in the
metadata the renderer's and the safety layer's settings, the device, and the results of its
activities (:mod:`haptic.activities`: the A/B/X blocks, the training protocols; one still
running at the end is kept as it stood, a training protocol marked abandoned).
"""

from __future__ import annotations

import datetime as _dt
from dataclasses import asdict
from typing import Any

import numpy as np

from fieldbank.haptic.protocol import DeviceInfo
from fieldbank.haptic.recording import NCOL, Trace, TraceBuffer
from fieldbank.haptic.safety import Safety
from fieldbank.params import ArmParams


def settings(config: object) -> dict[str, Any]:
    """A frozen configuration as plain values (tuples as lists)."""
    return {k: (list(v) if isinstance(v, tuple) else v)
            for k, v in asdict(config).items()}  # type: ignore[call-overload]


def assemble_trace(buf: TraceBuffer | None, *, rate_hz: int,
                   params: tuple[ArmParams, ArmParams], events: list[dict[str, Any]],
                   safety: Safety, stats: dict[str, Any], metadata: dict[str, Any],
                   renderer_config: object, device: DeviceInfo | None,
                   results: dict[str, list[dict[str, Any]]]) -> Trace:
    """The session's :class:`~haptic.recording.Trace` (float32 rows, ``rate_hz`` Hz);
    ``results``: the activities' results by kind (``abx``, ``training``), kept in the
    metadata under their kind."""
    if buf is not None:
        t, data = buf.arrays()
    else:
        t, data = np.zeros(0), np.zeros((0, NCOL), np.float32)
    meta = dict(metadata)
    meta.setdefault("renderer", settings(renderer_config))
    meta.setdefault("safety", settings(safety.config))
    if device is not None:
        meta.setdefault("device", asdict(device))
    for kind, done in results.items():
        meta[kind] = done
    return Trace(t_s=t, data=data.astype(np.float32, copy=False), rate_hz=float(rate_hz),
                 models={"A": params[0].to_dict(), "B": params[1].to_dict()},
                 events=list(events), faults=[r.to_dict() for r in safety.log_records],
                 stats=stats, metadata=meta)


def utc_now() -> str:
    """The wall-clock time now, UTC, ISO 8601 to the microsecond."""
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="microseconds")
