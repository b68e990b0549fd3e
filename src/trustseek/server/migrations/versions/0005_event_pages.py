"""The page load of every UI event.

* ``events.page``: the random id a participant's page makes when it opens; a reload or a second
  tab of the same session makes another, so that the events of two page loads can be told apart
  (empty for events stored before this revision, and for events posted without it).

Revision ID: 0005
Revises: 0004
"""

import sqlalchemy as sa
from alembic import op

revision = "0005"
down_revision = "0004"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.add_column("events", sa.Column("page", sa.String(32), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("events") as batch:
        batch.drop_column("page")
