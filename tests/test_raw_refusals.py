"""Nothing wrong is stored from a raw recording, and every option is taken or refused in words.

Flat channels, a unit its values contradict, time running backwards, a map of one posture, an
sd of exactly 0 — each refused naming the channel; every missing channel listed at once; NWB
series found in processing/; a marker as the hand; events as trials only when named; MAT and
HDF5 files take --kind/--frame/--sign or refuse --column; a Latin-1 CSV read, an undecidable
one refused with "save it as UTF-8"; an NWB export of two sessions goes back into both.
"""

from __future__ import annotations

import io

import numpy as np
import pytest

from fieldbank.errors import Problem
from fieldbank.ingest.batch import read_file
from fieldbank.ingest.options import ReadOptions
from fieldbank.maps import FieldMap
from fieldbank.measure.recording import Recording


def _c3d(labels: list[str], units: list[str], data: np.ndarray, rate: float = 100.0,
         events: list[tuple[str, float]] = (),  # type: ignore[assignment]
         markers: np.ndarray | None = None) -> bytes:
    """A C3D file of analog channels (channels, n) at ``rate`` (one point, 'Hand', in mm)."""
    import c3d

    w = c3d.Writer(point_rate=rate, analog_rate=rate)
    frames = []
    for k in range(data.shape[1]):
        pts = np.zeros((1, 5), dtype=np.float32)
        if markers is not None:
            pts[0, :2] = markers[k]
        frames.append((pts, data[:, k:k + 1].astype(np.float32)))
    w.add_frames(frames)
    w.set_point_labels(["Hand"])
    w.set_analog_labels(labels)
    width = max(len(u) for u in units)
    w.analog_group.add_str("UNITS", "units", "".join(u.ljust(width) for u in units), width,
                           len(units))
    if events:
        ev = w.add_group(20, "EVENT", "events")
        ev.add_array("USED", "n", np.array([len(events)], dtype=np.int16))
        ev.add_array("TIMES", "t", np.array([[0.0, t] for _, t in events],
                                            dtype=np.float32).ravel().reshape(2, len(events)))
        lw = max(len(e) for e, _ in events)
        ev.add_str("LABELS", "l", "".join(e.ljust(lw) for e, _ in events), lw, len(events))
    buf = io.BytesIO()
    w.write(buf)
    return buf.getvalue()


def _holds(n_post: int = 3, per: int = 150, rate: float = 100.0) -> np.ndarray:
    """x, y (m) of holds at n_post postures with 5 mm displacements; force = −K Δx + noise."""
    rng = np.random.default_rng(1)
    xs, fs = [], []
    for p in range(n_post):
        base = np.array([0.05 * p - 0.05, 0.40])
        for d in [(0, 0), (0.006, 0), (0, 0), (0, 0.006), (0, 0), (-0.006, 0), (0, 0),
                  (0, -0.006)]:
            x = np.tile(base + np.array(d), (per, 1))
            f = -np.array([[300.0, 0], [0, 150.0]]) @ np.array(d) + 2.0
            xs.append(x)
            fs.append(np.tile(f, (per, 1)) + rng.normal(0, 0.05, (per, 2)))
        xs.append(np.linspace(base, base + np.array([0.05, 0.0]), per))  # to the next posture
        fs.append(np.full((per, 2), 2.0) + rng.normal(0, 0.05, (per, 2)))
    return np.hstack([np.vstack(xs), np.vstack(fs)]).T           # (4, n)


def _reasons(probs: list[Problem]) -> str:
    return " | ".join(p.reason for p in probs)


def test_a_clean_c3d_gives_maps_and_a_flat_force_is_refused_naming_it() -> None:
    d = _holds()
    ok = _c3d(["HandX", "HandY", "ForceX", "ForceY"], ["m", "m", "N", "N"], d)
    inc, probs = read_file("ok.c3d", ok, None)
    assert inc is not None, probs
    assert {m.kind for m in inc.maps} == {"postural", "stiffness"}
    flat = d.copy()
    flat[2:] = 0.0                                   # an unloaded force plate
    _, probs = read_file("flat.c3d", _c3d(["HandX", "HandY", "FX2", "FY2"],
                                          ["m", "m", "N", "N"], flat), None,
                         options=ReadOptions.from_flags(columns=("fx=FX2", "fy=FY2")))
    text = _reasons(probs)
    assert "channel FX2 (N) (fx) is flat" in text and "channel FY2 (N) (fy) is flat" in text


