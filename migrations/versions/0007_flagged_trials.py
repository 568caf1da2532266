"""Trials flagged for a fault or no force during their window.

Revision ID: 0007
Revises: 0006
Create Date: 2026-11-24 13:00:00

Upgrade adds ``haptic_trials.flagged``: the trial's window held a fault or no force, so its
answer is kept but left out of every accuracy (the reasons are in the trial's detail document).
Trials stored before are not flagged: they were stored before the renderer judged windows, and
nothing a user stored is changed. Downgrade drops the column; the reasons stay in each trial's
detail document. (A session's plan needs no column: the plan id is in the session's statistics
document, beside the models' descriptions.)
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0007"
down_revision = "0006"
branch_labels = None
depends_on = None


def upgrade() -> None:
    # a plain text default: SQLite then adds the column in place, without copying the table
    with op.batch_alter_table("haptic_trials", schema=None) as batch_op:
        batch_op.add_column(sa.Column("flagged", sa.Boolean(), nullable=False,
                                      server_default="0"))


def downgrade() -> None:
    with op.batch_alter_table("haptic_trials", schema=None) as batch_op:
        batch_op.drop_column("flagged")
