"""Every real recording in the shared folder through ingest and inspect.

Files no one here wrote (c3d.org's sample set — Intel, DEC and SGI processors, integer and
float storage, force plates of types 1–4, a KINARM exoskeleton, MotionMonitor, a damaged
parameter section — and pynwb's back-compatibility NWB files, 2.0b to 2.5). Each either gives
maps or is refused with every missing channel named and the option that maps one, never an
internal exception's text; ``fieldbank inspect`` reads every recording (exit 0). A file added to
the folder later is tested too: the list is read when the tests run.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from fieldbank.ingest.batch import detect_format, read_file
from fieldbank.ingest.inspect import inspect_file
from fieldbank.ingest.options import ReadOptions
from fieldbank.model import Arm
from fieldbank.params import ArmParams
from tests.realfiles import all_realfiles, need_realfiles
from tests.report_helpers import run_cli

RAW = ("c3d", "nwb", "kinarm")
#: What an internal error looks like in a message (a library's own words or a type name).
INTERNAL = re.compile(r"Traceback|AssertionError|AxisError|TypeError|KeyError|IndexError|"
                      r"ValueError|AttributeError|RuntimeError|only 0-dimensional|"
                      r"inconsistent analog count|\\x00|\x00|object has no attribute")
OPTIONS = ("--column", "--unit", "--trial-events", "--shoulder", "--sign", "--limit")


def _files() -> list[Path]:
    return all_realfiles() or [Path("(no real files)")]


@pytest.fixture(scope="module")
def arm() -> Arm:
    return Arm.from_params(ArmParams.from_anthropometry(75.0, 1.75))


def test_the_folder_holds_recordings() -> None:
    base = need_realfiles()
    kinds = {detect_format(p.read_bytes()) for p in base.rglob("*") if p.is_file()}
    assert {"c3d", "nwb"} <= kinds


@pytest.mark.parametrize("path", _files(), ids=lambda p: p.name)
def test_each_file_gives_maps_or_a_refusal_in_words(path: Path, arm: Arm) -> None:
    need_realfiles()
    data = path.read_bytes()
    fmt = detect_format(data)
    inc, problems = read_file(path.name, data, arm, "P01", options=ReadOptions())
    if inc is not None:
        assert inc.maps and not problems
        return
    text = "\n".join(str(p) for p in problems)
    assert problems and all(p.location.startswith(path.name) for p in problems)
    assert not INTERNAL.search(text), text
    if fmt in RAW:
        # what is missing, named, and how to map it
        assert any(o in text for o in OPTIONS), text
        assert "no " in text or "not " in text or "flat" in text, text


@pytest.mark.parametrize("path", _files(), ids=lambda p: p.name)
def test_inspect_reads_every_recording(path: Path) -> None:
    need_realfiles()
    data = path.read_bytes()
    ins = inspect_file(path)
    if detect_format(data) in RAW:
        assert ins.readable, ins.lines()
        assert ins.data.get("ingest"), ins.lines()
        assert not INTERNAL.search("\n".join(ins.lines()))
    else:
        assert ins.readable or ins.format is None


def test_inspect_on_the_command_line_exits_0_for_the_recordings() -> None:
    base = need_realfiles()
    recs = [p for p in base.rglob("*") if p.is_file()
            and detect_format(p.read_bytes()) in RAW]
    res = run_cli("inspect", "--json", *[str(p) for p in recs])
    assert res.exit_code == 0, res.output
    assert res.stdout.count('"readable": true') == len(recs)


def test_labels_are_shown_without_their_padding() -> None:
    base = need_realfiles()
    for p in base.rglob("*.[cC]3[dD]"):
        ins = inspect_file(p)
        labels = [a["label"] for a in ins.data["c3d"]["analog"]] + ins.data["c3d"]["markers"]
        assert all(lab == lab.strip() and "\0" not in lab for lab in labels), p.name


def test_a_marker_serves_as_the_hand_and_a_refusal_says_what_the_force_channel_lacks() -> None:
    base = need_realfiles()
    mm = next(base.rglob("sample24_*.c3d"), None)
    if mm is None:
        pytest.skip("the MotionMonitor sample is not in the folder")
    opts = ReadOptions.from_flags(columns=("x=M1:x", "y=M1:y", "fx=A1", "fy=A2"))
    _, problems = read_file(mm.name, mm.read_bytes(), None, options=opts)
    text = " ".join(p.reason for p in problems)
    # the marker was accepted as the position; the force channels are refused for their units
    assert "M1" not in text
    assert "'A1' (fx) has unit 'V'" in text and "'A2' (fy) has no unit" in text
    assert "--unit fy=UNIT" in text


def test_the_kinarm_exoskeleton_says_it_has_no_force_sensor() -> None:
    base = need_realfiles()
    kin = next(base.rglob("sample22_*.c3d"), None)
    if kin is None:
        pytest.skip("the KINARM sample is not in the folder")
    opts = ReadOptions.from_flags(columns=("x=Right_Hand:x", "y=Right_Hand:y"))
    _, problems = read_file(kin.name, kin.read_bytes(), None, options=opts)
    assert any("no hand force: this robot has no force sensor" in p.reason for p in problems)
    ins = inspect_file(kin)
    assert ins.readable and [e["label"] for e in ins.data["c3d"]["events"]] == \
        ["STAY_CENTRE", "TARGET_ON"]
