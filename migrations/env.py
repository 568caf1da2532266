"""Alembic environment of the field database.

Used through :mod:`fieldbank.storage.migrate` (``fieldbank db upgrade``), which hands over an
open connection in ``config.attributes['connection']`` inside a transaction it already holds
(with its lock). Run directly (``alembic -c migrations/alembic.ini``), it connects to the URL
resolved as fieldbank does (``-x db=URL`` > ``FIELDBANK_DB`` > the embedded SQLite file).
SQLite uses batch mode, since it cannot alter most constraints in place.
"""

from __future__ import annotations

from alembic import context
from sqlalchemy import Connection

from fieldbank.storage.config import make_engine
from fieldbank.storage.orm import Base

config = context.config
target_metadata = Base.metadata


def _run(connection: Connection) -> None:
    context.configure(
        connection=connection,
        target_metadata=target_metadata,
        render_as_batch=connection.dialect.name == "sqlite",
        compare_type=True,
    )
    with context.begin_transaction():
        context.run_migrations()


def run_online() -> None:
    connection = config.attributes.get("connection")
    if connection is not None:
        _run(connection)
        return
    url = context.get_x_argument(as_dictionary=True).get("db")
    engine = make_engine(url)
    try:
        with engine.connect() as conn:
            _run(conn)
            conn.commit()
    finally:
        engine.dispose()


if context.is_offline_mode():
    raise SystemExit("fieldbank migrations run online only (they need a connection).")
run_online()
