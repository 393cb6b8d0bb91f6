"""The soak rack's recordings: a unit's rest from power-on, compressed, with its SHA-256, found by serial.

Revision ID: 0006
Revises: 0005
Create Date: 2026-11-28
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = '0006'
down_revision = '0005'
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table('rack_recordings',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('serial', sa.String(length=100), nullable=False),
    sa.Column('station', sa.String(length=100), nullable=False),
    sa.Column('slot', sa.Integer(), nullable=False),
    sa.Column('boot_count', sa.Integer(), nullable=True),
    sa.Column('wall_clock_at_start_s', sa.Float(), nullable=True),
    sa.Column('duration_s', sa.Float(), nullable=False),
    sa.Column('codec', sa.String(length=20), nullable=False),
    sa.Column('sha256', sa.String(length=64), nullable=False),
    sa.Column('size_bytes', sa.Integer(), nullable=False),
    sa.Column('data', sa.LargeBinary(), nullable=False),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_rack_recordings'))
    )
    op.create_index(op.f('ix_rack_recordings_serial'), 'rack_recordings', ['serial'], unique=False)


def downgrade() -> None:
    op.drop_index(op.f('ix_rack_recordings_serial'), table_name='rack_recordings')
    op.drop_table('rack_recordings')
