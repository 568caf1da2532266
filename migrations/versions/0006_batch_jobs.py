"""Batch work over workers: fit keys and versions, interval documents, job runs and jobs.

Revision ID: 0006
Revises: 0003
Create Date: 2026-11-24 12:00:00

Upgrade adds to ``fits`` the key of what a fit was made from (``fit_key``, unique: one fit per
key), the model version it was made under and the session it fitted (``session_id``, filled for
existing fits from the session their report names); adds ``fit_intervals`` (prediction
intervals kept with a fit) and ``job_runs`` / ``jobs`` (batch work: what ran, what failed, what
is left). Existing fits keep no key and no version: a batch refit treats them as made under an
older version. Downgrade drops the tables and columns; the fits themselves, their reports and
their maps stay, so nothing a user stored is lost (the interval documents are derived, the job
records are bookkeeping).
"""

from __future__ import annotations

import json

import sqlalchemy as sa
from alembic import op

revision = "0006"
down_revision = "0003"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("fits", schema=None) as batch_op:
        batch_op.add_column(sa.Column("fit_key", sa.String(length=64), nullable=True))
        batch_op.add_column(sa.Column("model_version", sa.Integer(), nullable=True))
        batch_op.add_column(sa.Column("session_id", sa.Integer(), nullable=True))
        batch_op.create_unique_constraint(batch_op.f("uq_fits_fit_key"), ["fit_key"])
        batch_op.create_foreign_key(batch_op.f("fk_fits_session_id_sessions"), "sessions",
                                    ["session_id"], ["id"])
        batch_op.create_index(batch_op.f("ix_fits_session_id"), ["session_id"], unique=False)
    _fill_fit_sessions()
    op.create_table(
        "fit_intervals",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("fit_id", sa.Integer(), nullable=False),
        sa.Column("key", sa.String(length=64), nullable=False),
        sa.Column("model_version", sa.Integer(), nullable=False),
        sa.Column("document_json", sa.Text(), nullable=False),
        sa.Column("arrays", sa.LargeBinary(), nullable=True),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.ForeignKeyConstraint(["fit_id"], ["fits.id"],
                                name=op.f("fk_fit_intervals_fit_id_fits")),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_fit_intervals")),
        sa.UniqueConstraint("fit_id", "key", name=op.f("uq_fit_intervals_fit_id_key")),
    )
    with op.batch_alter_table("fit_intervals", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_fit_intervals_fit_id"), ["fit_id"], unique=False)
    op.create_table(
        "job_runs",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("kind", sa.String(length=16), nullable=False),
        sa.Column("token", sa.String(length=64), nullable=False),
        sa.Column("engine", sa.String(length=255), nullable=False),
        sa.Column("args_json", sa.Text(), nullable=False),
        sa.Column("actor", sa.String(length=128), nullable=False),
        sa.Column("started_at", sa.DateTime(), nullable=False),
        sa.Column("finished_at", sa.DateTime(), nullable=True),
        sa.CheckConstraint("kind IN ('fit', 'report', 'validate')",
                           name=op.f("ck_job_runs_kind")),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_job_runs")),
        sa.UniqueConstraint("token", name=op.f("uq_job_runs_token")),
    )
    op.create_table(
        "jobs",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("run_id", sa.Integer(), nullable=False),
        sa.Column("key", sa.String(length=255), nullable=False),
        sa.Column("patient_code", sa.String(length=64), nullable=True),
        sa.Column("session_label", sa.String(length=128), nullable=True),
        sa.Column("state", sa.String(length=16), nullable=False),
        sa.Column("attempts", sa.Integer(), nullable=False),
        sa.Column("worker", sa.String(length=255), nullable=True),
        sa.Column("started_at", sa.DateTime(), nullable=True),
        sa.Column("finished_at", sa.DateTime(), nullable=True),
        sa.Column("error", sa.Text(), nullable=True),
        sa.Column("result_json", sa.Text(), nullable=True),
        sa.Column("payload", sa.LargeBinary(), nullable=True),
        sa.CheckConstraint("state IN ('pending', 'running', 'done', 'skipped', 'failed')",
                           name=op.f("ck_jobs_state")),
        sa.CheckConstraint("attempts >= 0", name=op.f("ck_jobs_attempts_non_negative")),
        sa.ForeignKeyConstraint(["run_id"], ["job_runs.id"],
                                name=op.f("fk_jobs_run_id_job_runs")),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_jobs")),
        sa.UniqueConstraint("run_id", "key", name=op.f("uq_jobs_run_id_key")),
    )
    with op.batch_alter_table("jobs", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_jobs_run_id"), ["run_id"], unique=False)


def _fill_fit_sessions() -> None:
    """Each existing fit's session, from the session its stored report names (a fit of every
    session, or a report naming no session, keeps None)."""
    fits = sa.table("fits", sa.column("id", sa.Integer), sa.column("patient_id", sa.Integer),
                    sa.column("result_json", sa.Text), sa.column("session_id", sa.Integer))
    sessions = sa.table("sessions", sa.column("id", sa.Integer),
                        sa.column("patient_id", sa.Integer), sa.column("label", sa.String))
    bind = op.get_bind()
    ids = {(int(p), str(label)): int(i) for i, p, label in
           bind.execute(sa.select(sessions.c.id, sessions.c.patient_id, sessions.c.label))}
    for fid, pid, doc in bind.execute(sa.select(fits.c.id, fits.c.patient_id,
                                                fits.c.result_json)):
        try:
            label = json.loads(doc or "{}").get("session")
        except (ValueError, AttributeError):
            continue  # an unreadable report stays as it is; its fit keeps no session
        sid = ids.get((int(pid), str(label))) if label else None
        if sid is not None:
            bind.execute(fits.update().where(fits.c.id == fid).values(session_id=sid))


def downgrade() -> None:
    with op.batch_alter_table("jobs", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_jobs_run_id"))
    op.drop_table("jobs")
    op.drop_table("job_runs")
    with op.batch_alter_table("fit_intervals", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_fit_intervals_fit_id"))
    op.drop_table("fit_intervals")
    with op.batch_alter_table("fits", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_fits_session_id"))
        batch_op.drop_constraint(batch_op.f("fk_fits_session_id_sessions"), type_="foreignkey")
        batch_op.drop_constraint(batch_op.f("uq_fits_fit_key"), type_="unique")
        batch_op.drop_column("session_id")
        batch_op.drop_column("model_version")
        batch_op.drop_column("fit_key")
