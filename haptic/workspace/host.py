"""The workspace's renderer: today's session machinery behind the workspace's robot seam.

:class:`RendererHost` implements :class:`fieldbank.web.robot.RobotSeam`. "Feel it" on the
page calls :meth:`RendererHost.feel`: when no renderer runs for that patient it starts one - a
``fieldbank.haptic.session.serve`` in a process of its own (:mod:`haptic.workspace.__main__`),
on the configured robot or, where none is configured, the simulated robot in real time - and
renders the pair from its first tick; a renderer already running for the patient gets the pair
pushed through its control socket, as ``fieldbank haptic push`` does (a renderer held by a
fault refuses it until the robot is re-armed, in the robot view).
The renderer publishes its loop snapshot into the host's private directory, where the robot
view (:mod:`haptic.workspace.view`) reads it. One renderer at a time: a pair for another
patient ends the running session (its trace is written and recorded) and starts the next.

The renderer's process records its session in the field database as the account that asked
for it; it ends when :meth:`RendererHost.stop` asks it to, or when the workspace's process
ends (its standard input closes).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fieldbank.haptic.client import ControlClient, push_models
from fieldbank.haptic.errors import ControlError, HapticError
from fieldbank.haptic.modelinfo import ModelInfo
from fieldbank.haptic.rendererconfig import RENDERER_BOUNDS
from fieldbank.haptic.robots import adapter_for, scheme_of
from fieldbank.haptic.safety import SAFETY_BOUNDS
from fieldbank.redact import mask_url
from fieldbank.validation import check_fields
from fieldbank.web.robot import FeelPair

#: The robot when none is configured: the simulated one, in real time.
SIMULATED = "sim://?mode=realtime"
#: Longest wait for a new renderer to answer on its control socket, s (the loop's kernel
#: compiles on first use; a busy machine is slow).
START_TIMEOUT_S = 120.0
#: Longest wait for a stopped renderer to write its trace and end, s.
STOP_TIMEOUT_S = 60.0
#: The ranges of :class:`RobotSettings`: the loop's and the safety layer's own.
ROBOT_SETTINGS_BOUNDS = {"rate_hz": RENDERER_BOUNDS["rate_hz"],
                         "force_limit_n": SAFETY_BOUNDS["force_limit_n"]}


@dataclass(frozen=True)
class RobotSettings:
    """How the workspace renders: the robot (None: the simulated one), the loop's rate, the
    force limit, the database the sessions are recorded in, where traces go.

    The robot is any the robot port opens (:func:`haptic.robots.open_robot`: a device path,
    a built-in scheme, or an installed adapter's): one no adapter serves is refused here, when
    the workspace starts, not at the first 'Feel it'."""

    robot: str | None
    db_url: str
    trace_dir: str
    rate_hz: int = 1000
    force_limit_n: float = 40.0

    def __post_init__(self) -> None:
        check_fields(self, ROBOT_SETTINGS_BOUNDS, what="workspace robot setting")
        if self.robot is not None:
            adapter_for(self.robot)

    @property
    def simulated(self) -> bool:
        return self.robot is None or scheme_of(self.robot) == "sim"


class _Running:
    """One renderer process and what it renders for."""

    def __init__(self, proc: subprocess.Popen[bytes], patient: str | None, actor: str,
                 socket_path: Path, snapshot_path: Path, log_path: Path,
                 generation: int) -> None:
        self.proc = proc
        self.patient = patient
        self.actor = actor
        self.socket_path = socket_path
        self.snapshot_path = snapshot_path
        self.log_path = log_path
        self.generation = generation

    def alive(self) -> bool:
        return self.proc.poll() is None

    def log_tail(self, lines: int = 6) -> str:
        try:
            text = self.log_path.read_text("utf-8", errors="replace").strip().splitlines()
        except OSError:
            return ""
        return " | ".join(text[-lines:])


class RendererHost:
    """The workspace's renderer (module docstring); a :class:`~fieldbank.web.robot.RobotSeam`.

    Parameters
    ----------
    settings : RobotSettings
    """

    view_path = "/robot"

    def __init__(self, settings: RobotSettings) -> None:
        self.settings = settings
        self._dir = Path(tempfile.mkdtemp(prefix="fieldbank-workspace-"))
        os.chmod(self._dir, 0o700)
        self._lock = threading.RLock()
        self._running: _Running | None = None
        self._generation = 0

    # --- what the robot view reads --------------------------------------------------------------
    @property
    def current(self) -> _Running | None:
        r = self._running
        return r if r is not None and r.alive() else None

    @property
    def robot_shown(self) -> str:
        return mask_url(self.settings.robot or SIMULATED)

    # --- the seam -------------------------------------------------------------------------------
    def feel(self, pair: FeelPair) -> dict[str, Any]:
        info = {"A": ModelInfo.describe(pair.labels[0], pair.model_ids[0], pair.patient_code),
                "B": ModelInfo.describe(pair.labels[1], pair.model_ids[1], pair.patient_code,
                                        pair.plan_label or None, pair.plan_id)}
        with self._lock:
            run = self.current
            if run is None or run.patient != pair.patient_code:
                if run is not None:
                    self._stop(run)
                run = self._start(pair, info)  # starts with the pair itself
                state = ControlClient(run.socket_path, timeout_s=5.0).request("status")
                started = True
            else:
                state = push_models(pair.before, pair.after, run.socket_path,
                                    model_ids=pair.model_ids, model_info=info)
                started = False
        return {"robot": self.robot_shown, "simulated": self.settings.simulated,
                "started": started, "patient": pair.patient_code, "view": self.view_path,
                "renderer": state}

    def status(self) -> dict[str, Any]:
        run = self.current
        out: dict[str, Any] = {"robot": self.robot_shown, "simulated": self.settings.simulated,
                               "running": run is not None, "view": self.view_path}
        if run is not None:
            out["patient"] = run.patient
            out["started_by"] = run.actor
            try:
                out["renderer"] = ControlClient(run.socket_path, timeout_s=5.0).request(
                    "status")
            except HapticError as exc:
                out["renderer_error"] = str(exc)
        return out

    def stop(self) -> dict[str, Any]:
        with self._lock:
            run = self.current
            if run is None:
                return {"stopped": False, "running": False}
            self._stop(run)
            return {"stopped": True, "running": False, "patient": run.patient}

    def close(self) -> None:
        """End the renderer (if any) and remove the private directory."""
        with self._lock:
            if self._running is not None:
                self._stop(self._running)
        for p in sorted(self._dir.glob("**/*"), reverse=True):
            try:
                p.rmdir() if p.is_dir() else p.unlink()
            except OSError:
                pass
        try:
            self._dir.rmdir()
        except OSError:
            pass

    # --- the renderer's process -----------------------------------------------------------------
    def _start(self, pair: FeelPair, info: dict[str, ModelInfo]) -> _Running:
        self._generation += 1
        gen = self._generation
        run_dir = self._dir / f"r{gen}"
        run_dir.mkdir(mode=0o700)
        sock, log = run_dir / "haptic.sock", run_dir / "renderer.log"
        s = self.settings
        config = {
            "robot": s.robot or SIMULATED, "rate_hz": s.rate_hz,
            "force_limit_n": s.force_limit_n, "before": pair.before.to_dict(),
            "after": pair.after.to_dict(), "model_ids": list(pair.model_ids),
            "patient": pair.patient_code, "actor": pair.actor,
            "model_info": {k: v.to_dict() for k, v in info.items()},
            "socket": str(sock), "snapshot_dir": str(run_dir), "trace_dir": s.trace_dir,
            "db_url": s.db_url,
        }
        root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [root, env.get("PYTHONPATH")]))
        with open(log, "wb") as logf:
            proc = subprocess.Popen([sys.executable, "-m", "fieldbank.haptic.workspace"],
                                    stdin=subprocess.PIPE, stdout=logf, stderr=logf, env=env)
        assert proc.stdin is not None
        proc.stdin.write((json.dumps(config) + "\n").encode())
        proc.stdin.flush()  # the pipe stays open: the renderer ends when it closes
        run = _Running(proc, pair.patient_code, pair.actor, sock, run_dir / "loop.snapshot",
                       log, gen)
        deadline = time.monotonic() + START_TIMEOUT_S
        client = ControlClient(sock, timeout_s=5.0)
        while True:
            if not run.alive():
                raise HapticError(f"the renderer did not start on {self.robot_shown} (exit "
                                  f"code {proc.returncode}): {run.log_tail()}")
            try:
                client.request("status")
                break
            except ControlError:
                if time.monotonic() > deadline:
                    self._stop(run)
                    raise HapticError(f"the renderer on {self.robot_shown} did not answer "
                                      f"within {START_TIMEOUT_S:g} s: {run.log_tail()}") from None
                time.sleep(0.2)
        self._running = run
        return run

    def _stop(self, run: _Running) -> None:
        if run.alive():
            try:
                ControlClient(run.socket_path, timeout_s=5.0).request("stop")
            except HapticError:
                pass
            try:
                run.proc.wait(timeout=STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                run.proc.kill()
                run.proc.wait()
        if run.proc.stdin is not None:
            run.proc.stdin.close()
        if self._running is run:
            self._running = None
