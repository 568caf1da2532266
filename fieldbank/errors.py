"""Exceptions raised by fieldbank.

The whole tree, rooted in built-ins so callers may catch either::

    FieldbankError(Exception)
    ├── ParameterError(FieldbankError, ValueError)    a parameter outside its allowed range
    ├── UnreachableError(FieldbankError, ValueError)  a hand position the arm cannot reach
    ├── MapError(FieldbankError, ValueError)          a force/stiffness map that is malformed
    ├── ValidationError(FieldbankError, ValueError)   input with one or more located problems
    ├── FileRefused(FieldbankError, ValueError)       an input file refused before reading it
    │                                                 (not a regular file, too large)
    ├── ConfigError(FieldbankError, ValueError)       fieldbank.toml or a setting is malformed
    ├── StorageError(FieldbankError, RuntimeError)    the database or the array store failed
    │   ├── IntegrityError(StorageError)              a stored reference or checksum is wrong
    │   └── DatabaseMissing(StorageError)             no database where one was to be read
    ├── FitError(FieldbankError, RuntimeError)        a fit that cannot run or was refused
    ├── ClusterError(FieldbankError, RuntimeError)    a Dask scheduler refused (an address open
    │                                                 to anyone, missing certificates) or
    │                                                 not reached
    ├── InterventionError(FieldbankError, ValueError) subtree in fieldbank.interventions.errors
    └── HapticError(FieldbankError, RuntimeError)     subtree in fieldbank.haptic.errors

The packages above the core keep their own subtrees next to their code (the core never imports
them): ``fieldbank.interventions.errors`` holds InterventionError and SelectionError,
``fieldbank.haptic.errors`` HapticError, LinkDown, FrameError and the control errors.

Messages say what was expected, what arrived, and where (parameter, file, row, dataset).
"""

from __future__ import annotations

from dataclasses import dataclass


class FieldbankError(Exception):
    """Root of every error fieldbank raises on purpose."""


class ParameterError(FieldbankError, ValueError):
    """A model parameter, or an argument of the library, is missing, not finite, outside its
    allowed range or not one of the names it may be."""


class UnreachableError(FieldbankError, ValueError):
    """A hand position lies outside the arm's reachable workspace."""


class MapError(FieldbankError, ValueError):
    """A map's arrays or metadata are inconsistent."""


@dataclass(frozen=True)
class Problem:
    """One located problem found while validating input.

    Attributes
    ----------
    location : str
        Where: ``file.csv:row 12``, ``file.h5:/maps/0/positions``, ``parameter km_n_per_m[2]``.
    reason : str
        What is wrong, saying what was expected and what arrived.
    """

    location: str
    reason: str

    def __str__(self) -> str:
        return f"{self.location}: {self.reason}"


class ValidationError(FieldbankError, ValueError):
    """Input with one or more problems; ``problems`` lists every one, located.

    ``max_shown``: the message lists at most this many, then says how many more there are
    (``problems`` keeps them all).
    """

    def __init__(self, problems: list[Problem] | tuple[Problem, ...], header: str = "",
                 max_shown: int | None = None) -> None:
        self.problems = tuple(problems)
        lines = [header] if header else []
        shown = self.problems if max_shown is None else self.problems[:max_shown]
        lines += [str(p) for p in shown]
        if len(shown) < len(self.problems):
            lines.append(f"... and {len(self.problems) - len(shown)} more problem(s) not "
                         "listed")
        super().__init__("\n".join(lines))


class FileRefused(FieldbankError, ValueError):
    """An input file refused before it is read: not a regular file (a FIFO, a device, a
    directory), larger than the limit, or unreadable. The message names the file."""


class ConfigError(FieldbankError, ValueError):
    """The configuration file, or a setting from a variable or a flag, is malformed."""


class StorageError(FieldbankError, RuntimeError):
    """The database or the array store failed or refused an operation."""


class IntegrityError(StorageError):
    """A stored reference, checksum or array does not match what was recorded."""


class DatabaseMissing(StorageError):
    """No database file where a command that only reads or adds to one looked: it is never
    created by surprise (the message names the path and how to create it)."""


class FitError(FieldbankError, RuntimeError):
    """A fit that cannot run (no data, wrong patient, inconsistent units) or failed."""


class ClusterError(FieldbankError, RuntimeError):
    """A Dask scheduler fieldbank will not use (a plain address beyond the loopback, a tls://
    address without the cluster's certificates, certificates that do not fit) or cannot reach;
    or certificates for a cluster that cannot be made."""
