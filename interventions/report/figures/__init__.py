"""The figures of a what-if case, as vector graphics on :mod:`fieldbank.figures`: the report's
and ``whatif --plot``'s - one set of figures, one module per family.

Each function takes already computed values and returns a
:class:`~fieldbank.figures.scene.Scene`; what the plan changes comes first
(:func:`.case.case_figures` puts them in order, with their captions):

* ``stretches`` - :func:`~.stretches.stretch_figure`: the clinic's joint stretches
  (Tardieu-style): torque resisting the slow (5°/s) and the fast (180°/s) stretch over the joint
  angle, before and after, per joint and direction, the catch (R1) and the slow stop (R2)
  marked, the treated groups' stretches named; where the what-if has intervals, the 95% band of
  the fast stretch after; :func:`~.stretches.timecourse_figure`: botulinum effect and
  fast-stretch torque week by week;
* ``workspace`` - :func:`~.workspace.moving_field_figure`: the field with the hand moving in
  the direction that lengthens the treated groups (where the stretch reflex acts), before,
  after and the change; :func:`~.workspace.static_field_figure`: the passive (postural) field
  over the potential U, and ΔU on a diverging map; :func:`~.workspace.ellipse_figure`: static
  stiffness;
* ``grades`` - :func:`~.grades.severity_figure`: passive and dynamic grade per muscle group,
  before → after; :func:`~.grades.probes_figure`: force felt along the seed's probing motions;
* ``cohort`` - :func:`~.cohort.validation_figure`: predicted against measured change, where
  maps measured after the plan exist (one case, or across patients);
  :func:`~.cohort.cohort_change_figure`: the change per intervention kind across a batch;
* ``case`` - :func:`~.case.case_figures`: one case's figures in order, with captions;
* ``common`` - the page width and the small texts every family shares.

Before is drawn in blue, after in vermillion, changes in near black; units on every axis and
key; every curve and arrow set carries ``data-*`` attributes naming what it shows.
"""
