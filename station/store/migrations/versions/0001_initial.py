"""Initial schema: inspection, characteristic_result, image_crop, event.

Revision ID: 0001
Revises:
Create Date: written by hand, matching station/store/models.py at the store's first version

Types and constraint names are spelt out here (``op.f`` marks a name as final, so
the models' naming convention is not applied to it a second time) rather than imported from the models,
so that this revision keeps meaning what it meant when the models move on.
"""

from alembic import op
import sqlalchemy as sa
from sqlalchemy.dialects.postgresql import JSONB

revision = "0001"
down_revision = None
branch_labels = None
depends_on = None

_STATES = "'running', 'complete', 'aborted', 'faulted', 'interrupted'"
_JSON = sa.JSON().with_variant(JSONB(), "postgresql")


def upgrade() -> None:
    op.create_table(
        "inspection",
        sa.Column("id", sa.String(36), nullable=False),
        sa.Column("part_number", sa.String(64), nullable=False),
        sa.Column("serial", sa.String(64), nullable=True),
        sa.Column("order_id", sa.String(64), nullable=True),
        sa.Column("state", sa.String(16), nullable=False),
        sa.Column("result", sa.String(8), nullable=True),
        sa.Column("reason", sa.Text(), nullable=True),
        sa.Column("started_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("finished_at", sa.DateTime(timezone=True), nullable=True),
        sa.Column("traceability", _JSON, nullable=False),
        sa.Column("idempotency_key", sa.String(128), nullable=True),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_inspection")),
        sa.UniqueConstraint("idempotency_key", name=op.f("uq_inspection_idempotency_key")),
        sa.CheckConstraint(f"state IN ({_STATES})", name=op.f("ck_inspection_state")),
        sa.CheckConstraint("result IS NULL OR result IN ('pass', 'fail')", name=op.f("ck_inspection_result")),
        sa.CheckConstraint("(state = 'complete') = (result IS NOT NULL)", name=op.f("ck_inspection_result_iff_complete")),
        sa.CheckConstraint("(state = 'running') = (finished_at IS NULL)",
                           name=op.f("ck_inspection_finished_iff_not_running")),
    )
    op.create_index(op.f("ix_inspection_started_at"), "inspection", ["started_at"])
    op.create_index(op.f("ix_inspection_part_number_started_at"), "inspection", ["part_number", "started_at"])
    op.create_index(op.f("ix_inspection_serial"), "inspection", ["serial"])
    op.create_index(op.f("ix_inspection_state"), "inspection", ["state"])

    op.create_table(
        "characteristic_result",
        sa.Column("id", sa.Integer(), autoincrement=True, nullable=False),
        sa.Column("inspection_id", sa.String(36), nullable=False),
        sa.Column("characteristic_id", sa.String(64), nullable=False),
        sa.Column("unit", sa.String(16), nullable=False),
        sa.Column("nominal", sa.Float(), nullable=False),
        sa.Column("lower_limit", sa.Float(), nullable=False),
        sa.Column("upper_limit", sa.Float(), nullable=False),
        sa.Column("measured", sa.Float(), nullable=True),
        sa.Column("uncertainty_k2", sa.Float(), nullable=True),
        sa.Column("passed", sa.Boolean(), nullable=False),
        sa.Column("true_value", sa.Float(), nullable=True),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_characteristic_result")),
        sa.ForeignKeyConstraint(["inspection_id"], ["inspection.id"],
                                name=op.f("fk_characteristic_result_inspection_id_inspection")),
        sa.UniqueConstraint("inspection_id", "characteristic_id",
                            name=op.f("uq_characteristic_result_inspection_id_characteristic_id")),
        sa.CheckConstraint("lower_limit < upper_limit", name=op.f("ck_characteristic_result_limits_ordered")),
        sa.CheckConstraint("uncertainty_k2 IS NULL OR uncertainty_k2 >= 0",
                           name=op.f("ck_characteristic_result_uncertainty_non_negative")),
        sa.CheckConstraint("measured IS NOT NULL OR NOT passed", name=op.f("ck_characteristic_result_unmeasured_fails")),
    )

    op.create_table(
        "image_crop",
        sa.Column("id", sa.Integer(), autoincrement=True, nullable=False),
        sa.Column("inspection_id", sa.String(36), nullable=False),
        sa.Column("subject", sa.String(64), nullable=False),
        sa.Column("path", sa.String(512), nullable=False),
        sa.Column("sha256", sa.String(64), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_image_crop")),
        sa.ForeignKeyConstraint(["inspection_id"], ["inspection.id"], name=op.f("fk_image_crop_inspection_id_inspection")),
        sa.UniqueConstraint("path", name=op.f("uq_image_crop_path")),
    )
    op.create_index(op.f("ix_image_crop_inspection_id"), "image_crop", ["inspection_id"])

    op.create_table(
        "event",
        sa.Column("id", sa.Integer(), autoincrement=True, nullable=False),
        sa.Column("inspection_id", sa.String(36), nullable=True),
        sa.Column("at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("kind", sa.String(32), nullable=False),
        sa.Column("message", sa.Text(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_event")),
        sa.ForeignKeyConstraint(["inspection_id"], ["inspection.id"], name=op.f("fk_event_inspection_id_inspection")),
    )
    op.create_index(op.f("ix_event_inspection_id"), "event", ["inspection_id"])
    op.create_index(op.f("ix_event_at"), "event", ["at"])


def downgrade() -> None:
    for table in ("event", "image_crop", "characteristic_result"):
        op.drop_table(table)
    for index in ("ix_inspection_state", "ix_inspection_serial", "ix_inspection_part_number_started_at",
                  "ix_inspection_started_at"):
        op.drop_index(index, table_name=op.f("inspection"))
    op.drop_table("inspection")
