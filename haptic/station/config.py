"""The station's configuration: light (standard library only), so the renderer's process can
make one without loading the web server."""

from __future__ import annotations

import secrets
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class StationConfig:
    """What the station process needs (passed on its standard input, never on its command line).

    Attributes
    ----------
    snapshot_path : str
        The loop's snapshot file.
    socket_path : str
        The renderer's control socket.
    token : str
        The per-session secret every request must carry.
    host : str
        Address to bind (127.0.0.1 unless the user asked for another).
    port : int
        0: any free port.
    frame_hz : float, Hz
        Frames sent to each page per second.
    training : dict
        The training protocol 'Start training' begins (``TrainingProtocol.to_dict``).
    view : str
        'opposite' (the patient faces the clinician, as in the seed) or 'behind'.
    remote : dict
        A remote assessment (:mod:`haptic.remote.station`): the link's tap, the assessment
        log, the candidates; empty for an ordinary session.
    """

    snapshot_path: str
    socket_path: str
    token: str
    host: str = "127.0.0.1"
    port: int = 0
    frame_hz: float = 60.0
    training: dict[str, Any] = field(default_factory=dict)
    view: str = "opposite"
    remote: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> StationConfig:
        return cls(**{k: d[k] for k in cls.__dataclass_fields__ if k in d})

    def to_dict(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


def new_token() -> str:
    """A fresh per-session secret (URL-safe, 192 bits)."""
    return secrets.token_urlsafe(24)
