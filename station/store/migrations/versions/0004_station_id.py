"""Station ids: many stations write one database (docs/plant.md).

Revision ID: 0004
Revises: 0003
Create Date: written by hand, matching Inspection.station_id and Event.station_id in
station/store/models.py

Every inspection and every event carries the id of the station that wrote it (the
config's ``station_id``). Rows written before this revision keep NULL: which station
made them is not known, and the store does not invent it. As in 0001, types and names
are spelt out so this revision keeps its meaning when the models move on.
"""

from alembic import op
import sqlalchemy as sa

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None


def upgrade() -> None:
    # plain ADD COLUMN (nullable, no constraint), which SQLite does in place
    op.add_column("inspection", sa.Column("station_id", sa.String(64), nullable=True))
    op.add_column("event", sa.Column("station_id", sa.String(64), nullable=True))
    op.create_index(op.f("ix_inspection_station_id_started_at"), "inspection", ["station_id", "started_at"])
    op.create_index(op.f("ix_event_station_id"), "event", ["station_id"])


def downgrade() -> None:
    op.drop_index(op.f("ix_event_station_id"), table_name="event")
    op.drop_index(op.f("ix_inspection_station_id_started_at"), table_name="inspection")
    with op.batch_alter_table("event") as batch:
        batch.drop_column("station_id")
    with op.batch_alter_table("inspection") as batch:
        batch.drop_column("station_id")
