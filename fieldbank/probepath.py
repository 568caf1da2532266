"""A probe as plain data, and the file of designed probes.

A :class:`ProbePath` is what a station draws and an operator - a clinician, the simulated
operator of :mod:`fieldbank.haptic`, the simulated trainee - follows: a name, what to do in
words, and a polyline of hand positions with their times. Its points are in the **robot
frame**, the shoulder frame shifted by ``shoulder_offset_m``, which the path records; a path
with a zero offset is in the shoulder frame, which is how the training protocol keeps its paths
(:meth:`ProbePath.in_shoulder_frame`), so a probe designed for one robot is placed right on a
robot whose shoulder sits elsewhere.

Every probe of :mod:`fieldbank.evaluate` becomes one (:meth:`ProbeMotion.path
<fieldbank.evaluate.probing.ProbeMotion.path>`); ``fieldbank probe design --out FILE`` writes
them as a probes file, which the training's instructed mode reads (:func:`read_probes`)::

    {"format": "fieldbank-probes", "version": 1,
     "probes": [{"name": "stroke 1", "description": "stroke 15 cm toward the body ...",
                 "frame": "robot", "shoulder_offset_m": [0.0, 0.1],
                 "times_s": [0.0, 0.0133, ...], "points_m": [[0.08, 0.65], ...]}, ...]}

Every field is checked (:data:`PROBE_LIMITS`), and a file's problems are all listed with the
file and the field (``probes.json: probes[1].times_s[4]: ...``). A probe of the training
protocol's earlier form, ``{"name", "times_s", "positions_m"}`` in the shoulder frame, still
reads.

The module imports nothing heavy (no numpy): the live command line reads probes files with it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fieldbank.errors import ParameterError, Problem, ValidationError
from fieldbank.files import read_json_document
from fieldbank.validation import Interval

PROBES_FORMAT = "fieldbank-probes"
PROBES_VERSION = 1
#: Most points of one probe path.
MAX_PROBE_POINTS = 2000
#: Most probes in one probes file.
MAX_PROBES_PER_FILE = 64
#: Most further probes a training protocol draws beside the seed's (a screen's worth).
MAX_DRAWN_PROBES = 8
MAX_NAME_CHARS = 64
MAX_DESCRIPTION_CHARS = 1000
#: Points of a probe path kept for a screen (resampled evenly in time).
DISPLAY_POINTS = 40
#: Bounds of a probe's numbers: times from the start of the motion, positions and the
#: shoulder offset (a planar robot's workspace is well inside).
PROBE_LIMITS: dict[str, Interval] = {
    "times_s": Interval(0.0, 600.0, "s"),
    "points_m": Interval(-2.0, 2.0, "m"),
    "shoulder_offset_m": Interval(-2.0, 2.0, "m"),
}
_FIELDS = ("name", "description", "frame", "shoulder_offset_m", "times_s", "points_m")
_LEGACY_FIELDS = ("name", "times_s", "positions_m")
FRAMES = ("robot", "shoulder")


def _number(value: Any, key: str) -> str | None:
    """The reason ``value`` is not a number within ``PROBE_LIMITS[key]``, else None."""
    interval = PROBE_LIMITS[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return f"must be a number in {interval.describe()}; got {value!r}"
    if not interval.contains(float(value)):
        return f"must be a finite number in {interval.describe()}; got {value!r}"
    return None


def _pair_problems(label: str, value: Any, key: str) -> list[tuple[str, str]]:
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence) or len(value) != 2:
        return [(label, f"must be a pair [x, y] of numbers in m; got {value!r}")]
    out = []
    for k, v in enumerate(value):
        msg = _number(v, key)
        if msg is not None:
            out.append((f"{label}[{k}]", msg))
    return out


def _path_problems(name: Any, description: Any, times: Any, points: Any, offset: Any,
                   points_field: str = "points_m") -> list[tuple[str, str]]:
    """Every problem of a probe's fields, as (field, reason)."""
    out: list[tuple[str, str]] = []
    if not isinstance(name, str) or not 0 < len(name.strip()) <= MAX_NAME_CHARS:
        out.append(("name", f"must be text of 1-{MAX_NAME_CHARS} characters; got {name!r}"))
    if not isinstance(description, str) or len(description) > MAX_DESCRIPTION_CHARS:
        out.append(("description", f"must be text of at most {MAX_DESCRIPTION_CHARS} "
                                   f"characters; got {type(description).__name__}"
                                   + (f" of {len(description)}" if isinstance(description, str)
                                      else "")))
    out += _pair_problems("shoulder_offset_m", offset, "shoulder_offset_m")
    seqs = {}
    for key, value in (("times_s", times), (points_field, points)):
        if isinstance(value, (str, bytes)) or not isinstance(value, Sequence):
            out.append((key, f"must be a list; got {type(value).__name__}"))
        elif not 2 <= len(value) <= MAX_PROBE_POINTS:
            out.append((key, f"must have 2-{MAX_PROBE_POINTS} entries; got {len(value)}"))
        else:
            seqs[key] = value
    if "times_s" in seqs:
        bad = [(f"times_s[{k}]", m) for k, t in enumerate(seqs["times_s"])
               if (m := _number(t, "times_s")) is not None]
        out += bad[:5]
        if not bad:
            ts = [float(t) for t in seqs["times_s"]]
            back = next((k for k in range(1, len(ts)) if ts[k] < ts[k - 1]), None)
            if back is not None:
                out.append((f"times_s[{back}]", f"{ts[back]:g} s comes before the time of the "
                                                f"point before it ({ts[back - 1]:g} s); times "
                                                "must not decrease"))
            elif ts[-1] <= ts[0]:
                out.append(("times_s", "the path must take time: the last time equals the "
                                       "first"))
    if points_field in seqs:
        bad_points: list[tuple[str, str]] = []
        for k, p in enumerate(seqs[points_field]):
            bad_points += _pair_problems(f"{points_field}[{k}]", p, "points_m")
        out += bad_points[:5]
    if "times_s" in seqs and points_field in seqs and \
            len(seqs["times_s"]) != len(seqs[points_field]):
        out.append((points_field, f"must have as many entries as times_s "
                                  f"({len(seqs['times_s'])}); got {len(seqs[points_field])}"))
    return out


