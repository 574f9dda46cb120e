"""The whole-surface inspection: ``inspection.surface``, the coverage scan's document.

Revision ID: 0006
Revises: 0005
Create Date: written by hand, matching Inspection.surface in station/store/models.py

``surface`` holds what the coverage scan of the bore wall found (the defects, with
place, size and uncertainty, and the meta of the unrolled picture: docs/surface.md);
the picture itself is an image of the record (``image_crop``, subject ``surface``).
Inspections recorded before this revision, and those whose part spec asks for no
surface inspection, keep NULL. As in 0001, types and names are spelt out so this
revision keeps its meaning when the models move on.
"""

from alembic import op
import sqlalchemy as sa
from sqlalchemy.dialects.postgresql import JSONB

revision = "0006"
down_revision = "0005"
branch_labels = None
depends_on = None

_JSON = sa.JSON().with_variant(JSONB(), "postgresql")


def upgrade() -> None:
    # plain ADD COLUMN (nullable, no constraint), which SQLite does in place: the store
    # checks the document before writing it
    op.add_column("inspection", sa.Column("surface", _JSON, nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("inspection") as batch:
        batch.drop_column("surface")
