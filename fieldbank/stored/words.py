"""What is not there, in words: the messages for a patient or a batch run that a command names
and the database does not hold - one wording for :class:`fieldbank.storage.Database` and the
light listing (:mod:`fieldbank.stored.listing`)."""

from __future__ import annotations

from collections.abc import Sequence


def no_patient(code: str, codes: Sequence[str], where: str) -> str:
    """No patient ``code`` in the database ``where`` (its URL as messages show it), which holds
    the patients ``codes`` (sorted): the nearest codes, or how to start."""
    import difflib  # only when a code is not found: listing needs no matcher

    if not codes:
        held = ("it holds no patients (a new database, or not the one you meant: "
                "'fieldbank config show' says which is in force)")
    else:
        near = difflib.get_close_matches(code, codes, n=3, cutoff=0.5) or list(codes[:3])
        held = (f"it holds {len(codes)} patient{'s' if len(codes) != 1 else ''}; "
                f"nearest: {', '.join(near)}")
    return (f"No patient with code {code!r} in {where}: {held}. "
            "Add one with 'fieldbank patient add'.")


def no_run(run_id: int) -> str:
    """No batch run ``run_id``."""
    return f"No job run with id {run_id}; 'fieldbank jobs' lists them."
