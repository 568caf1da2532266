"""Protocols that see what they must: per muscle group, before the robot moves, whether the
planned postures reach its slack length and the planned passes its reflex threshold."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from fieldbank import storage
from fieldbank.measure.protocol import ProtocolConfig, plan
from fieldbank.measure.visibility import ProtocolBlind, check_must_see, pass_points, sight
from fieldbank.model import Arm
from fieldbank.params import GROUPS, ArmParams
from tests.report_helpers import run_cli


@pytest.mark.parametrize("seed", range(4))
def test_the_default_protocol_sees_all_six_groups_on_bodies_of_their_own(seed: int) -> None:
    """The default grid follows the arm: bodies the tuning did not use (drawn here: 50-100 kg,
    1.50-1.95 m, either side) are seen in every group, passive and reflex."""
    rng = np.random.default_rng([4242, seed])
    base = ArmParams.from_anthropometry(float(rng.uniform(50, 100)), float(rng.uniform(1.5, 1.95)),
                                        "left" if seed % 2 else "right")
    arm = Arm.from_params(base)
    s = sight(plan(ProtocolConfig(), arm), arm)
    assert s.sees_all, "\n".join(s.table())
    assert len(s.table()) == 2 + len(GROUPS)


def test_a_grid_nearer_the_body_misses_the_elbow_flexors_and_a_change_is_suggested() -> None:
    arm = Arm.from_params(ArmParams.from_anthropometry())
    c = ProtocolConfig().resolved(arm)
    near = dataclasses.replace(c, centre_m=(c.centre[0], c.centre[1] - 0.06))
    p = plan(near, arm)
    s = sight(p, arm)
    assert not s.of("ef").reflex_seen and not s.of("ef").passive_seen
    with pytest.raises(ProtocolBlind) as err:
        check_must_see(p, arm, ("ef", "bf"))
    text = str(err.value)
    assert "ef (elbow flexors)" in text and "stretch reflex" in text
    # the suggestion is a protocol that does see them
    suggested = text.split("try --centre ")[1].split(",")
    centre = (float(suggested[0]), float(suggested[1].split()[0]))
    fixed = plan(dataclasses.replace(near, centre_m=centre), arm)
    assert not sight(fixed, arm).unseen(("ef", "bf"))
    # a group it does see is not refused
    check_must_see(p, arm, ("ee", "be"))


def test_the_passes_are_read_where_the_estimator_reads_them() -> None:
    arm = Arm.from_params(ArmParams.from_anthropometry())
    p = plan(ProtocolConfig(grid=(3, 3)), arm)
    pos, vel = pass_points(p)
    # every posture is crossed by a stroke each way; offsets beside the column add nothing
    assert len(pos) == 2 * 9
    assert np.allclose(np.abs(vel[:, 1]), p.config.stretch_speed_m_per_s)
    assert np.allclose(vel[:, 0], 0.0)


def test_a_grid_missing_a_named_groups_reflex_is_refused_before_the_robot_moves(
        tmp_path: Path) -> None:
    """``haptic measure --must-see ef,bf`` on a grid 6 cm nearer the body: refused with the
    visibility table and a suggestion, before the robot link is opened (its URL points at a
    port nobody serves: opening it would fail with another message), nothing written or
    stored."""
    url = f"sqlite:///{tmp_path / 'fb.sqlite3'}"
    storage.Database.open(url).add_patient("VIS", 75.0, 1.75, "right")
    arm = Arm.from_params(ArmParams.from_anthropometry(75.0, 1.75, "right"))
    c = ProtocolConfig().resolved(arm)
    raw = tmp_path / "vis.nwb"
    res = run_cli("haptic", "measure", "--db", url, "--robot", "socket://127.0.0.1:9",
                  "--patient", "VIS", "--session", "near", "--grid", "5x5",
                  "--centre", f"{c.centre[0]:g},{c.centre[1] - 0.06:g}",
                  "--must-see", "ef,bf", "--raw", str(raw))
    assert res.exit_code == 1
    err = " ".join(res.stderr.split())
    assert "what the protocol sees" in err and "NOT SEEN" in err
    assert "would not see ef (elbow flexors)" in err and "try --centre" in err
    assert "Nothing was measured" in err
    assert "127.0.0.1" not in err and "onnect" not in err  # the link was never opened
    assert not raw.exists()
    with storage.Database.open(url) as db:
        assert db.list_maps("VIS") == []
    # an unknown group is refused in the user's words
    bad = run_cli("haptic", "measure", "--db", url, "--robot", "socket://127.0.0.1:9",
                  "--patient", "VIS", "--session", "x", "--must-see", "ef,elbow")
    assert bad.exit_code != 0 and "unknown muscle group(s) elbow" in bad.stderr


def test_cli_json_of_a_default_measurement_carries_the_table(tmp_path: Path) -> None:
    """A measured session says what its protocol saw (a short protocol on the simulated robot:
    postural holds and passes only)."""
    url = f"sqlite:///{tmp_path / 'fb.sqlite3'}"
    storage.Database.open(url).add_patient("SEE", 75.0, 1.75, "right")
    res = run_cli("haptic", "measure", "--db", url, "--robot", "sim://?patient=elbow=severe",
                  "--patient", "SEE", "--session", "pre", "--grid", "2x2", "--protocol",
                  "postural", "--raw", str(tmp_path / "see.nwb"), "--json")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    vis = doc["visibility"]
    assert [g["group"] for g in vis["groups"]] == list(GROUPS)
    assert vis["criteria"]["reflex_level"] == "mild"
    # without passes no reflex can be seen, and the table says so
    assert not any(g["reflex_seen"] for g in vis["groups"])
    assert "what the protocol sees" in res.stderr
