"""Study lifecycle and the panel study link.

* ``studies.status``: ``draft``, ``open``, ``paused`` or ``closed`` (studies made before this
  revision are ``open``); ``studies.link_token``: the unguessable token of the study link
  (``/join/<token>``) that an online panel gives every participant;
* ``sessions.role``: ``participant``, ``pilot`` (left out of the analysis export unless asked
  for) or ``preview`` (the experimenter's look at the participant's view: never exported or
  counted); ``sessions.panel_id``: the panel's participant id of a session made through the
  study link, unique per study (one session per panel id, also under concurrent arrivals);
  ``sessions.speed``: the animation speed the session ran at; ``sessions.revoked_at``,
  ``sessions.ended_at``; ``sessions.quiz``: the comprehension quiz's attempts and outcome.

Revision ID: 0004
Revises: 0003
"""

import secrets

import sqlalchemy as sa
from alembic import context, op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None


def upgrade() -> None:
    # columns and unique indexes only: SQLite adds them in place (no table rebuilt under live foreign keys)
    op.add_column("studies", sa.Column("status", sa.String(8), nullable=False, server_default="open"))
    op.add_column("studies", sa.Column("link_token", sa.String(64), nullable=True))
    op.create_index("uq_study_link_token", "studies", ["link_token"], unique=True)
    op.add_column("sessions", sa.Column("role", sa.String(12), nullable=False, server_default="participant"))
    op.add_column("sessions", sa.Column("panel_id", sa.String(200), nullable=True))
    op.add_column("sessions", sa.Column("speed", sa.Float(), nullable=True))
    op.add_column("sessions", sa.Column("revoked_at", sa.DateTime(), nullable=True))
    op.add_column("sessions", sa.Column("ended_at", sa.DateTime(), nullable=True))
    op.add_column("sessions", sa.Column("quiz", sa.JSON(), nullable=True))
    op.create_index("uq_session_study_panel_id", "sessions", ["study_id", "panel_id"], unique=True)
    if not context.is_offline_mode():
        conn = op.get_bind()
        studies = sa.table("studies", sa.column("id", sa.String), sa.column("link_token", sa.String))
        for (sid,) in conn.execute(sa.select(studies.c.id)).all():
            conn.execute(studies.update().where(studies.c.id == sid).values(link_token=secrets.token_urlsafe(24)))


def downgrade() -> None:
    op.drop_index("uq_session_study_panel_id", "sessions")
    op.drop_index("uq_study_link_token", "studies")
    with op.batch_alter_table("sessions") as batch:
        for col in ("quiz", "ended_at", "revoked_at", "speed", "panel_id", "role"):
            batch.drop_column(col)
    with op.batch_alter_table("studies") as batch:
        batch.drop_column("link_token")
        batch.drop_column("status")
