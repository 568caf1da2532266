"""Property tests: any valid map survives CSV (SI and lab units), HDF5 and MAT round trips."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from fieldbank.ingest import read_file, write_hdf5, write_mat5, write_mat73
from fieldbank.maps import FieldMap
from fieldbank.sampledata import lab_units_csv
from fieldbank.sanitize import csv_comment

#: Values up to 90% of the plausibility limits (fieldbank.ingest.limits), above which a valid
#: file is refused: forces in N, stiffness in N/m.
PLAUSIBLE = {"postural": 900.0, "stiffness": 90_000.0}


@st.composite
def field_maps(draw: st.DrawFn) -> FieldMap:
    kind = draw(st.sampled_from(["postural", "stiffness"]))
    n = draw(st.integers(1, 12))
    # distinct positions on a 1 mm lattice
    cells = draw(st.lists(st.tuples(st.integers(-300, 300), st.integers(100, 600)), min_size=n,
                          max_size=n, unique=True))
    pos = np.array(cells, dtype=float) * 1e-3
    shape = (n, 2) if kind == "postural" else (n, 2, 2)
    finite = st.floats(-PLAUSIBLE[kind], PLAUSIBLE[kind], allow_nan=False,
                       allow_infinity=False)
    vals = np.array(draw(st.lists(finite, min_size=int(np.prod(shape)),
                                  max_size=int(np.prod(shape))))).reshape(shape)
    with_sd = draw(st.booleans())
    sd = np.abs(vals) * 0.05 + 0.01 if with_sd else None
    moving = kind == "stiffness" and draw(st.booleans())
    vel = (draw(st.floats(-0.5, 0.5)), draw(st.floats(0.01, 0.5))) if moving else (0.0, 0.0)
    return FieldMap(kind=kind, positions_m=pos, values=vals, sd=sd,
                    sign=draw(st.sampled_from(["arm-on-handle", "handle-on-arm"])),
                    velocity_m_per_s=vel, source=draw(st.text(
                        st.characters(blacklist_categories=("Cc", "Cs", "Zl", "Zp")),
                        max_size=30)).strip(),
                    metadata={"operator": "K7"})


def _check(m: FieldMap, data: bytes, name: str, rtol: float,
           source: str | None = None) -> None:
    inc, problems = read_file(name, data, None)
    assert problems == [], problems
    got = inc.maps[0]
    assert (got.kind, got.sign, got.frame) == (m.kind, m.sign, m.frame)
    np.testing.assert_allclose(got.positions_m, m.positions_m, rtol=rtol, atol=1e-12)
    np.testing.assert_allclose(got.values, m.values, rtol=rtol, atol=1e-9)
    np.testing.assert_allclose(got.velocity_m_per_s, m.velocity_m_per_s, rtol=1e-9, atol=1e-12)
    assert (got.sd is None) == (m.sd is None)
    assert got.source == (m.source if source is None else source)


@given(field_maps())
def test_csv_round_trip(m: FieldMap) -> None:
    # the CSV writer neutralises text for spreadsheets (fieldbank.sanitize.csv_comment)
    _check(m, m.to_csv().encode(), "m.csv", 1e-9, csv_comment(m.source).strip())
    _check(m, lab_units_csv(m).encode(), "lab.csv", 1e-8)


@given(field_maps())
def test_binary_formats_round_trip(m: FieldMap) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        for name, writer in (("m.h5", lambda p: write_hdf5(p, [m])), ("v5.mat", None),
                             ("v73.mat", None)):
            p = Path(tmp) / name
            if name == "v5.mat":
                write_mat5(p, m)
            elif name == "v73.mat":
                write_mat73(p, m)
            else:
                writer(p)
            _check(m, p.read_bytes(), name, 1e-12)