def test_a_position_its_unit_contradicts_is_refused() -> None:
    d = _holds()
    d[:2] *= 9600.0                          # up to 960 "m": a centre of pressure in mm
    _, probs = read_file("cop.c3d", _c3d(["PX2", "PY2", "ForceX", "ForceY"],
                                         ["m", "m", "N", "N"], d), None,
                         options=ReadOptions.from_flags(columns=("x=PX2", "y=PY2")))
    text = _reasons(probs)
    assert "channel PX2 (m) (x) reads up to 960" in text and "cannot be right" in text


def test_every_missing_channel_is_listed_at_once() -> None:
    d = _holds()
    _, probs = read_file("lab.c3d", _c3d(["A", "B", "C", "D"], ["m", "m", "N", "N"], d), None)
    text = _reasons(probs)
    for role in ("hand position x", "hand position y", "hand force x", "hand force y"):
        assert f"no channel for the {role}" in text
    assert "the file has analog channels: A (m), B (m), C (N), D (N)" in text


def test_a_marker_is_the_hand_and_foreign_events_are_ignored_unless_named() -> None:
    d = _holds()
    markers = d[:2].T * 1000.0                    # the hand as a marker, mm
    data = _c3d(["Fx", "Fy"], ["N", "N"], d[2:], events=[("LHS", 1.0), ("RTO", 2.0)],
                markers=markers)
    opts = ReadOptions.from_flags(columns=("x=Hand:x", "y=Hand:y", "fx=Fx", "fy=Fy"))
    inc, probs = read_file("gait.c3d", data, None, options=opts)
    assert inc is not None, probs
    m = inc.maps[0]
    assert "Hand:x (mm)" in m.metadata["channels"]
    assert "LHS ×1, RTO ×1" in m.metadata["events_ignored"]
    named = ReadOptions.from_flags(columns=("x=Hand:x", "y=Hand:y", "fx=Fx", "fy=Fy"),
                                   trial_events=("NOPE",))
    _, probs = read_file("gait.c3d", data, None, options=named)
    assert "no event named NOPE (the file's events: LHS, RTO)" in _reasons(probs)


def test_a_map_of_one_posture_and_an_sd_of_zero_are_refused() -> None:
    from fieldbank.ingest.rawfmt import _unfit

    rec = Recording(np.arange(3.0), np.zeros((3, 2)), np.zeros((3, 2)), np.zeros((3, 2)), (),
                    {"fx": "FX2 (N)", "fy": "FY2 (N)"})
    one = FieldMap("postural", np.array([[0.0, 0.4]]), np.array([[1.0, 1.0]]),
                   np.array([[0.1, 0.1]]))
    two = FieldMap("postural", np.array([[0.0, 0.4], [0.05, 0.4]]),
                   np.array([[1.0, 1.0], [1.0, 1.0]]), np.zeros((2, 2)))
    text = _reasons(_unfit("f.c3d", (one, two), rec))
    assert "1 posture(s), fewer than the 2" in text
    assert "standard deviation of exactly 0 at 2 posture(s)" in text and "FX2 (N)" in text


def _nwb(path_kind: str, backwards: bool = False) -> bytes:
    import tempfile
    from datetime import UTC, datetime

    from pynwb import NWBHDF5IO, NWBFile, TimeSeries
    from pynwb.behavior import Position

    d = _holds()
    n = d.shape[1]
    t = np.arange(n) / 100.0
    if backwards:
        t[500] = t[498]
    nwb = NWBFile(session_description="lab", identifier="x", session_start_time=datetime.now(UTC))
    mod = nwb.create_processing_module("behavior", "processed")
    pos = Position(name="Position")
    pos.create_spatial_series(name="hand", data=d[:2].T, timestamps=t, reference_frame="lab",
                              unit="meters")
    mod.add(pos)
    nwb.add_acquisition(TimeSeries(name="loadcell", data=d[2:].T, timestamps=t, unit="N"))
    with tempfile.NamedTemporaryFile(suffix=".nwb") as f:
        with NWBHDF5IO(f.name, "w") as io_:
            io_.write(nwb)
        return open(f.name, "rb").read()


def test_nwb_series_in_processing_are_found_by_path_and_backward_time_is_refused() -> None:
    data = _nwb("processing")
    _, probs = read_file("lab.nwb", data, None)
    text = _reasons(probs)
    assert "processing/behavior/Position/hand" in text and "--column position=PATH" in text
    opts = ReadOptions.from_flags(columns=("position=processing/behavior/Position/hand",
                                           "force=loadcell"))
    inc, probs = read_file("lab.nwb", data, None, options=opts)
    assert inc is not None, probs
    _, probs = read_file("back.nwb", _nwb("processing", backwards=True), None, options=opts)
    assert "time runs backwards or stands still at sample 500" in _reasons(probs)


