"""fieldbank's data directory, in a module light enough for every command to import.

``$FIELDBANK_HOME``, else the platform's user data directory (platformdirs). The embedded
SQLite database, its array store, haptic traces and the renderer's control socket live there
unless configured elsewhere. Kept apart from :mod:`fieldbank.storage.config` so that the live
haptic commands find the socket without loading SQLAlchemy.
"""

from __future__ import annotations

import os
from pathlib import Path

import platformdirs

ENV_HOME = "FIELDBANK_HOME"


def data_home() -> Path:
    """The data directory: ``FIELDBANK_HOME`` or the platform's user data directory."""
    env = os.environ.get(ENV_HOME)
    if env:
        return Path(env).expanduser()
    return Path(platformdirs.user_data_dir("fieldbank", appauthor=False))
