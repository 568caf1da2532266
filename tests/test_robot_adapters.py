"""Robot adapters (haptic/robots.py, docs/robot-adapters.md): the worked adapter of the document,
built into a distribution with its own entry point, installed with pip into a fresh environment,
and a session rendered through it with ``fieldbank haptic serve``; and the refusals of
:func:`open_robot` in words.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import sysconfig
import venv
from pathlib import Path

import numpy as np
import pytest

from fieldbank.evaluate.severity import synthesize
from fieldbank.haptic.errors import HapticError
from fieldbank.haptic.port import HandleState, RobotPort
from fieldbank.haptic.protocol import FaultCode
from fieldbank.haptic.recording import read_trace_h5
from fieldbank.haptic.robots import BUILT_IN, _refusal, open_robot, scheme_of
from fieldbank.model import Arm

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "robot-adapters.md"


def doc_files() -> dict[str, str]:
    """The files of the worked adapter, as the document gives them (``<!-- file: NAME -->``
    before a fenced block)."""
    text = DOC.read_text(encoding="utf-8")
    found = re.findall(r"<!-- file: (\S+) -->\n```\w*\n(.*?)```", text, flags=re.S)
    return dict(found)


@pytest.fixture(scope="module")
def adapter_env(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fresh environment in which the worked adapter is installed by pip as a distribution
    of its own; fieldbank and its dependencies come from the test's environment."""
    base = tmp_path_factory.mktemp("adapter")
    pkg = base / "fieldbank-desk"
    pkg.mkdir()
    files = doc_files()
    assert set(files) == {"pyproject.toml", "fieldbank_desk.py"}
    for name, text in files.items():
        (pkg / name).write_text(text, encoding="utf-8")
    env_dir = base / "venv"
    venv.create(env_dir, with_pip=False)
    py = env_dir / "bin" / "python"
    site = subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_path("
                           "'purelib'))"], check=True, capture_output=True, text=True)
    # the test environment's packages (fieldbank among them, with its own import hook)
    (Path(site.stdout.strip()) / "testenv.pth").write_text(
        f"import site; site.addsitedir({sysconfig.get_path('purelib')!r})\n", encoding="utf-8")
    r = subprocess.run([sys.executable, "-m", "pip", "--python", str(py), "install", "-q",
                        "--no-deps", "--no-index", "--no-build-isolation", str(pkg)],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    return env_dir


def _py(env_dir: Path, code: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(env_dir / "bin" / "python"), "-c", code], cwd=cwd, text=True,
                          capture_output=True, timeout=600,
                          env={"PATH": f"{env_dir / 'bin'}:/usr/bin:/bin",
                               "FIELDBANK_HOME": str(cwd / "home")})


def test_the_installed_adapter_is_a_distribution_found_by_its_scheme(adapter_env: Path,
                                                                     tmp_path: Path) -> None:
    r = _py(adapter_env, (
        "import json\n"
        "from importlib.metadata import distribution\n"
        "from fieldbank.haptic.robots import adapters, open_robot\n"
        "from fieldbank.haptic.port import RobotPort\n"
        "(ep,) = adapters()['desk']\n"
        "port = open_robot('desk://?x0=0.1&y0=0.45', 1000, 20)\n"
        "d = distribution('fieldbank-desk')\n"
        "print(json.dumps({'dist': ep.dist.name, 'version': d.version,\n"
        "  'module': type(port).__module__, 'file': __import__('fieldbank_desk').__file__,\n"
        "  'port': isinstance(port, RobotPort), 'device': port.device.device_id}))\n"), tmp_path)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["dist"] == "fieldbank-desk" and out["version"] == "1.0.0"
    assert out["module"] == "fieldbank_desk" and out["port"] is True
    assert out["device"] == "desk-1"
    # installed into the fresh environment, not imported from the source tree
    assert str(adapter_env) in out["file"]
    # the test's own environment has no such adapter
    with pytest.raises(HapticError, match=r"no robot adapter for desk:// is installed"):
        open_robot("desk://?x0=0.1", 1000, 20)


