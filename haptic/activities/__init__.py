"""What the clinician runs on the loop, as activities the renderer's commands address.

* :mod:`~haptic.activities.base` — :class:`Activity` (start, its own steps, answer, the tick
  hook, stop, result, state), :class:`ActivityHost` (the loop as activities see it) and
  :class:`Activities` (one running at a time; the results by kind);
* :mod:`~haptic.activities.abx` — blinded A/B/X blocks: ``present`` A, B or X, ``answer``
  A or B;
* :mod:`~haptic.activities.training` — the seed's training protocol: ``next`` trial,
  ``answer`` shoulder, elbow or both;
* :mod:`~haptic.activities.window` — whether a trial was felt: its window, fed by the tick hook.

The control channel's requests for them (``{"cmd": "abx" | "train", "action": …}``) are in
:mod:`haptic.commands`; ``docs/haptics.md`` (Activities) has the table of their surface.
"""
