"""Remote assessment: the link a haptic session ran over; the posterior after each probe with
the clinician's answer beside it.

Revision ID: 0008
Revises: 0007
Create Date: 2026-11-24 15:00:00

Upgrade adds ``haptic_remote_links`` (one per remote session: the site's role, the peer, the
session key's fingerprint, the link's settings and what was measured) and
``haptic_assessments`` (one per probe: prior, posterior, most probable group and level, the
clinician's answer). Existing sessions are not remote and have no assessment: nothing to fill.
Downgrade drops both tables; the remote links and assessments they held are lost with them
(the per-tick link columns stay, as traces of their sessions) — ``fieldbank db downgrade`` takes
a backup first.
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0008"
down_revision = "0007"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "haptic_remote_links",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("haptic_session_id", sa.Integer(), nullable=False),
        sa.Column("role", sa.String(length=16), nullable=False),
        sa.Column("peer", sa.String(length=255), nullable=False),
        sa.Column("key_fingerprint", sa.String(length=32), nullable=False),
        sa.Column("settings_json", sa.Text(), nullable=False),
        sa.Column("summary_json", sa.Text(), nullable=False),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.CheckConstraint("role IN ('clinician', 'patient')",
                           name=op.f("ck_haptic_remote_links_role")),
        sa.ForeignKeyConstraint(
            ["haptic_session_id"], ["haptic_sessions.id"],
            name=op.f("fk_haptic_remote_links_haptic_session_id_haptic_sessions"),
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_haptic_remote_links")),
        sa.UniqueConstraint("haptic_session_id",
                            name=op.f("uq_haptic_remote_links_haptic_session_id")),
    )
    op.create_table(
        "haptic_assessments",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("haptic_session_id", sa.Integer(), nullable=False),
        sa.Column("probe", sa.Integer(), nullable=False),
        sa.Column("started_s", sa.Float(), nullable=True),
        sa.Column("ended_s", sa.Float(), nullable=True),
        sa.Column("prior_json", sa.Text(), nullable=False),
        sa.Column("posterior_json", sa.Text(), nullable=False),
        sa.Column("impaired_group", sa.String(length=32), nullable=True),
        sa.Column("group_probability", sa.Float(), nullable=True),
        sa.Column("level", sa.String(length=32), nullable=True),
        sa.Column("level_probability", sa.Float(), nullable=True),
        sa.Column("explains", sa.Boolean(), nullable=True),
        sa.Column("verdict", sa.Text(), nullable=False),
        sa.Column("detail_json", sa.Text(), nullable=False),
        sa.Column("answer_group", sa.String(length=32), nullable=True),
        sa.Column("answer_level", sa.String(length=32), nullable=True),
        sa.Column("answer_note", sa.Text(), nullable=True),
        sa.Column("answered_s", sa.Float(), nullable=True),
        sa.ForeignKeyConstraint(
            ["haptic_session_id"], ["haptic_sessions.id"],
            name=op.f("fk_haptic_assessments_haptic_session_id_haptic_sessions"),
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_haptic_assessments")),
        sa.UniqueConstraint("haptic_session_id", "probe",
                            name=op.f("uq_haptic_assessments_haptic_session_id_probe")),
    )
    with op.batch_alter_table("haptic_assessments", schema=None) as batch_op:
        batch_op.create_index(
            batch_op.f("ix_haptic_assessments_haptic_session_id"), ["haptic_session_id"],
            unique=False,
        )


def downgrade() -> None:
    with op.batch_alter_table("haptic_assessments", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_haptic_assessments_haptic_session_id"))
    op.drop_table("haptic_assessments")
    op.drop_table("haptic_remote_links")
