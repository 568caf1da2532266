"""Haptic rendering of arm models on a 2-DOF planar robot.

The package may use the fieldbank core (models, storage); it never imports
``fieldbank.interventions`` or the command line. Modules:

- :mod:`haptic.errors` — the ``HapticError`` subtree (``LinkDown``, ``HandshakeError``,
  ``FrameError``, ``CommandError``, ``ControlError``), drawn in its docstring
- :mod:`haptic.port` — the robot seam: ``RobotPort`` and ``HandleState``
- :mod:`haptic.robots` — a robot by its URL: the project's link or an installed adapter
  (entry point group ``fieldbank.robots``)
- :mod:`haptic.protocol` — wire format (COBS frames, CRC-16, sequence numbers), version 1
- :mod:`haptic.link` — host endpoint over any pyserial URL (``sim://`` included), a robot port
- :mod:`haptic.simrobot`, :mod:`haptic.protocol_sim`, :mod:`haptic.motions` — the simulated
  robot and operator
- :mod:`haptic.safety` — limits (one bounds table), passivity observer/controller, latched faults
- :mod:`haptic.monitor` — the safety monitor: every fault check of a loop and its counters
- :mod:`haptic.clock` — real and virtual clocks, the ``realtime()`` context of the loop
  (SCHED_FIFO, a core of its own, what was granted), the simulated device's priority
- :mod:`haptic.renderer`, :mod:`haptic.rendererconfig` — the real-time loop (``Renderer``:
  tick, start, run, finish) and its settings
- :mod:`haptic.loopstats` — period error, overruns, tick cost, status figures
- :mod:`haptic.commands`, :mod:`haptic.commandbase` — the typed command table (switch, push,
  arm, disarm, stop, status, A/B/X, training): parsed from control requests, applied by the loop
- :mod:`haptic.activities` — A/B/X blocks and training protocols as activities the commands
  address; whether a trial was felt (faults, zero force): flagged trials
- :mod:`haptic.client` — control-channel client (light: what the live commands load)
- :mod:`haptic.control` — control-channel server (Unix socket)
- :mod:`haptic.session` — a whole session: robot, handshake, render, trace file, database
- :mod:`haptic.recording`, :mod:`haptic.dbsink`, :mod:`haptic.replay` — traces
- :mod:`haptic.probe` — scripted probing

Design and safety: ``docs/haptics.md``; wire specification: ``docs/robot-protocol.md``.
"""
