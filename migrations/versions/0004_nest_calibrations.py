"""nest calibrations: each rig's nest mounting errors, versioned per rig

Revision ID: 0004
Revises: 0003
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = '0004'
down_revision = '0003'
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table('nest_calibrations',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('rig', sa.String(length=300), nullable=False),
    sa.Column('version', sa.Integer(), nullable=False),
    sa.Column('reference_serial', sa.String(length=100), nullable=False),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.Column('format', sa.String(length=40), nullable=False),
    sa.Column('body', sa.Text(), nullable=False),
    sa.Column('sha256', sa.String(length=64), nullable=False),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_nest_calibrations')),
    sa.UniqueConstraint('rig', 'version', name=op.f('uq_nest_calibrations_rig'))
    )
    op.create_index('ix_nest_calibrations_rig', 'nest_calibrations', ['rig'], unique=False)


def downgrade() -> None:
    op.drop_index('ix_nest_calibrations_rig', table_name='nest_calibrations')
    op.drop_table('nest_calibrations')
