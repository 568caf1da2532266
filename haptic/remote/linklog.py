"""Every tick of a remote port, kept: named float64 columns with units (:class:`LinkLog`), and
the columns each port writes (:data:`CLINICIAN_COLUMNS`, :data:`PATIENT_COLUMNS`).

The clinician's log goes beside the session's trace (``<trace>.link.h5``) and into the database
as ``link.*`` traces; the patient's site writes its own (``remote-patient-*.h5``). Both carry
the tick, so the two sites' logs align (the energy the link created is read from them).
"""

from __future__ import annotations

import array
import io
import math
from typing import Any

import numpy as np

from fieldbank.files import to_json


class LinkLog:
    """Per-tick rows of named float64 columns with units (grows in chunks, never copies)."""

    def __init__(self, columns: tuple[tuple[str, str], ...]) -> None:
        self.columns = columns
        self._cols = [array.array("d") for _ in columns]
        self.n = 0

    def add(self, row: tuple[float, ...]) -> None:
        for c, v in zip(self._cols, row, strict=True):
            c.append(v)
        self.n += 1

    def arrays(self) -> dict[str, np.ndarray]:
        return {name: np.frombuffer(c, dtype=np.float64).copy()
                for (name, _), c in zip(self.columns, self._cols, strict=True)}

    def last(self, name: str) -> float:
        i = [c for c, _ in self.columns].index(name)
        return self._cols[i][-1] if self.n else math.nan

    @property
    def units(self) -> dict[str, str]:
        return dict(self.columns)

    def to_hdf5(self, attrs: dict[str, Any]) -> bytes:
        """The log as an HDF5 image: one dataset per column with its ``unit``; ``attrs`` (JSON)
        on the file."""
        import h5py  # heavy: loaded only when a session's log is written

        bio = io.BytesIO()
        with h5py.File(bio, "w") as f:
            for name, data in self.arrays().items():
                d = f.create_dataset(name, data=data, compression="gzip", fletcher32=True)
                d.attrs["unit"] = self.units[name]
            for k, v in attrs.items():
                f.attrs[k] = to_json(v)
        return bio.getvalue()


CLINICIAN_COLUMNS: tuple[tuple[str, str], ...] = (
    ("t_s", "s"), ("tick", "1"),
    ("x_m", "m"), ("y_m", "m"), ("vx_m_per_s", "m/s"), ("vy_m_per_s", "m/s"),  # port (sent)
    ("want_fx_n", "N"), ("want_fy_n", "N"),          # received patient force × ramp gain
    ("fx_n", "N"), ("fy_n", "N"),                    # displayed (booked: what was commanded)
    ("e_in_j", "J"), ("e_out_j", "J"),               # this port's observer
    ("e_sent_j", "J"), ("e_received_j", "J"),        # its tank's hand-overs
    ("peer_e_in_j", "J"), ("peer_e_out_j", "J"),     # the patient port, as last received
    ("alpha_n_s_per_m", "N·s/m"),                    # passivity controller's damping
    ("gain", "1"), ("link_ok", "1"), ("engaged", "1"), ("rtt_s", "s"),
    ("peer_x_m", "m"), ("peer_y_m", "m"), ("peer_vx_m_per_s", "m/s"),
    ("peer_vy_m_per_s", "m/s"), ("peer_fx_n", "N"), ("peer_fy_n", "N"),
    ("peer_tick", "1"), ("peer_flags", "1"), ("new_state", "1"), ("lost", "1"),
    ("dissipated_j", "J"),
)
PATIENT_COLUMNS: tuple[tuple[str, str], ...] = (
    ("t_s", "s"), ("tick", "1"),
    ("x_m", "m"), ("y_m", "m"), ("vx_m_per_s", "m/s"), ("vy_m_per_s", "m/s"),  # patient handle
    ("hand_fx_n", "N"), ("hand_fy_n", "N"),          # the patient's force on the handle
    ("target_x_m", "m"), ("target_y_m", "m"),        # the clinician's position (received)
    ("cmd_x_m", "m"), ("cmd_y_m", "m"),              # the robot's reference
    ("cmd_vx_m_per_s", "m/s"), ("cmd_vy_m_per_s", "m/s"),
    ("servo_fx_n", "N"), ("servo_fy_n", "N"),        # commanded to the patient's robot
    ("e_in_j", "J"), ("e_out_j", "J"),
    ("e_sent_j", "J"), ("e_received_j", "J"),
    ("peer_e_in_j", "J"), ("peer_e_out_j", "J"),
    ("beta_m_per_n_s", "m/(N·s)"),
    ("gain", "1"), ("link_ok", "1"), ("engaged", "1"), ("rtt_s", "s"),
    ("new_state", "1"), ("lost", "1"),
)
