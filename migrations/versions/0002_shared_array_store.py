"""Shared array store: a server database keeps its large arrays inside itself.

Adds ``arrays.location`` ('file': the array store directory; 'database': ``array_chunks``)
and the table ``array_chunks`` (the HDF5 file image of an array in numbered pieces), so every
workstation of a PostgreSQL database reads the same arrays (``fieldbank.storage.arrays``).

Existing data are kept both ways:

* upgrade: every existing array stays where it is ('file'). On a server database, arrays
  whose files this workstation's store holds are copied into ``array_chunks`` and marked
  'database' (verified against their SHA-256 first); the files stay where they were.
  Arrays held by other workstations are moved in by ``fieldbank db gc`` run there.
* downgrade: revision 0001 reads arrays from the store directory only, so every array kept in
  the database is first written to this workstation's store directory (write-once, verified),
  then ``array_chunks`` and the column are dropped. If a file cannot be written the downgrade
  fails and nothing changes.

The store directory is the one fieldbank would use for this database
(``fieldbank.storage.config.default_store_root``), unless fieldbank passes another in the
alembic configuration's ``store_root`` attribute.

Revision ID: 0002
Revises: 0001
Create Date: 2026-12-02 09:00:00
"""

from __future__ import annotations

from pathlib import Path

import sqlalchemy as sa
from alembic import context, op

from fieldbank.arraystore import ArrayStore, decode_array
from fieldbank.storage.arrays import CHUNK_BYTES
from fieldbank.storage.config import default_store_root

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None

_arrays = sa.table("arrays", sa.column("sha256", sa.String), sa.column("location", sa.String))
_chunks = sa.table("array_chunks", sa.column("sha256", sa.String), sa.column("idx", sa.Integer),
                   sa.column("data", sa.LargeBinary))


def _store() -> ArrayStore:
    root = context.config.attributes.get("store_root")
    if root is None:
        root = default_store_root(op.get_bind().engine.url)
    return ArrayStore(Path(root))


def upgrade() -> None:
    op.add_column("arrays", sa.Column("location", sa.String(length=16), server_default="file",
                                      nullable=False))
    op.create_table(
        "array_chunks",
        sa.Column("sha256", sa.String(length=64), nullable=False),
        sa.Column("idx", sa.Integer(), nullable=False),
        sa.Column("data", sa.LargeBinary(), nullable=False),
        sa.ForeignKeyConstraint(["sha256"], ["arrays.sha256"],
                                name=op.f("fk_array_chunks_sha256_arrays")),
        sa.PrimaryKeyConstraint("sha256", "idx", name=op.f("pk_array_chunks")),
    )
    bind = op.get_bind()
    if bind.dialect.name == "sqlite":
        return  # a SQLite database keeps its arrays in its own store directory
    store = _store()
    for (key,) in bind.execute(sa.select(_arrays.c.sha256)).all():
        if not store.has(key):
            continue  # another workstation's file: moved in by 'fieldbank db gc' there
        image = store.read_image(key)
        decode_array(key, image, f"file {store.relpath(key)}")
        for i, off in enumerate(range(0, max(1, len(image)), CHUNK_BYTES)):
            bind.execute(sa.insert(_chunks).values(sha256=key, idx=i,
                                                   data=image[off:off + CHUNK_BYTES]))
        bind.execute(sa.update(_arrays).where(_arrays.c.sha256 == key)
                     .values(location="database"))


def downgrade() -> None:
    bind = op.get_bind()
    keys = [k for (k,) in bind.execute(sa.select(_arrays.c.sha256)
                                       .where(_arrays.c.location == "database")).all()]
    if keys:
        store = _store()
        for key in keys:
            parts = bind.execute(sa.select(_chunks.c.data).where(_chunks.c.sha256 == key)
                                 .order_by(_chunks.c.idx)).scalars().all()
            image = b"".join(parts)
            decode_array(key, image, "in the database")
            store.write_image(key, image)
    op.drop_table("array_chunks")
    op.drop_column("arrays", "location")
