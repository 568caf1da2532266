"""Measured maps from raw data: the protocol, the recording, the estimator, raw file readers.

The robot's own measurement (:mod:`fieldbank.haptic.measure`) and the readers of raw lab files
(NWB :mod:`~fieldbank.measure.nwbraw`, C3D :mod:`~fieldbank.measure.c3draw`) produce the same
:class:`~fieldbank.measure.recording.Recording`; one estimator
(:mod:`~fieldbank.measure.estimate`) turns it into postural and stiffness maps with their
standard deviations and the trials kept and dropped. ``docs/measuring.md`` describes the method
and its accuracy.
"""
