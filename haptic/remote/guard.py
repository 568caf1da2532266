"""The robot checks a site runs every tick on the robot it drives (the patient's site).

The same checks as the renderer's (:mod:`haptic.renderer`, :mod:`haptic.safety`): the link's
CRC leaky bucket, sequence gaps, no STATE within the timeout, device FAULT frames and the fault
and watchdog flags of every STATE frame read, NaN, the workspace box and the speed limit. The
first that fails is returned with its message; the site trips the fault (zero force at once,
disarm, latched) and its port stops following the clinician.
"""

from __future__ import annotations

import math

from fieldbank.haptic.link import RobotLink
from fieldbank.haptic.protocol import FaultCode, device_report
from fieldbank.haptic.safety import Safety


class RobotGuard:
    """Per-tick checks of one robot link against one safety layer."""

    def __init__(self, link: RobotLink, safety: Safety, dt_s: float) -> None:
        self.link = link
        self.safety = safety
        self._timeout_ticks = max(1, math.ceil(safety.config.state_timeout_ms * 1e-3 / dt_s))
        self._stale = 0
        self.forgive()

    def forgive(self) -> None:
        """Take the link's counters as they are now (on arming)."""
        link = self.link
        self._seen = (link.device_faults, link.fault_flag_frames, link.watchdog_flag_frames)
        self._stale = 0
        link.take_gap()

    def check(self, new_states: int) -> tuple[int, str]:
        """Fault code (0: none) and message after a poll that brought ``new_states`` STATEs."""
        link, safety = self.link, self.safety
        self._stale = 0 if new_states else self._stale + 1
        if safety.check_crc(link.crc_errors):
            return FaultCode.CRC, f"{link.crc_errors} CRC errors (leaky bucket)"
        gap = link.take_gap()
        if gap > safety.config.max_seq_gap:
            return FaultCode.SEQ_GAP, f"{gap} frames lost in one gap"
        if self._stale > self._timeout_ticks:
            return FaultCode.TIMEOUT, f"no STATE for {self._stale} ticks"
        seen = (link.device_faults, link.fault_flag_frames, link.watchdog_flag_frames)
        if seen != self._seen:
            self._seen = seen
            return FaultCode.DEVICE, device_report(link.last_device_fault, link.flags)
        return safety.check_handle(link.x, link.y, link.vx, link.vy)
