"""What the user tells ingest that a file does not say: metadata defaults and column names.

A plain lab CSV often has no ``# kind/frame/sign/velocity`` lines and its own column names.
``fieldbank ingest --kind postural --frame shoulder --sign arm-on-handle --velocity 0
--column x_mm=HandX --column fx_n=ForceX`` supplies them: the flags fill only what the file
lacks (a file that says otherwise is a problem, never silently overridden), and each
``--column NAME=HEADER`` reads the file's column HEADER as the quantity and unit NAME (for raw
recordings, NAME is a channel role — x, y, vx, vy, fx, fy, or position/velocity/force for NWB
series — and HEADER the file's channel or series name).
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

    def __post_init__(self) -> None:
        bad = [k for k in self.defaults if k not in DEFAULT_KEYS]
        if bad:
            raise ParameterError(f"unknown ingest default(s) {', '.join(bad)}; known: "
                                 f"{', '.join(DEFAULT_KEYS)}")
        object.__setattr__(self, "defaults", dict(self.defaults))
        object.__setattr__(self, "columns", dict(self.columns))

    def csv_defaults(self) -> dict[str, str]:
        return dict(self.defaults)

    @classmethod
    def from_flags(cls, kind: str | None = None, frame: str | None = None,
                   sign: str | None = None, velocity: str | None = None,
                   columns: tuple[str, ...] = ()) -> ReadOptions:
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
        return cls(d, cols)