def test_mat_and_hdf5_take_the_metadata_flags_or_refuse_them(tmp_path: object) -> None:
    from fieldbank.ingest.hdf5fmt import write_hdf5
    from fieldbank.ingest.matfmt import write_mat5

    m = FieldMap("postural", np.array([[0.0, 0.4], [0.05, 0.4]]),
                 np.array([[1.0, 1.0], [1.0, 2.0]]), None)
    p = tmp_path / "m.mat"  # type: ignore[operator]
    write_mat5(p, m)
    raw = p.read_bytes()
    _, probs = read_file("m.mat", raw, None, options=ReadOptions.from_flags(kind="stiffness"))
    assert "the file says kind: 'postural', the command line says 'stiffness'" in \
        _reasons(probs)
    _, probs = read_file("m.mat", raw, None,
                         options=ReadOptions.from_flags(columns=("positions=nope",)))
    assert "the file has no variable 'nope'" in _reasons(probs)
    h = tmp_path / "m.h5"  # type: ignore[operator]
    write_hdf5(h, [m])
    _, probs = read_file("m.h5", h.read_bytes(), None,
                         options=ReadOptions.from_flags(columns=("x_mm=X",)))
    assert "--column does not apply" in _reasons(probs)
    _, probs = read_file("m.h5", h.read_bytes(), None,
                         options=ReadOptions.from_flags(shoulder_m=(0.0, 0.0)))
    assert "--shoulder apply to raw recordings" in _reasons(probs)


CSV = "x_m,y_m,fx_n,fy_n\n0.0,0.4,1,1\n0.05,0.4,1,2\n"


def test_csv_encodings_are_detected_or_refused_with_save_it_as_utf8() -> None:
    meta = ("# kind: postural\n# frame: shoulder\n# sign: arm-on-handle\n"
            "# operator: José Müller, Universität Zürich, Département de réadaptation\n")
    inc, probs = read_file("u16.csv", (meta + CSV).encode("utf-16"), None)
    assert inc is not None, probs
    assert inc.maps[0].metadata["operator"].startswith("José Müller")
    assert "UTF-16" in inc.maps[0].metadata["text_encoding"]
    # a short Windows-1252 file: code pages read its accents differently; said, not guessed
    inc, probs = read_file("lat.csv", (meta + CSV).encode("cp1252"), None)
    if inc is None:
        text = _reasons(probs)
        assert "not UTF-8 text (byte " in text and "save it as UTF-8" in text
        assert "cannot be told apart" in text and "reads 'Jos" in text
    else:   # a detector that tells it apart must have read it right
        assert "José Müller" in inc.maps[0].metadata["operator"]
    _, probs = read_file("junk.csv", (meta + CSV).encode() + bytes(range(128, 256)) * 4, None)
    assert "save it as UTF-8" in _reasons(probs)


@pytest.mark.parametrize("n", [2])
def test_an_nwb_export_of_two_sessions_goes_back_into_both(n: int, tmp_path: object) -> None:
    from fieldbank.ingest import ingest_paths
    from fieldbank.nwbexport import patient_nwb
    from fieldbank.storage import Database

    url = f"sqlite:///{tmp_path / 'a.sqlite3'}"  # type: ignore[operator]
    src = tmp_path / "m.csv"  # type: ignore[operator]
    head = "# kind: postural\n# frame: shoulder\n# sign: arm-on-handle\n"
    with Database.open(url) as db:
        db.add_patient("P1", 75, 1.75, "right")
        for k, label in enumerate(("pre", "post")):
            src.write_text(head + f"# source: lab {k}\n" + CSV)
            ingest_paths(db, [src], "P1", label)
        data = patient_nwb(db, "P1")
    url2 = f"sqlite:///{tmp_path / 'b.sqlite3'}"  # type: ignore[operator]
    out = tmp_path / "p1.nwb"  # type: ignore[operator]
    out.write_bytes(data)
    with Database.open(url2) as db:
        db.add_patient("P1", 75, 1.75, "right")
        ingest_paths(db, [out], "P1", "imported")
        assert sorted(r.session_label for r in db.list_maps("P1")) == ["post", "pre"]
        assert len({r.session_label for r in db.list_maps("P1")}) == n


def test_c3d_labels_lose_their_nul_and_space_padding() -> None:
    from fieldbank.measure.c3dfile import clean_label

    assert clean_label(b"F1x12\x00\x00\x00") == "F1x12"
    assert clean_label(b"  FX1   ") == "FX1"
    assert clean_label(b"Fz\x00junk") == "Fz"
