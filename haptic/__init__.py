"""Haptic rendering of arm models on a 2-DOF planar robot.

- :mod:`haptic.protocol` — wire format (COBS frames, CRC-16, sequence numbers), version 1
- :mod:`haptic.link` — host endpoint over any pyserial URL (``sim://`` included)
- :mod:`haptic.simrobot`, :mod:`haptic.protocol_sim`, :mod:`haptic.motions` — the simulated
  robot and operator
- :mod:`haptic.safety` — limits, passivity observer/controller, latched faults
- :mod:`haptic.renderer` — the real-time loop, A↔B crossfade, A/B/X (:mod:`haptic.abx`)
- :mod:`haptic.control` — local control channel (Unix socket)
- :mod:`haptic.recording`, :mod:`haptic.dbsink`, :mod:`haptic.replay` — traces
- :mod:`haptic.probe` — scripted probing (models come from :mod:`fieldbank.modelsource`)

Design and safety: ``docs/haptics.md``; wire specification: ``docs/robot-protocol.md``.
"""
