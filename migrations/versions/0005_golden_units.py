"""golden units: their registered reference values and every check of a station against them

Revision ID: 0005
Revises: 0004
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = '0005'
down_revision = '0004'
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table('golden_units',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('serial', sa.String(length=100), nullable=False),
    sa.Column('version', sa.Integer(), nullable=False),
    sa.Column('registered_at', sa.DateTime(timezone=True), nullable=False),
    sa.Column('body', sa.Text(), nullable=False),
    sa.Column('sha256', sa.String(length=64), nullable=False),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_golden_units')),
    sa.UniqueConstraint('serial', 'version', name=op.f('uq_golden_units_serial'))
    )
    op.create_index('ix_golden_units_serial', 'golden_units', ['serial'], unique=False)
    op.create_table('golden_checks',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('run_unit_id', sa.Integer(), nullable=True),
    sa.Column('serial', sa.String(length=100), nullable=False),
    sa.Column('station', sa.String(length=100), nullable=False),
    sa.Column('golden_version', sa.Integer(), nullable=False),
    sa.Column('checked_at', sa.DateTime(timezone=True), nullable=False),
    sa.Column('passed', sa.Boolean(), nullable=False),
    sa.Column('body', sa.Text(), nullable=False),
    sa.ForeignKeyConstraint(['run_unit_id'], ['run_units.id'], name=op.f('fk_golden_checks_run_unit_id_run_units')),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_golden_checks'))
    )
    op.create_index('ix_golden_checks_run_unit_id', 'golden_checks', ['run_unit_id'], unique=False)
    op.create_index('ix_golden_checks_serial', 'golden_checks', ['serial'], unique=False)
    op.create_index('ix_golden_checks_station_time', 'golden_checks', ['station', 'checked_at'], unique=False)


def downgrade() -> None:
    op.drop_index('ix_golden_checks_station_time', table_name='golden_checks')
    op.drop_index('ix_golden_checks_serial', table_name='golden_checks')
    op.drop_index('ix_golden_checks_run_unit_id', table_name='golden_checks')
    op.drop_table('golden_checks')
    op.drop_index('ix_golden_units_serial', table_name='golden_units')
    op.drop_table('golden_units')
