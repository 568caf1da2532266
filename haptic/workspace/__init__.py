"""The haptic wing's part of the workspace (``fieldbank serve``).

* :mod:`~haptic.workspace.host` - :class:`RendererHost`, the workspace's robot seam
  (:class:`fieldbank.web.robot.RobotSeam`): starts the configured robot's renderer (the
  simulated one where none is configured) in a process of its own and pushes before/after;
* :mod:`~haptic.workspace.view` - :class:`RobotViewRoutes`, the station's robot view (A ↔ B,
  A/B/X, training) served inside the workspace behind its login, and the robot's API routes;
* ``python -m fieldbank.haptic.workspace`` - the renderer's process.

This package imports the core's web seam and the haptic wing only; the command line hands the
host to the plan composer (interventions), which never imports it.
"""
