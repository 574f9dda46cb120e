"""API tokens: hashed REST API tokens with a role.

Revision ID: 0002
Revises: 0001
Create Date: written by hand, matching ApiToken in station/store/models.py

As in 0001, types and names are spelt out so this revision keeps its meaning when the
models move on.
"""

from alembic import op
import sqlalchemy as sa

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "api_token",
        sa.Column("id", sa.Integer(), autoincrement=True, nullable=False),
        sa.Column("name", sa.String(64), nullable=False),
        sa.Column("role", sa.String(16), nullable=False),
        sa.Column("prefix", sa.String(16), nullable=False),
        sa.Column("salt", sa.String(64), nullable=False),
        sa.Column("token_hash", sa.String(128), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("revoked_at", sa.DateTime(timezone=True), nullable=True),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_api_token")),
        sa.UniqueConstraint("prefix", name=op.f("uq_api_token_prefix")),
        sa.CheckConstraint("role IN ('mes', 'operator', 'engineer', 'admin')", name=op.f("ck_api_token_role")),
    )


def downgrade() -> None:
    op.drop_table("api_token")
