"""Measuring through the robot port (haptic/measure.py, haptic/robots.py): a robot adapter
registered for its own URL scheme (entry point group ``fieldbank.robots``, a distribution on the
path) is opened by ``open_robot`` and measured on through its port alone; the worked adapter of
docs/robot-adapters.md, which has no force sensor, is refused in words.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np
import pytest

from fieldbank.haptic.errors import HapticError
from fieldbank.haptic.measure import run_protocol
from fieldbank.haptic.patient import resolve_patient
from fieldbank.measure.protocol import ProtocolConfig, plan
from fieldbank.model import Arm

DOC = Path(__file__).resolve().parents[1] / "docs" / "robot-adapters.md"

#: A vendor's robot with a force sensor, as its adapter would present it: here the simulated
#: robot stands behind it, reached through the port's members only (no ``__getattr__``: a call
#: to anything else fails), and every call is written down.
RAIL = '''
from fieldbank.haptic.robots import open_robot

OPENED = []


class RailPort:
    def __init__(self, inner):
        self.inner = inner
        self.state = inner.state
        self.device = inner.device
        self.calls = []

    def poll(self):
        return self.inner.poll()

    def wait_state(self, timeout_s, spin_s=0.0):
        return self.inner.wait_state(timeout_s, spin_s)

    def send_force(self, fx_n, fy_n):
        self.calls.append("force")
        return self.inner.send_force(fx_n, fy_n)

    def heartbeat(self):
        self.calls.append("heartbeat")
        self.inner.heartbeat()

    def sensor_on(self):
        self.calls.append("sensor_on")
        self.inner.sensor_on()

    def arm(self):
        self.calls.append("arm")
        self.inner.arm()

    def disarm(self):
        self.calls.append("disarm")
        self.inner.disarm()

    def counters(self):
        return self.inner.counters()

    def close(self):
        self.calls.append("close")
        self.inner.close()


def open_rail(url, *, rate_hz, watchdog_ms):
    query = url.split("?", 1)[1] if "?" in url else ""
    port = RailPort(open_robot("sim://?" + query, rate_hz, watchdog_ms))
    OPENED.append(port)
    return port
'''


def _install(root: Path, name: str, module: str, source: str, entry: str,
             monkeypatch: pytest.MonkeyPatch) -> None:
    """A distribution ``name`` with ``module`` and its entry point in ``fieldbank.robots``,
    on the import path for this test only."""
    (root / f"{module}.py").write_text(source, encoding="utf-8")
    info = root / f"{name.replace('-', '_')}-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 0.1\n",
                                   encoding="utf-8")
    (info / "entry_points.txt").write_text(f"[fieldbank.robots]\n{entry}\n", encoding="utf-8")
    monkeypatch.syspath_prepend(str(root))
    monkeypatch.delitem(sys.modules, module, raising=False)


def _plan():
    arm = Arm.from_params(resolve_patient("elbow=moderate").params)
    return plan(ProtocolConfig(parts=("postural",), grid=(2, 1), centre_m=(0.0, 0.50),
                               spacing_m=0.04), arm)


def test_measuring_runs_on_an_adapter_s_robot_through_its_port(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    _install(tmp_path, "fieldbank-rail", "rail_adapter", RAIL, "rail = rail_adapter:open_rail",
             monkeypatch)
    pl = _plan()
    rec, commanded = run_protocol("rail://?patient=elbow=moderate&seed=3", pl)
    import rail_adapter  # the adapter fieldbank loaded through the entry point

    (port,) = rail_adapter.OPENED
    # the port alone: the heartbeat first, then the force sensor, armed once, forces every
    # tick; at the end zero force, disarmed, closed
    assert port.calls[:2] == ["heartbeat", "sensor_on"] and port.calls.count("arm") == 1
    assert port.calls.count("force") >= len(rec.t_s)
    assert port.calls[-3:] == ["force", "disarm", "close"]
    # a recording of the plan: both postures held, the hand's force read by the sensor
    assert len(rec.trials) == len(pl.postures_m) == 2
    assert len(commanded) == len(rec.t_s) > 100
    assert np.all(np.isfinite(rec.force_n)) and np.abs(rec.force_n).max() > 0.1
    # each hold where the plan put it (shoulder frame): the hand within 5 mm, mid-hold
    for trial in rec.trials:
        mid = np.searchsorted(rec.t_s, 0.5 * (trial.window_s[0] + trial.window_s[1]))
        target = pl.postures_m[trial.posture]
        assert np.hypot(rec.position_m[mid, 0] - target[0],
                        rec.position_m[mid, 1] - target[1]) < 0.005


def test_measuring_on_the_worked_adapter_without_a_force_sensor_is_refused_in_words(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    text = DOC.read_text(encoding="utf-8")
    files = dict(re.findall(r"<!-- file: (\S+) -->\n```\w*\n(.*?)```", text, flags=re.S))
    entry = re.search(r"^desk\s*=\s*\"?([\w.:]+)\"?", files["pyproject.toml"], flags=re.M)
    assert entry is not None
    _install(tmp_path, "fieldbank-desk", "fieldbank_desk", files["fieldbank_desk.py"],
             f"desk = {entry.group(1)}", monkeypatch)
    with pytest.raises(HapticError, match=r"desk://.*cannot report the force of the hand on "
                                          r"its handle.*measuring needs one"):
        run_protocol("desk://?x0=0.0&y0=0.5", _plan())
