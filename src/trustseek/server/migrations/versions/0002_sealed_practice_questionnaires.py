"""Sealed outcomes, practice trials, questionnaires, online panels.

* ``sessions.secret``: the per-session secret that outcomes and scene layouts are drawn from
  (sessions made before this revision get a fresh one);
* ``sessions.panel``: an online panel's participant ids from the link's query;
* ``trials.practice``: practice trials, logged but left out of the analysis export;
* ``answers``: questionnaire items, one row per item.

Revision ID: 0002
Revises: 0001
"""

import secrets

import sqlalchemy as sa
from alembic import context, op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("sessions") as batch:
        batch.add_column(sa.Column("secret", sa.String(64), nullable=True))
        batch.add_column(sa.Column("panel", sa.JSON(), nullable=True))
    with op.batch_alter_table("trials") as batch:
        batch.add_column(sa.Column("practice", sa.Boolean(), nullable=False, server_default=sa.false()))
    if not context.is_offline_mode():  # the SQL script (alembic --sql) only alters the schema
        conn = op.get_bind()
        sessions = sa.table("sessions", sa.column("id", sa.String), sa.column("kind", sa.String), sa.column("secret", sa.String))
        for (sid,) in conn.execute(sa.select(sessions.c.id).where(sessions.c.kind == "study")).all():
            conn.execute(sessions.update().where(sessions.c.id == sid).values(secret=secrets.token_hex(16)))
    op.create_table(
        "answers",
        sa.Column("id", sa.Integer(), primary_key=True, autoincrement=True),
        sa.Column("session_id", sa.String(32), sa.ForeignKey("sessions.id"), nullable=False),
        sa.Column("questionnaire", sa.String(100), nullable=False),
        sa.Column("when", sa.String(8), nullable=False),
        sa.Column("after_trial", sa.Integer(), nullable=False),
        sa.Column("block", sa.Integer(), nullable=False),
        sa.Column("item", sa.String(100), nullable=False),
        sa.Column("value", sa.Float(), nullable=False),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.UniqueConstraint("session_id", "questionnaire", "after_trial", "item", name="uq_answer"),
    )
    op.create_index("ix_answers_session_id", "answers", ["session_id"])


def downgrade() -> None:
    op.drop_table("answers")
    with op.batch_alter_table("trials") as batch:
        batch.drop_column("practice")
    with op.batch_alter_table("sessions") as batch:
        batch.drop_column("panel")
        batch.drop_column("secret")