@dataclass(frozen=True)
class ProbePath:
    """A probe as plain data: a polyline of hand positions with timing, in the robot frame.

    Attributes
    ----------
    name : str
        Short name ("pull", "stroke 1"), 1-64 characters.
    description : str
        What to do, in words.
    times_s : tuple of float, s
        Time of each point from the start of the motion (not decreasing, first 0 for paths
        made here).
    points_m : tuple of (x, y), m
        Hand positions in the robot frame (shoulder frame + ``shoulder_offset_m``).
    shoulder_offset_m : (x, y), m
        Where the shoulder is in robot coordinates ((0, 0): the points are in the shoulder
        frame).

    Raises
    ------
    ParameterError
        A field outside :data:`PROBE_LIMITS` or of the wrong shape; the message names it.
    """

    name: str
    description: str
    times_s: tuple[float, ...]
    points_m: tuple[tuple[float, float], ...]
    shoulder_offset_m: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        problems = _path_problems(self.name, self.description, self.times_s, self.points_m,
                                  self.shoulder_offset_m)
        if problems:
            raise ParameterError(f"probe {self.name!r}: "
                                 + "; ".join(f"{f}: {r}" for f, r in problems))

    @classmethod
    def from_dict(cls, d: Any, where: str = "probe") -> ProbePath:
        """From :meth:`to_dict`'s form (or the training protocol's earlier
        ``{"name", "times_s", "positions_m"}``, shoulder frame).

        Raises
        ------
        ValidationError
            Every problem, located as ``where.field`` (e.g. ``probes.json: probes[0].times_s``).
        """
        if not isinstance(d, Mapping):
            raise ValidationError([Problem(where, "a probe is a JSON object with "
                                                  f"{', '.join(_FIELDS)}; got "
                                                  f"{type(d).__name__}")])
        legacy = "positions_m" in d and "points_m" not in d
        known = _LEGACY_FIELDS if legacy else _FIELDS
        problems = [Problem(f"{where}.{k}", "unknown field; a probe has "
                                            f"{', '.join(known)}")
                    for k in sorted(set(d) - set(known), key=str)]
        required = ("name", "times_s", "positions_m") if legacy else ("name", "times_s",
                                                                      "points_m")
        problems += [Problem(f"{where}.{k}", "missing") for k in required if k not in d]
        if problems:
            raise ValidationError(problems)
        frame = d.get("frame", "robot")
        offset = d.get("shoulder_offset_m", [0.0, 0.0])
        if frame not in FRAMES:
            problems.append(Problem(f"{where}.frame", f"must be one of {', '.join(FRAMES)}; "
                                                      f"got {frame!r}"))
        elif frame == "shoulder" and offset != [0.0, 0.0] and offset != [0, 0]:
            problems.append(Problem(f"{where}.shoulder_offset_m", "a path in the shoulder frame "
                                                                  "has no shoulder offset"))
        points_field = "positions_m" if legacy else "points_m"
        problems += [Problem(f"{where}.{f}", r) for f, r in _path_problems(
            d["name"], d.get("description", ""), d["times_s"], d[points_field], offset,
            points_field)]
        if problems:
            raise ValidationError(problems)
        return cls(d["name"], d.get("description", ""), tuple(float(t) for t in d["times_s"]),
                   tuple((float(x), float(y)) for x, y in d[points_field]),
                   (float(offset[0]), float(offset[1])))

    def to_dict(self) -> dict[str, object]:
        return {"name": self.name, "description": self.description, "frame": "robot",
                "shoulder_offset_m": list(self.shoulder_offset_m),
                "times_s": [round(t, 6) for t in self.times_s],
                "points_m": [[round(x, 6), round(y, 6)] for x, y in self.points_m]}

    @property
    def duration_s(self) -> float:
        return self.times_s[-1] - self.times_s[0]

    @property
    def shoulder_points_m(self) -> tuple[tuple[float, float], ...]:
        """The points in the shoulder frame (robot frame minus the shoulder offset), m."""
        ox, oy = self.shoulder_offset_m
        return tuple((x - ox, y - oy) for x, y in self.points_m)

    def in_shoulder_frame(self) -> ProbePath:
        """The same path with its points in the shoulder frame (a zero shoulder offset)."""
        if self.shoulder_offset_m == (0.0, 0.0):
            return self
        return ProbePath(self.name, self.description, self.times_s, self.shoulder_points_m)

    def at(self, t_s: float) -> tuple[float, float, float, float]:
        """Position and velocity (x, y, vx, vy) at ``t_s`` from the path's start, in the frame
        of its points (linear between points; held at the ends)."""
        ts, ps = self.times_s, self.points_m
        t = ts[0] + t_s
        if t <= ts[0]:
            return ps[0][0], ps[0][1], 0.0, 0.0
        if t >= ts[-1]:
            return ps[-1][0], ps[-1][1], 0.0, 0.0
        lo, hi = 0, len(ts) - 1
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if ts[mid] <= t:
                lo = mid
            else:
                hi = mid
        dt = ts[hi] - ts[lo]
        if dt <= 0.0:
            return ps[hi][0], ps[hi][1], 0.0, 0.0
        s = (t - ts[lo]) / dt
        (x0, y0), (x1, y1) = ps[lo], ps[hi]
        return x0 + s * (x1 - x0), y0 + s * (y1 - y0), (x1 - x0) / dt, (y1 - y0) / dt

    def display(self, points: int = DISPLAY_POINTS) -> dict[str, Any]:
        """The path for a screen: at most ``points`` positions, evenly spaced in time, in the
        frame of its points."""
        n = max(2, min(points, len(self.times_s)))
        pts = [list(self.at(self.duration_s * k / (n - 1))[:2]) for k in range(n)]
        return {"name": self.name, "duration_s": self.duration_s, "points_m": pts}


