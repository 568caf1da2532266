"""The station's configuration: light (the standard library and the validator only), so the
renderer's process can make one without loading the web server. One bounds table
(:data:`STATION_BOUNDS`) and one list of views serve the session's options
(:class:`haptic.station.launch.StationOptions`) and the station process's configuration."""

from __future__ import annotations

import secrets
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from fieldbank.errors import ParameterError
from fieldbank.validation import Interval, check_fields

#: How the arm is drawn: the patient faces the clinician (the seed's picture) or is seen from
#: behind.
VIEWS = ("opposite", "behind")
#: Allowed range of each numeric setting of a station (messages are generated).
STATION_BOUNDS: dict[str, Interval] = {
    "port": Interval.whole(0, 65535),
    "frame_hz": Interval(1.0, 240.0, "Hz"),
}


def check_view(view: object) -> None:
    """ParameterError unless ``view`` is one of :data:`VIEWS`."""
    if view not in VIEWS:
        raise ParameterError(f"The 'view' station setting must be {' or '.join(VIEWS)}; got "
                             f"{view!r} instead.")


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
    panel : dict
        The settings of the page's panel (:mod:`haptic.station.panel`; a remote assessment's:
        the link's tap, the assessment log, the candidates), read by the panel's program;
        empty for an ordinary session.
    """

    snapshot_path: str
    socket_path: str
    token: str
    host: str = "127.0.0.1"
    port: int = 0
    frame_hz: float = 60.0
    training: dict[str, Any] = field(default_factory=dict)
    view: str = "opposite"
    panel: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        check_fields(self, STATION_BOUNDS, what="station setting")
        check_view(self.view)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> StationConfig:
        return cls(**{k: d[k] for k in cls.__dataclass_fields__ if k in d})

    def to_dict(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


def new_token() -> str:
    """A fresh per-session secret (URL-safe, 192 bits)."""
    return secrets.token_urlsafe(24)
