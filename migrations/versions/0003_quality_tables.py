"""Quality analytics: the production lot of a run, and the narrow, indexed quality tables (results, values,
daily sums per parameter, yield counts per quarter hour) that yield, capability and control charts aggregate
in SQL. Existing records are indexed here (station.store.quality_index.rebuild), so an old database has its statistics at once.

Revision ID: 0003
Revises: 0002
Create Date: 2026-11-24
"""

from __future__ import annotations

import sqlite3

import sqlalchemy as sa
from alembic import op

revision = '0003'
down_revision = '0002'
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table('runs') as batch:
        batch.add_column(sa.Column('lot', sa.String(length=100), server_default='', nullable=False))
    op.create_table('quality_parameters',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('name', sa.String(length=100), nullable=False),
    sa.Column('unit', sa.String(length=20), nullable=False),
    sa.Column('ref', sa.Float(), nullable=False),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_quality_parameters')),
    sa.UniqueConstraint('name', name=op.f('uq_quality_parameters_name'))
    )
    op.create_table('quality_results',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('run_unit_id', sa.Integer(), nullable=False),
    sa.Column('unit_id', sa.Integer(), nullable=False),
    sa.Column('station_id', sa.Integer(), nullable=False),
    sa.Column('lot', sa.String(length=100), nullable=False),
    sa.Column('limits_version', sa.String(length=100), nullable=False),
    sa.Column('started_at', sa.DateTime(timezone=True), nullable=False),
    sa.Column('day', sa.String(length=10), nullable=False),
    sa.Column('minute', sa.Integer(), nullable=False),
    sa.Column('outcome', sa.String(length=16), nullable=False),
    sa.Column('tested', sa.Boolean(), nullable=False),
    sa.Column('attempt', sa.Integer(), nullable=False),
    sa.Column('final_outcome', sa.String(length=16), nullable=False),
    sa.Column('latest', sa.Boolean(), nullable=False),
    sa.ForeignKeyConstraint(['run_unit_id'], ['run_units.id'], name=op.f('fk_quality_results_run_unit_id_run_units')),
    sa.ForeignKeyConstraint(['station_id'], ['stations.id'], name=op.f('fk_quality_results_station_id_stations')),
    sa.ForeignKeyConstraint(['unit_id'], ['units.id'], name=op.f('fk_quality_results_unit_id_units')),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_quality_results')),
    sa.UniqueConstraint('run_unit_id', name=op.f('uq_quality_results_run_unit_id'))
    )
    op.create_index('ix_quality_results_day_station', 'quality_results', ['day', 'station_id'], unique=False)
    op.create_index('ix_quality_results_unit_latest', 'quality_results', ['unit_id', 'latest'], unique=False)
    op.create_index('ix_quality_results_groups', 'quality_results',
                    ['day', 'minute', 'station_id', 'lot', 'limits_version', 'tested', 'attempt', 'outcome',
                     'final_outcome',
                     'unit_id'], unique=False)
    op.create_index(op.f('ix_quality_results_lot'), 'quality_results', ['lot'], unique=False)
    op.create_index(op.f('ix_quality_results_started_at'), 'quality_results', ['started_at'], unique=False)
    op.create_table('quality_values',
    sa.Column('result_id', sa.Integer(), nullable=False),
    sa.Column('param_id', sa.Integer(), nullable=False),
    sa.Column('day', sa.String(length=10), nullable=False),
    sa.Column('value', sa.Float(), nullable=False),
    sa.ForeignKeyConstraint(['param_id'], ['quality_parameters.id'],
                            name=op.f('fk_quality_values_param_id_quality_parameters')),
    sa.ForeignKeyConstraint(['result_id'], ['quality_results.id'],
                            name=op.f('fk_quality_values_result_id_quality_results')),
    sa.PrimaryKeyConstraint('result_id', 'param_id', name=op.f('pk_quality_values'))
    )
    op.create_index('ix_quality_values_param_day', 'quality_values', ['param_id', 'day', 'value'], unique=False)
    op.create_table('quality_daily',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('param_id', sa.Integer(), nullable=False),
    sa.Column('day', sa.String(length=10), nullable=False),
    sa.Column('station_id', sa.Integer(), nullable=False),
    sa.Column('lot', sa.String(length=100), nullable=False),
    sa.Column('limits_version', sa.String(length=100), nullable=False),
    sa.Column('n', sa.Integer(), nullable=False),
    sa.Column('s1', sa.Float(), nullable=False),
    sa.Column('s2', sa.Float(), nullable=False),
    sa.Column('vmin', sa.Float(), nullable=False),
    sa.Column('vmax', sa.Float(), nullable=False),
    sa.Column('low', sa.Float(), nullable=True),
    sa.Column('high', sa.Float(), nullable=True),
    sa.Column('n_below', sa.Integer(), nullable=False),
    sa.Column('n_above', sa.Integer(), nullable=False),
    sa.ForeignKeyConstraint(['param_id'], ['quality_parameters.id'],
                            name=op.f('fk_quality_daily_param_id_quality_parameters')),
    sa.ForeignKeyConstraint(['station_id'], ['stations.id'], name=op.f('fk_quality_daily_station_id_stations')),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_quality_daily')),
    sa.UniqueConstraint('param_id', 'day', 'station_id', 'lot', 'limits_version', name='uq_quality_daily_group')
    )
    op.create_index('ix_quality_daily_day', 'quality_daily', ['day'], unique=False)
    op.create_table('quality_yield',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('day', sa.String(length=10), nullable=False),
    sa.Column('quarter', sa.Integer(), nullable=False),
    sa.Column('station_id', sa.Integer(), nullable=False),
    sa.Column('lot', sa.String(length=100), nullable=False),
    sa.Column('limits_version', sa.String(length=100), nullable=False),
    sa.Column('results', sa.Integer(), nullable=False),
    sa.Column('not_tested', sa.Integer(), nullable=False),
    sa.Column('tested', sa.Integer(), nullable=False),
    sa.Column('first_tested', sa.Integer(), nullable=False),
    sa.Column('first_pass', sa.Integer(), nullable=False),
    sa.Column('final_pass', sa.Integer(), nullable=False),
    sa.Column('retests', sa.Integer(), nullable=False),
    sa.ForeignKeyConstraint(['station_id'], ['stations.id'], name=op.f('fk_quality_yield_station_id_stations')),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_quality_yield')),
    sa.UniqueConstraint('day', 'quarter', 'station_id', 'lot', 'limits_version', name='uq_quality_yield_group')
    )
    from station.store.quality_index import rebuild

    rebuild(op.get_bind())


def downgrade() -> None:
    op.drop_table('quality_yield')
    op.drop_index('ix_quality_daily_day', table_name='quality_daily')
    op.drop_table('quality_daily')
    op.drop_index('ix_quality_values_param_day', table_name='quality_values')
    op.drop_table('quality_values')
    for ix in ('ix_quality_results_started_at', 'ix_quality_results_lot', 'ix_quality_results_groups',
               'ix_quality_results_unit_latest', 'ix_quality_results_day_station'):
        op.drop_index(ix, table_name='quality_results')
    op.drop_table('quality_results')
    op.drop_table('quality_parameters')
    if op.get_bind().dialect.name == 'sqlite' and sqlite3.sqlite_version_info >= (3, 35):
        # in place: a batch copy of runs would drop a table that run_units refers to (foreign keys are on)
        op.execute('ALTER TABLE runs DROP COLUMN lot')
    else:
        with op.batch_alter_table('runs') as batch:
            batch.drop_column('lot')