def test_a_session_renders_through_the_installed_adapter(adapter_env: Path,
                                                         tmp_path: Path) -> None:
    """``fieldbank haptic serve`` on desk://: the models' forces go out through the adapter,
    the robot's emergency stop is judged by the loop's monitor (DEVICE fault, zero force from
    that tick), and the trace records the desk robot."""
    x0, y0 = (float(v) for v in Arm.from_params(synthesize({"elbow": "severe"})).rest_position())
    url = f"desk://?x0={x0:.4f}&y0={y0:.4f}&estop_at_s=1.5"
    r = subprocess.run(
        [str(adapter_env / "bin" / "python"), "-m", "fieldbank.cli", "haptic", "serve",
         "--robot", url, "--before-severity", "elbow=severe", "--after-severity", "elbow=mild",
         "--duration-s", "2.5", "--no-db", "--trace-dir", str(tmp_path / "traces"),
         "--socket", str(tmp_path / "h.sock"), "--json"],
        cwd=tmp_path, text=True, capture_output=True, timeout=600,
        env={"PATH": f"{adapter_env / 'bin'}:/usr/bin:/bin", "FIELDBANK_HOME": str(tmp_path)})
    assert r.returncode == 0, r.stderr[-3000:]
    out = json.loads(r.stdout)
    assert out["robot"] == url
    trace = read_trace_h5(out["trace"])
    assert trace.metadata["device"]["device_id"] == "desk-1"
    # one force a tick and the zero at the end; a state for every tick (the first state came
    # before it, the last force's answer after the end)
    assert trace.stats["link"] == {"forces": len(trace) + 1, "states": len(trace)}
    assert len(trace) == 2500
    fx, fy = trace.column("fx_n"), trace.column("fy_n")
    f = np.hypot(fx, fy)
    t = trace.t_s
    # the hand moves the handle on its circle and the arm pushes back while armed
    x = trace.column("x_m")
    assert x.max() - x.min() > 0.03
    before = (t > 0.5) & (t < 1.4)
    assert f[before].max() > 1.0 and np.all(np.isfinite(f))
    # the emergency stop: one DEVICE fault at 1.5 s, nothing commanded from that tick on
    (fault,) = [d for d in trace.faults if d["code"] == FaultCode.DEVICE]
    assert 1.5 <= fault["t_s"] <= 1.51
    after = t >= fault["t_s"]
    assert after.sum() > 900 and np.all(fx[after] == 0.0) and np.all(fy[after] == 0.0)


def test_open_robot_says_why_it_refuses() -> None:
    assert scheme_of("/dev/ttyUSB0") is None and scheme_of("Desk://x") == "desk"
    assert scheme_of("sim://?x0_m=0.1") in BUILT_IN
    with pytest.raises(HapticError) as info:
        open_robot("acme://user:hunter2@robot.local/arm", 1000, 20)
    msg = str(info.value)
    assert "no robot adapter for acme://" in msg and "sim://" in msg and "hunter2" not in msg

    class Half:
        state = HandleState()
        device = None

        def poll(self) -> int:
            return 0

    assert "missing: wait_state, send_force, heartbeat, arm, disarm, counters, close" in str(
        _refusal(Half(), 1000))

    class NoDevice(Half):
        def wait_state(self, timeout_s: float, spin_s: float = 0.0) -> int:
            return 0

        def send_force(self, fx_n: float, fy_n: float) -> None: ...
        def heartbeat(self) -> None: ...
        def arm(self) -> None: ...
        def disarm(self) -> None: ...

        def counters(self) -> dict[str, int]:
            return {}

        def close(self) -> None: ...

    assert isinstance(NoDevice(), RobotPort)
    assert "did not say what it is" in str(_refusal(NoDevice(), 1000))


def test_the_remote_patient_s_site_and_the_workspace_take_the_adapter_s_robot(
        adapter_env: Path, tmp_path: Path) -> None:
    """The patient's site of a remote assessment opens its robot through the robot port too:
    the desk robot opens, and is refused in words because it reports no force of the hand
    (its port has no ``sensor_on``) - before anything listens. The workspace takes desk:// as
    its robot and refuses a scheme no adapter serves when it starts."""
    env = {"PATH": f"{adapter_env / 'bin'}:/usr/bin:/bin", "FIELDBANK_HOME": str(tmp_path)}
    cli = [str(adapter_env / "bin" / "python"), "-m", "fieldbank.cli", "haptic", "remote"]
    key = tmp_path / "session.key"
    r = subprocess.run([*cli, "key", "--out", str(key)], cwd=tmp_path, text=True,
                       capture_output=True, timeout=600, env=env)
    assert r.returncode == 0, r.stderr
    r = subprocess.run([*cli, "patient", "--robot", "desk://?x0=0.1&y0=0.45", "--key", str(key),
                        "--shoulder", "0,0", "--bind", "127.0.0.1:0", "--wait-s", "1"],
                       cwd=tmp_path, text=True, capture_output=True, timeout=600, env=env)
    assert r.returncode == 1
    assert ("the robot at desk://?x0=0.1&y0=0.45 cannot report the force of the hand on its "
            "handle (its port has no force sensor); the patient's site needs one") in r.stderr
    assert "listening" not in r.stdout + r.stderr
    r = _py(adapter_env, (
        "from fieldbank.haptic.errors import HapticError\n"
        "from fieldbank.haptic.workspace.host import RobotSettings\n"
        "s = RobotSettings('desk://?x0=0.1', 'sqlite://', 'traces')\n"
        "print('desk', s.simulated)\n"
        "try:\n"
        "    RobotSettings('acme://arm', 'sqlite://', 'traces')\n"
        "except HapticError as exc:\n"
        "    print(exc)\n"), tmp_path)
    assert r.returncode == 0, r.stderr
    first, second = r.stdout.splitlines()
    assert first == "desk False"
    assert second.startswith("no robot adapter for acme:// is installed")
    assert "adapters installed: desk://" in second
