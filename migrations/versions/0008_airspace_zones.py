"""airspace zones: organisation zones and per-base operating areas (issue 20)

Revision ID: 0008
Revises: 0007
Create Date: 2026-11-25
"""

import sqlalchemy as sa
from alembic import op

revision = "0008"
down_revision = "0007"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "airspace_zones",
        sa.Column("organization_id", sa.Uuid(), nullable=False),
        sa.Column("base_id", sa.Uuid(), nullable=True),
        sa.Column("name", sa.String(length=100), nullable=False),
        sa.Column("description", sa.String(length=2000), nullable=False),
        sa.Column(
            "kind",
            sa.Enum("inclusion", "exclusion", name="zone_kind", native_enum=False, length=16),
            nullable=False,
        ),
        sa.Column("geometry", sa.JSON(), nullable=False),
        sa.Column("radius_m", sa.Float(), nullable=True),
        sa.Column("floor_m", sa.Float(), nullable=True),
        sa.Column("ceiling_m", sa.Float(), nullable=True),
        sa.Column(
            "altitude_ref",
            sa.Enum("base", "amsl", name="altitude_ref", native_enum=False, length=8),
            nullable=False,
        ),
        sa.Column("windows", sa.JSON(), nullable=True),
        sa.Column("created_by", sa.String(length=64), nullable=True),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("updated_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("id", sa.Uuid(), nullable=False),
        sa.ForeignKeyConstraint(
            ["base_id"],
            ["assets.id"],
            name=op.f("fk_airspace_zones_base_id_assets"),
            ondelete="CASCADE",
        ),
        sa.ForeignKeyConstraint(
            ["organization_id"],
            ["organizations.id"],
            name=op.f("fk_airspace_zones_organization_id_organizations"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_airspace_zones")),
    )
    with op.batch_alter_table("airspace_zones") as batch:
        batch.create_index(batch.f("ix_airspace_zones_organization_id"), ["organization_id"])
        batch.create_index(batch.f("ix_airspace_zones_base_id"), ["base_id"])


def downgrade() -> None:
    with op.batch_alter_table("airspace_zones") as batch:
        batch.drop_index(batch.f("ix_airspace_zones_base_id"))
        batch.drop_index(batch.f("ix_airspace_zones_organization_id"))
    op.drop_table("airspace_zones")
