"""Haptic rendering of arm models on a 2-DOF planar robot.

The package may use the fieldbank core (models, storage); it never imports
``fieldbank.interventions`` or the command line. Modules:

- :mod:`haptic.errors` — the ``HapticError`` subtree (``LinkDown``, ``HandshakeError``,
  ``FrameError``, ``CommandError``, ``ControlError``), drawn in its docstring
- :mod:`haptic.protocol` — wire format (COBS frames, CRC-16, sequence numbers), version 1
- :mod:`haptic.link` — host endpoint over any pyserial URL (``sim://`` included)
- :mod:`haptic.simrobot`, :mod:`haptic.protocol_sim`, :mod:`haptic.motions` — the simulated
  robot and operator
- :mod:`haptic.safety` — limits (one bounds table), passivity observer/controller, latched faults
- :mod:`haptic.clock` — real and virtual clocks, the ``realtime()`` context of the loop
  (SCHED_FIFO, a core of its own, what was granted), the simulated device's priority
- :mod:`haptic.renderer` — the real-time loop: ``RendererConfig``, ``Renderer`` (tick, start,
  run, finish), A↔B crossfade
- :mod:`haptic.loopstats` — period error, overruns, tick cost, status figures
- :mod:`haptic.commands` — the typed command table (switch, push, arm, disarm, stop, status,
  A/B/X): parsed from control requests, applied by the loop
- :mod:`haptic.abx` — blinded A/B/X trials (A before, B after; X hidden)
- :mod:`haptic.trialwindow` — whether a trial was felt (faults, zero force): flagged trials
- :mod:`haptic.client` — control-channel client (light: what the live commands load)
- :mod:`haptic.control` — control-channel server (Unix socket)
- :mod:`haptic.session` — a whole session: link, handshake, render, trace file, database
- :mod:`haptic.recording`, :mod:`haptic.dbsink`, :mod:`haptic.replay` — traces
- :mod:`haptic.probe` — scripted probing

Design and safety: ``docs/haptics.md``; wire specification: ``docs/robot-protocol.md``.
"""
