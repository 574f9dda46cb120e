"""Findings of a scan (unexpected holes, unresolved identities, the part's angular
datum) and the inspection's machine time.

Revision ID: 0003
Revises: 0002
Create Date: written by hand, matching Finding and Inspection.machine_s / cycle in
station/store/models.py

As in 0001, types and names are spelt out so this revision keeps its meaning when the
models move on.
"""

from alembic import op
import sqlalchemy as sa
from sqlalchemy.dialects.postgresql import JSONB

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None

_JSON = sa.JSON().with_variant(JSONB(), "postgresql")


def upgrade() -> None:
    # plain ADD COLUMN (no constraint), which SQLite does in place: the store checks
    # the value before writing it
    op.add_column("inspection", sa.Column("machine_s", sa.Float(), nullable=True))
    op.add_column("inspection", sa.Column("cycle", _JSON, nullable=True))
    op.create_table(
        "finding",
        sa.Column("id", sa.Integer(), autoincrement=True, nullable=False),
        sa.Column("inspection_id", sa.String(36), nullable=False),
        sa.Column("kind", sa.String(32), nullable=False),
        sa.Column("message", sa.Text(), nullable=False),
        sa.Column("subject", sa.String(64), nullable=True),
        sa.Column("axial_mm", sa.Float(), nullable=True),
        sa.Column("angle_deg", sa.Float(), nullable=True),
        sa.Column("diameter_mm", sa.Float(), nullable=True),
        sa.Column("u_mm", sa.Float(), nullable=True),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_finding")),
        sa.ForeignKeyConstraint(["inspection_id"], ["inspection.id"], name=op.f("fk_finding_inspection_id_inspection")),
        sa.CheckConstraint("kind IN ('unexpected_hole', 'ambiguous_identity', 'datum')", name=op.f("ck_finding_kind")),
    )
    op.create_index(op.f("ix_finding_inspection_id"), "finding", ["inspection_id"])


def downgrade() -> None:
    op.drop_index(op.f("ix_finding_inspection_id"), table_name="finding")
    op.drop_table("finding")
    with op.batch_alter_table("inspection") as batch:
        batch.drop_column("cycle")
        batch.drop_column("machine_s")
