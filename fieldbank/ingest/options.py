"""What the user tells ingest that a file does not say: metadata defaults and column names.

A plain lab CSV often has no ``# kind/frame/sign/velocity`` lines and its own column names.
``fieldbank ingest --kind postural --frame shoulder --sign arm-on-handle --velocity 0
--column x_mm=HandX --column fx_n=ForceX`` supplies them: the flags fill only what the file
lacks (a file that says otherwise is a problem, never silently overridden), and each
``--column NAME=HEADER`` reads the file's column HEADER as the quantity and unit NAME (for raw
recordings, NAME is a channel role — x, y, vx, vy, fx, fy, or position/velocity/force for NWB
series, hand for a KINARM exam — and HEADER the file's channel or series name). For raw
recordings ``--sign`` says whose force the file holds, ``--shoulder X,Y`` where the
shoulder is in the file's coordinates, ``--trial-events LABEL`` which events start trials and
``--unit ROLE=UNIT`` the unit of a channel the file states none for. A map file (CSV, HDF5,
MAT) given an option it cannot take is refused, never silently ignored.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from fieldbank.errors import ParameterError

#: Metadata keys the flags can supply.
DEFAULT_KEYS = ("kind", "frame", "sign", "velocity_m_per_s", "velocity_vector_m_per_s")


@dataclass(frozen=True)
class ReadOptions:
    """Metadata defaults (``kind``, ``frame``, ``sign``, ``velocity_m_per_s``,
    ``velocity_vector_m_per_s``) and a column mapping (our name → the file's)."""

    defaults: Mapping[str, str] = field(default_factory=dict)
    columns: Mapping[str, str] = field(default_factory=dict)
    #: The shoulder's position in a raw recording's own coordinates (m); None: the file's
    #: positions are in the shoulder frame already.
    shoulder_m: tuple[float, float] | None = None
    #: Raw recordings: the event labels that start trials (other events are ignored).
    trial_events: tuple[str, ...] = ()
    #: Raw recordings: the unit of a channel the file gives none (role → unit).
    units: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        bad = [k for k in self.defaults if k not in DEFAULT_KEYS]
        if bad:
            raise ParameterError(f"unknown ingest default(s) {', '.join(bad)}; known: "
                                 f"{', '.join(DEFAULT_KEYS)}")
        object.__setattr__(self, "defaults", dict(self.defaults))
        object.__setattr__(self, "columns", dict(self.columns))
        object.__setattr__(self, "units", dict(self.units))
        object.__setattr__(self, "trial_events", tuple(self.trial_events))

    def raw_only(self) -> list[str]:
        """The options given that only raw recordings take (for a map file's refusal)."""
        out = []
        if self.shoulder_m is not None:
            out.append("--shoulder")
        if self.trial_events:
            out.append("--trial-events")
        if self.units:
            out.append("--unit")
        return out

    def csv_defaults(self) -> dict[str, str]:
        return dict(self.defaults)

    @classmethod
    def from_flags(cls, kind: str | None = None, frame: str | None = None,
                   sign: str | None = None, velocity: str | None = None,
                   columns: tuple[str, ...] = (),
                   shoulder_m: tuple[float, float] | None = None,
                   trial_events: tuple[str, ...] = (),
                   units: tuple[str, ...] = ()) -> ReadOptions:
        """From command-line values; ``velocity`` is a speed (m/s, '0' static) or 'vx,vy'."""
        d: dict[str, str] = {}
        for key, value in (("kind", kind), ("frame", frame), ("sign", sign)):
            if value:
                d[key] = value
        if velocity:
            if "," in velocity:
                parts = velocity.split(",")
                try:
                    vx, vy = (float(p) for p in parts)
                except ValueError:
                    raise ParameterError(f"--velocity {velocity!r}: expected a speed in m/s "
                                         "or 'vx,vy'") from None
                d["velocity_vector_m_per_s"] = f"{vx!r}, {vy!r}"
                d["velocity_m_per_s"] = repr((vx * vx + vy * vy) ** 0.5)
            else:
                d["velocity_m_per_s"] = velocity
        cols: dict[str, str] = {}
        for item in columns:
            name, sep, header = item.partition("=")
            if not sep or not name.strip() or not header.strip():
                raise ParameterError(f"--column {item!r}: expected NAME=HEADER, e.g. "
                                     "x_mm=HandX")
            cols[name.strip()] = header.strip()
        unit_map: dict[str, str] = {}
        for item in units:
            role, sep, unit = item.partition("=")
            if not sep or not role.strip() or not unit.strip():
                raise ParameterError(f"--unit {item!r}: expected ROLE=UNIT, e.g. fx=N or "
                                     "position=mm")
            unit_map[role.strip()] = unit.strip()
        events = tuple(e.strip() for item in trial_events for e in item.split(",")
                       if e.strip())
        return cls(d, cols, shoulder_m, events, unit_map)
