"""A C3D file read whole into numpy arrays, by fieldbank's own reader.

The layout is the one of the C3D User Guide (C3D.ORG, "The C3D File Format"): 512-byte
blocks; block 1 the header (the first byte points to the parameter section, the second is the
key 0x50); the parameter section (4 bytes: two reserved, the number of parameter blocks, the
processor type 84 Intel, 85 DEC, 86 MIPS/SGI), then groups and parameters, each
``nchars (int8), id (int8; < 0 a group), name, offset to the next (int16)`` followed, for a
parameter, by ``type (int8: -1 char, 1 byte, 2 int16, 4 float), ndims, dims, data`` and, for
both, a description; then the frames from ``POINT:DATA_START``: per frame ``POINT:USED`` × 4
words (x, y, z and the residual/camera word) and ``ANALOG:USED`` × samples-per-frame analog
words, 16-bit integers scaled by ``POINT:SCALE`` when it is positive, 32-bit floats when it is
negative. Integers and floats are little-endian (Intel), VAX F floats with little-endian words
(DEC) or big-endian (MIPS). Analog values are ``(raw − ANALOG:OFFSET) × ANALOG:GEN_SCALE ×
ANALOG:SCALE``, raw read unsigned when ``ANALOG:FORMAT`` says ``UNSIGNED``.

Why fieldbank reads C3D itself (measured on the c3d.org sample set, docs/measuring.md and
``benchmarks/bench_c3d_readers.py``): the ``c3d`` package stops with an assertion wherever the
header and the parameters disagree (MotionMonitor, Peak's FP1, an older Motion Analysis file),
and ``ezc3d`` reads no SGI/MIPS file, reads a KINARM file without its analog channels, and took
the Python process down (segmentation fault) on the damaged-parameter sample once asked to
tolerate it. Where the two disagree with each other the C3D guide says what the parameters
mean; this reader follows the parameters and checks them against the file's size, and never
allocates more than the file declares and the caller's budget allows.

Labels and units are text with their NUL and space padding removed (Kistler pads with NULs).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fieldbank.errors import MapError

BLOCK = 512
PROCESSORS = {84: "Intel", 85: "DEC", 86: "MIPS (SGI)"}


class C3DError(MapError):
    """A C3D file that cannot be read; the message says where and why."""


def clean_label(raw: bytes | str) -> str:
    """A C3D text entry without its padding: cut at the first NUL, spaces stripped."""
    text = raw.decode("latin-1") if isinstance(raw, bytes) else raw
    return text.split("\0", 1)[0].strip()


def _dec_floats(buf: bytes) -> np.ndarray:
    """VAX F floats (DEC) as float32: swap the two 16-bit words, read IEEE, divide by 4."""
    words = np.frombuffer(buf, dtype="<u2").reshape(-1, 2)[:, ::-1]
    return np.ascontiguousarray(words).view("<f4").ravel() / np.float32(4.0)


@dataclass(frozen=True)
class Param:
    """One C3D parameter: its type (-1 char, 1 byte, 2 int16, 4 float), dims and data."""

    name: str
    type: int
    dims: tuple[int, ...]
    data: bytes
    processor: int

    def numbers(self) -> np.ndarray:
        """The values as float64, flat in file order (first dimension fastest)."""
        big = self.processor == 86
        if self.type == 4:
            if self.processor == 85:
                return _dec_floats(self.data).astype(float)
            return np.frombuffer(self.data, dtype=">f4" if big else "<f4").astype(float)
        if self.type == 2:
            return np.frombuffer(self.data, dtype=">i2" if big else "<i2").astype(float)
        if self.type == 1:
            return np.frombuffer(self.data, dtype="i1").astype(float)
        raise C3DError(f"parameter {self.name} holds text, not numbers")

    def unsigned(self) -> np.ndarray:
        """int16 values read as unsigned (counts above 32767)."""
        if self.type == 2:
            return np.frombuffer(self.data, dtype=">u2" if self.processor == 86 else "<u2"
                                 ).astype(float)
        return self.numbers()

    def strings(self) -> list[str]:
        """Text entries: the first dimension is the length of each."""
        if self.type != -1:
            return [f"{v:g}" for v in self.numbers()]
        if not self.dims:
            return [clean_label(self.data)]
        width = self.dims[0]
        if width <= 0:
            return []
        n = len(self.data) // width
        return [clean_label(self.data[i * width:(i + 1) * width]) for i in range(n)]

    def first(self, default: float = 0.0) -> float:
        v = self.numbers() if self.type != -1 else np.zeros(0)
        return float(v[0]) if v.size else default


@dataclass
class C3DFile:
    """What a C3D file holds, in its own units (see the module docstring).

    points : (frames, points, 3) in ``point_unit``, NaN where the residual marks a point
        invalid; analog : (channels, samples), scaled; groups : name -> {parameter name: Param}.
    """

    processor: str
    storage: str                      # "integer" | "float"
    point_rate_hz: float
    analog_rate_hz: float
    first_frame: int
    point_labels: list[str]
    point_unit: str
    points: np.ndarray
    analog_labels: list[str]
    analog_units: list[str]
    analog: np.ndarray
    groups: dict[str, dict[str, Param]] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    @property
    def frames(self) -> int:
        return int(self.points.shape[0])

    def param(self, key: str) -> Param | None:
        group, _, name = key.partition(":")
        return self.groups.get(group.upper(), {}).get(name.upper())

    def strings(self, key: str) -> list[str]:
        p = self.param(key)
        return p.strings() if p is not None else []

    def events(self) -> list[tuple[str, float, str]]:
        """(label, time s, context) of every event in the EVENT group (or KINARM's EVENTS),
        or the header's events when there is no group; [] when they disagree in length."""
        for g in ("EVENT", "EVENTS"):
            labels = self.strings(f"{g}:LABELS")
            times_p = self.param(f"{g}:TIMES")
            if not labels or times_p is None or times_p.type == -1:
                continue
            times = times_p.numbers()
            if times.size == 2 * len(labels):
                pairs = times.reshape(-1, 2)
                secs = 60.0 * pairs[:, 0] + pairs[:, 1]
            elif times.size == len(labels):
                secs = times
            else:
                return []
            ctx = self.strings(f"{g}:CONTEXTS")
            return [(lab, float(t), ctx[i] if i < len(ctx) else "")
                    for i, (lab, t) in enumerate(zip(labels, secs, strict=True))]
        return []


def _parse_parameters(data: bytes, start: int, processor: int) -> dict[str, dict[str, Param]]:
    """Groups and parameters of the section starting at byte ``start``."""
    nblocks = data[start + 2]
    end = min(len(data), start + max(1, nblocks) * BLOCK)
    big = processor == 86
    i16 = ">h" if big else "<h"
    pos = start + 4
    names: dict[int, str] = {}
    params: dict[int, dict[str, Param]] = {}
    for _ in range(100_000):
        if pos + 2 > end:
            break
        nchars, gid = struct.unpack_from("bb", data, pos)
        if nchars == 0 or gid == 0:
            break
        n = abs(nchars)
        name = clean_label(data[pos + 2:pos + 2 + n]).upper()
        off_at = pos + 2 + n
        if off_at + 2 > end:
            break
        (offset,) = struct.unpack_from(i16, data, off_at)
        body = off_at + 2
        nxt = off_at + offset if offset > 0 else end
        if gid < 0:
            names[-gid] = name
        else:
            try:
                ptype, ndims = struct.unpack_from("bB", data, body)
                dims = tuple(data[body + 2:body + 2 + ndims])
                size = abs(ptype) * int(np.prod(dims, dtype=np.int64)) if ndims else abs(ptype)
                d0 = body + 2 + ndims
                if ptype not in (-1, 1, 2, 4) or d0 + size > end:
                    raise struct.error
                params.setdefault(gid, {})[name] = Param(name, ptype, dims,
                                                         bytes(data[d0:d0 + size]), processor)
            except struct.error:
                pass   # a damaged parameter: the ones that matter are checked by name later
        if offset <= 0 or nxt <= pos:
            break
        pos = nxt
    return {names.get(g, f"GROUP{g}"): ps for g, ps in params.items()}


def read_c3d(data: bytes, budget_bytes: int = 1 << 30) -> C3DFile:
    """Parse the bytes of a C3D file.

    ``budget_bytes`` bounds the arrays built (float64, as declared) before they are allocated.

    Raises
    ------
    C3DError
        The file is not C3D, is truncated, or declares more than the budget; the message says
        which part.
    """
    if len(data) < BLOCK or data[1] != 0x50:
        raise C3DError("not a C3D file (no 0x50 key in the second byte)")
    pstart = (data[0] - 1) * BLOCK if data[0] >= 1 else BLOCK
    if pstart + 4 > len(data):
        raise C3DError(f"the parameter section (block {data[0]}) lies past the end of the file")
    processor = data[pstart + 3]
    if processor not in PROCESSORS:
        raise C3DError(f"unknown processor type {processor} (expected 84 Intel, 85 DEC or "
                       "86 MIPS)")
    big = processor == 86
    u2 = ">H" if big else "<H"
    groups = _parse_parameters(data, pstart, processor)
    notes: list[str] = []

    def head_word(k: int) -> int:      # 1-based 16-bit word of the header
        return int(struct.unpack_from(u2, data, 2 * (k - 1))[0])

    def head_float(k: int) -> float:
        raw = data[2 * (k - 1):2 * (k - 1) + 4]
        if processor == 85:
            return float(_dec_floats(raw)[0])
        return float(struct.unpack(">f" if big else "<f", raw)[0])

    def p(key: str) -> Param | None:
        g, _, n = key.partition(":")
        return groups.get(g, {}).get(n)

    def num(key: str, default: float) -> float:
        q = p(key)
        return q.first(default) if q is not None and q.type != -1 else default

    def texts(key: str) -> list[str]:
        q = p(key)
        return q.strings() if q is not None else []

    def count(key: str) -> int | None:
        """A count parameter read unsigned (counts above 32767), None when absent."""
        q = p(key)
        if q is None or q.type == -1 or not q.numbers().size:
            return None
        return int(q.unsigned()[0])

    n_points = count("POINT:USED")
    if n_points is None:
        n_points = head_word(2)
    used = count("ANALOG:USED")
    if used is not None:
        n_analog = used
    else:   # no ANALOG:USED (Peak's FP1): the header's words per frame over the samples
        n_analog = head_word(3) // head_word(10) if head_word(10) else 0
        if n_analog:
            notes.append(f"no ANALOG:USED: {n_analog} channels from the header")
    scale = num("POINT:SCALE", head_float(7))
    point_rate = num("POINT:RATE", head_float(11))
    if not np.isfinite(point_rate) or point_rate <= 0:
        point_rate = head_float(11)
    analog_rate = num("ANALOG:RATE", 0.0)
    is_float = scale < 0
    word = 4 if is_float else 2
    first = head_word(4)
    data_block = count("POINT:DATA_START") or 0
    if data_block <= 0:
        data_block = head_word(9)
    start = (data_block - 1) * BLOCK
    if start <= pstart or start > len(data):
        start = (head_word(9) - 1) * BLOCK
    if start <= 0 or start > len(data):
        raise C3DError(f"the data section (block {data_block}) lies outside the file")
    # samples of each analog channel per frame: from the rates, else the header, checked
    # against the file's size (the C3D guide: the parameters describe the data)
    per_frame_options = []
    if analog_rate > 0 and point_rate > 0:
        per_frame_options.append(round(analog_rate / point_rate))
    per_frame_options.append(head_word(10))
    if n_analog:
        per_frame_options.append(head_word(3) // n_analog)
    declared_frames = head_word(5) - first + 1
    frames_p = p("POINT:FRAMES")
    if frames_p is not None and frames_p.type != -1 and frames_p.numbers().size:
        fp = int(frames_p.unsigned()[0]) if frames_p.type == 2 else int(frames_p.first())
        if fp > declared_frames:
            declared_frames = fp
    end_p = p("TRIAL:ACTUAL_END_FIELD")
    start_p = p("TRIAL:ACTUAL_START_FIELD")
    if end_p is not None and start_p is not None and end_p.type == 2 and start_p.type == 2:
        e, s = end_p.unsigned(), start_p.unsigned()
        if e.size >= 2 and s.size >= 2:
            n32 = int(e[0] + 65536 * e[1]) - int(s[0] + 65536 * s[1]) + 1
            if n32 > declared_frames:
                declared_frames = n32
    available = len(data) - start
    per_frame = 0
    frame_words = 4 * n_points
    for opt in per_frame_options:
        if opt < 0:
            continue
        fw = 4 * n_points + n_analog * opt
        if fw <= 0:
            continue
        if n_analog == 0 or opt > 0:
            if min(declared_frames, available // (fw * word)) > 0:
                per_frame, frame_words = opt, fw
                break
    if n_analog and per_frame == 0:
        notes.append("analog channels declared, but no sample rate fits the file: "
                     "analog data not read")
        n_analog = 0
        frame_words = 4 * n_points
    frame_bytes = frame_words * word
    if frame_bytes <= 0:
        n_frames = 0
    else:
        n_frames = max(0, min(declared_frames if declared_frames > 0 else 1 << 31,
                              available // frame_bytes))
        if 0 < declared_frames and available // frame_bytes < declared_frames:
            notes.append(f"the file holds {available // frame_bytes} of the "
                         f"{declared_frames} frames its header declares (truncated)")
    out_bytes = 8 * n_frames * (3 * n_points + n_analog * max(per_frame, 0))
    if out_bytes > budget_bytes:
        raise C3DError(f"declares {n_frames:,} frames of {n_points} points and {n_analog} "
                       f"analog channels: {out_bytes:,} bytes once read, over the "
                       f"{budget_bytes:,} bytes allowed")
    raw = data[start:start + n_frames * frame_bytes]
    if is_float:
        if processor == 85:
            words = _dec_floats(raw)
        else:
            words = np.frombuffer(raw, dtype=">f4" if big else "<f4")
    else:
        words = np.frombuffer(raw, dtype=">i2" if big else "<i2")
    block = words.reshape(n_frames, frame_words) if n_frames else np.zeros((0, frame_words))
    pts = block[:, :4 * n_points].reshape(n_frames, n_points, 4).astype(float)
    if is_float:
        resid = pts[:, :, 3]
        xyz = pts[:, :, :3]
    else:
        resid = pts[:, :, 3]
        xyz = pts[:, :, :3] * abs(scale)
    xyz = np.where((resid < 0)[:, :, None], np.nan, xyz)
    analog: np.ndarray = np.zeros((n_analog, 0))
    if n_analog and n_frames:
        a: np.ndarray = block[:, 4 * n_points:].reshape(n_frames * per_frame, n_analog
                                                        ).T.astype(float)
        fmt = " ".join(texts("ANALOG:FORMAT"))
        if not is_float and "UNSIGNED" in fmt.upper():
            a = np.where(a < 0, a + 65536.0, a)
        off = _per_channel(p("ANALOG:OFFSET"), n_analog, 0.0,
                           unsigned="UNSIGNED" in fmt.upper())
        sc = _per_channel(p("ANALOG:SCALE"), n_analog, 1.0)
        gen = num("ANALOG:GEN_SCALE", 1.0)
        analog = (a - off[:, None]) * (gen * sc)[:, None]
    if analog_rate <= 0 and per_frame > 0:
        analog_rate = point_rate * per_frame
    # labels beyond 255 continue in LABELS2, LABELS3 (ANALOG writes LABEL2 as often)
    labels = _names(texts("ANALOG:LABELS") + texts("ANALOG:LABELS2") + texts("ANALOG:LABEL2")
                    + texts("ANALOG:LABELS3"), n_analog, "A")
    plabels = _names(texts("POINT:LABELS") + texts("POINT:LABELS2") + texts("POINT:LABELS3"),
                     n_points, "P")
    units = texts("ANALOG:UNITS") + texts("ANALOG:UNITS2")
    punit = " ".join(texts("POINT:UNITS"))
    return C3DFile(PROCESSORS[processor], "float" if is_float else "integer", float(point_rate),
                   float(analog_rate), first, plabels, punit, xyz, labels,
                   (units + [""] * n_analog)[:n_analog], analog, groups, notes)


def _names(names: list[str], n: int, prefix: str) -> list[str]:
    names = names[:n] + [f"{prefix}{k + 1}" for k in range(len(names), n)]
    return [s or f"{prefix}{k + 1}" for k, s in enumerate(names)]


def _per_channel(q: Param | None, n: int, default: float, unsigned: bool = False
                 ) -> np.ndarray:
    if q is None or q.type == -1:
        return np.full(n, default)
    v = q.unsigned() if unsigned else q.numbers()
    if v.size == 0:
        return np.full(n, default)
    if v.size < n:
        v = np.concatenate([v, np.full(n - v.size, v[-1] if v.size else default)])
    return np.asarray(v[:n], dtype=float)


def describe_param(q: Param) -> Any:
    """A parameter's value for display: text, or numbers (one or a list)."""
    if q.type == -1:
        s = q.strings()
        return s[0] if len(s) == 1 else s
    v = q.numbers()
    return float(v[0]) if v.size == 1 else [float(x) for x in v[:32]]