def probes_document(paths: Sequence[ProbePath]) -> dict[str, object]:
    """The probes file's JSON document (format "fieldbank-probes", version 1)."""
    return {"format": PROBES_FORMAT, "version": PROBES_VERSION,
            "probes": [p.to_dict() for p in paths]}


def read_probes(path: str | Path, at_most: int = MAX_PROBES_PER_FILE
                ) -> tuple[ProbePath, ...]:
    """The probes of a probes file (:func:`probes_document`; ``fieldbank probe design --out``),
    at most ``at_most`` of them.

    Raises
    ------
    FileRefused
        Not a regular file, too large, unreadable.
    ValidationError
        Not JSON, another format, a newer version, or probes with problems: every problem,
        named by the file and the field.
    """
    p = Path(path)
    doc = read_json_document(p)
    if not isinstance(doc, Mapping) or doc.get("format") != PROBES_FORMAT:
        got = doc.get("format") if isinstance(doc, Mapping) else type(doc).__name__
        raise ValidationError([Problem(f"{p}: format", f"must be {PROBES_FORMAT!r} (a file of "
                                                       "'fieldbank probe design --out'); got "
                                                       f"{got!r}")])
    version = doc.get("version")
    if version != PROBES_VERSION:
        newer = isinstance(version, int) and not isinstance(version, bool) \
            and version > PROBES_VERSION
        raise ValidationError([Problem(f"{p}: version", (
            f"{version} is newer than this fieldbank reads ({PROBES_VERSION}); upgrade "
            "fieldbank") if newer else f"must be {PROBES_VERSION}; got {version!r}")])
    unknown = sorted(set(doc) - {"format", "version", "probes"}, key=str)
    if unknown:
        raise ValidationError([Problem(f"{p}: {k}", "unknown field; a probes file has format, "
                                                    "version, probes") for k in unknown])
    probes = doc.get("probes")
    if not isinstance(probes, list) or not 0 < len(probes) <= at_most:
        got = f"{len(probes)}" if isinstance(probes, list) else type(probes).__name__
        raise ValidationError([Problem(f"{p}: probes", f"must be a list of 1-{at_most} "
                                                       f"probes here; got {got}")])
    out: list[ProbePath] = []
    problems: list[Problem] = []
    seen: dict[str, int] = {}
    for k, item in enumerate(probes):
        try:
            out.append(ProbePath.from_dict(item, f"{p}: probes[{k}]"))
        except ValidationError as exc:
            problems += exc.problems
        name = item.get("name") if isinstance(item, Mapping) else None
        if isinstance(name, str) and name in seen:
            problems.append(Problem(f"{p}: probes[{k}].name", f"{name!r} is the name of "
                                                              f"probes[{seen[name]}] too"))
        if isinstance(name, str):
            seen.setdefault(name, k)
    if problems:
        raise ValidationError(problems, header=f"{p}: not a usable probes file")
    return tuple(out)


__all__ = [
    "MAX_DRAWN_PROBES",
    "MAX_PROBE_POINTS",
    "PROBES_FORMAT",
    "PROBES_VERSION",
    "PROBE_LIMITS",
    "ProbePath",
    "probes_document",
    "read_probes",
]
