"""Haptic trials: one row per A/B/X or training trial; why a session's patient differs.

Revision ID: 0003
Revises: 0001
Create Date: 2026-11-22 09:00:00

Upgrade adds ``haptic_trials`` and ``haptic_sessions.patient_note`` and fills ``haptic_trials``
from the A/B/X answers that existing sessions keep in their statistics document (nothing is
moved: the document stays as it was). Downgrade drops both again; every answer is still in the
sessions' statistics documents, so nothing a user stored is lost.
"""

from __future__ import annotations

import json
from typing import Any

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None


def _abx_rows(session_id: int, stats: dict[str, Any]) -> list[dict[str, Any]]:
    """The A/B/X trials kept in a session's statistics (the format written before 0003)."""
    meta = stats.get("metadata") or {}
    starts = [float(e.get("t_s", 0.0)) for e in stats.get("events") or []
              if e.get("event") == "abx_start"]
    rows = []
    for block, res in enumerate(meta.get("abx") or []):
        prev = starts[block] if block < len(starts) else None
        for a in res.get("answers") or []:
            answered = float(a["t_s"]) if a.get("t_s") is not None else None
            rows.append({
                "haptic_session_id": session_id, "kind": "abx", "block": block,
                "trial": int(a["trial"]), "phase": "abx", "condition": f"X={a.get('x_is')}",
                "answer": a.get("answer"), "correct": a.get("correct"),
                "started_s": prev, "answered_s": answered,
                "response_time_s": (answered - prev if answered is not None and prev is not None
                                    else None),
                "detail_json": json.dumps({"x_model": a.get("x_model"),
                                           "label_model": res.get("label_model"),
                                           "seed": res.get("seed"),
                                           "hide_labels": res.get("hide_labels")},
                                          sort_keys=True),
            })
            prev = answered
    return rows


def upgrade() -> None:
    with op.batch_alter_table("haptic_sessions", schema=None) as batch_op:
        batch_op.add_column(sa.Column("patient_note", sa.Text(), nullable=True))
    trials = op.create_table(
        "haptic_trials",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("haptic_session_id", sa.Integer(), nullable=False),
        sa.Column("kind", sa.String(length=16), nullable=False),
        sa.Column("block", sa.Integer(), nullable=False),
        sa.Column("trial", sa.Integer(), nullable=False),
        sa.Column("phase", sa.String(length=32), nullable=False),
        sa.Column("condition", sa.String(length=64), nullable=False),
        sa.Column("answer", sa.String(length=16), nullable=True),
        sa.Column("correct", sa.Boolean(), nullable=True),
        sa.Column("started_s", sa.Float(), nullable=True),
        sa.Column("answered_s", sa.Float(), nullable=True),
        sa.Column("response_time_s", sa.Float(), nullable=True),
        sa.Column("detail_json", sa.Text(), nullable=False),
        sa.CheckConstraint("kind IN ('abx', 'training')", name=op.f("ck_haptic_trials_kind")),
        sa.ForeignKeyConstraint(
            ["haptic_session_id"], ["haptic_sessions.id"],
            name=op.f("fk_haptic_trials_haptic_session_id_haptic_sessions"),
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_haptic_trials")),
        sa.UniqueConstraint("haptic_session_id", "block", "trial",
                            name=op.f("uq_haptic_trials_haptic_session_id_block_trial")),
    )
    with op.batch_alter_table("haptic_trials", schema=None) as batch_op:
        batch_op.create_index(
            batch_op.f("ix_haptic_trials_haptic_session_id"), ["haptic_session_id"],
            unique=False,
        )
    sessions = sa.table("haptic_sessions", sa.column("id", sa.Integer),
                        sa.column("stats_json", sa.Text))
    bind = op.get_bind()
    rows: list[dict[str, Any]] = []
    for sid, stats_json in bind.execute(sa.select(sessions.c.id, sessions.c.stats_json)):
        try:
            stats = json.loads(stats_json or "{}")
        except ValueError:
            continue  # an unreadable document stays as it is; it has no trial rows
        if isinstance(stats, dict):
            rows.extend(_abx_rows(int(sid), stats))
    if rows:
        op.bulk_insert(trials, rows)


def downgrade() -> None:
    with op.batch_alter_table("haptic_trials", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_haptic_trials_haptic_session_id"))
    op.drop_table("haptic_trials")
    with op.batch_alter_table("haptic_sessions", schema=None) as batch_op:
        batch_op.drop_column("patient_note")
