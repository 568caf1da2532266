"""Exceptions raised by the haptic package: the ``HapticError`` subtree of
:class:`fieldbank.errors.FieldbankError`.

Rooted in built-ins, so callers may catch either::

    FieldbankError                                  (fieldbank.errors)
    └── HapticError(FieldbankError, RuntimeError)   the renderer, the robot or its link failed
        ├── LinkDown(HapticError)                   the robot's port failed (unplugged, closed, I/O)
        ├── HandshakeError(HapticError)             the robot did not answer HELLO or refused it
        ├── FrameError(HapticError, ValueError)     a wire frame that cannot be decoded (``kind``)
        ├── CommandError(HapticError, ValueError)   a renderer command that is malformed or not
        │                                           possible now (no A/B/X block, not running)
        ├── ControlError(HapticError)               the control channel failed: no renderer on
        │                                           the socket, a refused or broken connection
        └── AssessError(HapticError, ValueError)    the clinician's prior or answer at the remote
                                                    desk refused (an unknown group or severity,
                                                    a note too long, a prior ruling out all)

Parameter ranges of the loop's frozen configurations (``RendererConfig``, ``SafetyConfig``) are
checked by :mod:`fieldbank.validation` and raise the core's ``ParameterError``; trace files and
database records raise the core's ``StorageError``.

This module imports nothing but :mod:`fieldbank.errors`, so the command line's light paths
(``fieldbank haptic switch``) can use it.
"""

from __future__ import annotations

from fieldbank.errors import FieldbankError


class HapticError(FieldbankError, RuntimeError):
    """The haptic renderer, the robot or the link to it failed."""


class LinkDown(HapticError):
    """The robot's port failed (unplugged, closed, I/O error)."""


class HandshakeError(HapticError):
    """The robot did not answer HELLO in time, refused it, or speaks another protocol."""


class FrameError(HapticError, ValueError):
    """A frame that cannot be decoded.

    Attributes
    ----------
    kind : str
        'cobs', 'crc', 'length', 'version' or 'type' (the frame reader counts errors by kind).
    """

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


class CommandError(HapticError, ValueError):
    """A renderer command that is malformed, unknown, or not possible in the renderer's state."""


class ControlError(HapticError):
    """The control channel failed: no renderer listening, a refused or broken connection."""


class AssessError(HapticError, ValueError):
    """The clinician's prior or answer at the remote desk is refused: a muscle group or
    severity the scale does not have, a note too long, or a prior that rules out every
    candidate."""
