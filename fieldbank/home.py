"""fieldbank's data directory, in a module light enough for every command to import.

``$FIELDBANK_HOME``, else ``home`` in ``fieldbank.toml``, else the platform's user data
directory (platformdirs) - the setting ``home`` of :mod:`fieldbank.config`. The embedded
SQLite database, its array store, haptic traces and the renderer's control socket live there
unless configured elsewhere. Kept apart from :mod:`fieldbank.storage.config` so that the live
haptic commands find the socket without loading SQLAlchemy.
"""

from __future__ import annotations

from pathlib import Path

from fieldbank.config import setting

ENV_HOME = "FIELDBANK_HOME"


def data_home() -> Path:
    """The data directory: ``FIELDBANK_HOME``, the configuration file's ``home``, or the
    platform's user data directory."""
    home: Path = setting("home").value
    return home
