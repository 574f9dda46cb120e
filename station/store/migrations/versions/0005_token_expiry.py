"""API tokens that expire and are rotated: ``api_token.expires_at`` and ``replaced_by``.

Revision ID: 0005
Revises: 0004
Create Date: written by hand, matching ApiToken.expires_at / replaced_by in
station/store/models.py

``expires_at`` (NULL: never) ends a token; ``replaced_by`` names the token a rotation
made in its place (docs/security.md, Tokens). Tokens made before this revision keep
NULL in both: they never expire, as before. SQLite cannot add a foreign key or a check
constraint to a table in place, so the batch mode copies the (small) table there; on
PostgreSQL it is a plain ALTER TABLE. As in 0001, types and names are spelt out so
this revision keeps its meaning when the models move on.
"""

from alembic import op
import sqlalchemy as sa

revision = "0005"
down_revision = "0004"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("api_token") as batch:
        batch.add_column(sa.Column("expires_at", sa.DateTime(timezone=True), nullable=True))
        batch.add_column(sa.Column("replaced_by", sa.Integer(), nullable=True))
        batch.create_foreign_key(op.f("fk_api_token_replaced_by_api_token"), "api_token", ["replaced_by"], ["id"])
        batch.create_check_constraint(op.f("ck_api_token_replaced_token_expires"),
                                      "replaced_by IS NULL OR expires_at IS NOT NULL")


def downgrade() -> None:
    with op.batch_alter_table("api_token") as batch:
        batch.drop_constraint(op.f("ck_api_token_replaced_token_expires"), type_="check")
        batch.drop_constraint(op.f("fk_api_token_replaced_by_api_token"), type_="foreignkey")
        batch.drop_column("replaced_by")
        batch.drop_column("expires_at")
