"""Initial schema: stations, fixture slots, units, runs, steps, limit checks, parameter sets,
session recordings, EEPROM writes, dispositions (see station/store/models.py).

Revision ID: 0001
Revises:
Create Date: 2026-11-21
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = '0001'
down_revision = None
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table('stations',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('name', sa.String(length=100), nullable=False),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_stations')),
    sa.UniqueConstraint('name', name=op.f('uq_stations_name'))
    )
    op.create_table('units',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('serial', sa.String(length=100), nullable=False),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_units')),
    sa.UniqueConstraint('serial', name=op.f('uq_units_serial'))
    )
    op.create_table('dispositions',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('unit_id', sa.Integer(), nullable=False),
    sa.Column('decision', sa.String(length=50), nullable=False),
    sa.Column('operator', sa.String(length=100), nullable=False),
    sa.Column('note', sa.Text(), nullable=False),
    sa.Column('decided_at', sa.DateTime(timezone=True), nullable=False),
    sa.ForeignKeyConstraint(['unit_id'], ['units.id'], name=op.f('fk_dispositions_unit_id_units')),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_dispositions'))
    )
    op.create_index(op.f('ix_dispositions_unit_id'), 'dispositions', ['unit_id'], unique=False)
    op.create_table('fixture_slots',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('station_id', sa.Integer(), nullable=False),
    sa.Column('slot', sa.Integer(), nullable=False),
    sa.Column('sensor_url', sa.String(length=500), nullable=False),
    sa.ForeignKeyConstraint(['station_id'], ['stations.id'], name=op.f('fk_fixture_slots_station_id_stations')),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_fixture_slots')),
    sa.UniqueConstraint('station_id', 'slot', name=op.f('uq_fixture_slots_station_id'))
    )
    op.create_index(op.f('ix_fixture_slots_station_id'), 'fixture_slots', ['station_id'], unique=False)
    op.create_table('runs',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('run_uid', sa.String(length=100), nullable=False),
    sa.Column('station_id', sa.Integer(), nullable=False),
    sa.Column('outcome', sa.String(length=16), nullable=False),
    sa.Column('started_at', sa.DateTime(timezone=True), nullable=False),
    sa.Column('finished_at', sa.DateTime(timezone=True), nullable=True),
    sa.Column('duration_s', sa.Float(), nullable=True),
    sa.Column('wall_s', sa.Float(), nullable=True),
    sa.Column('software_version', sa.String(length=100), nullable=False),
    sa.Column('sequence_version', sa.String(length=100), nullable=False),
    sa.Column('sequence_hash', sa.String(length=64), nullable=False),
    sa.Column('limits_version', sa.String(length=100), nullable=False),
    sa.Column('limits_hash', sa.String(length=64), nullable=False),
    sa.Column('operator', sa.String(length=100), nullable=False),
    sa.Column('rig', sa.String(length=200), nullable=False),
    sa.Column('host', sa.String(length=200), nullable=False),
    sa.Column('pid', sa.Integer(), nullable=False),
    sa.Column('rig_at_rest', sa.Boolean(), nullable=True),
    sa.Column('message', sa.Text(), nullable=False),
    sa.ForeignKeyConstraint(['station_id'], ['stations.id'], name=op.f('fk_runs_station_id_stations')),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_runs')),
    sa.UniqueConstraint('run_uid', name=op.f('uq_runs_run_uid'))
    )
    op.create_index(op.f('ix_runs_outcome'), 'runs', ['outcome'], unique=False)
    op.create_index(op.f('ix_runs_station_id'), 'runs', ['station_id'], unique=False)
    op.create_table('run_units',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('run_id', sa.Integer(), nullable=False),
    sa.Column('slot', sa.Integer(), nullable=False),
    sa.Column('sensor_url', sa.String(length=500), nullable=False),
    sa.Column('unit_id', sa.Integer(), nullable=True),
    sa.Column('outcome', sa.String(length=16), nullable=False),
    sa.Column('message', sa.Text(), nullable=False),
    sa.ForeignKeyConstraint(['run_id'], ['runs.id'], name=op.f('fk_run_units_run_id_runs')),
    sa.ForeignKeyConstraint(['unit_id'], ['units.id'], name=op.f('fk_run_units_unit_id_units')),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_run_units')),
    sa.UniqueConstraint('run_id', 'slot', name=op.f('uq_run_units_run_id'))
    )
    op.create_index(op.f('ix_run_units_run_id'), 'run_units', ['run_id'], unique=False)
    op.create_index(op.f('ix_run_units_unit_id'), 'run_units', ['unit_id'], unique=False)
    op.create_table('step_timings',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('run_id', sa.Integer(), nullable=False),
    sa.Column('step_index', sa.Integer(), nullable=False),
    sa.Column('name', sa.String(length=100), nullable=False),
    sa.Column('kind', sa.String(length=20), nullable=False),
    sa.Column('hold_s', sa.Float(), nullable=False),
    sa.Column('started_t_s', sa.Float(), nullable=False),
    sa.Column('duration_s', sa.Float(), nullable=True),
    sa.Column('ok', sa.Boolean(), nullable=True),
    sa.Column('units_active', sa.Integer(), nullable=True),
    sa.Column('message', sa.Text(), nullable=False),
    sa.ForeignKeyConstraint(['run_id'], ['runs.id'], name=op.f('fk_step_timings_run_id_runs')),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_step_timings')),
    sa.UniqueConstraint('run_id', 'step_index', name=op.f('uq_step_timings_run_id'))
    )
    op.create_index(op.f('ix_step_timings_run_id'), 'step_timings', ['run_id'], unique=False)
    op.create_table('eeprom_writes',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('run_unit_id', sa.Integer(), nullable=True),
    sa.Column('unit_id', sa.Integer(), nullable=False),
    sa.Column('image_sha256', sa.String(length=64), nullable=False),
    sa.Column('layout_version', sa.Integer(), nullable=False),
    sa.Column('attempts', sa.Integer(), nullable=False),
    sa.Column('verified', sa.Boolean(), nullable=False),
    sa.Column('message', sa.Text(), nullable=False),
    sa.Column('written_at', sa.DateTime(timezone=True), nullable=False),
    sa.ForeignKeyConstraint(['run_unit_id'], ['run_units.id'], name=op.f('fk_eeprom_writes_run_unit_id_run_units')),
    sa.ForeignKeyConstraint(['unit_id'], ['units.id'], name=op.f('fk_eeprom_writes_unit_id_units')),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_eeprom_writes'))
    )
    op.create_index(op.f('ix_eeprom_writes_run_unit_id'), 'eeprom_writes', ['run_unit_id'], unique=False)
    op.create_index(op.f('ix_eeprom_writes_unit_id'), 'eeprom_writes', ['unit_id'], unique=False)
    op.create_table('limit_checks',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('run_unit_id', sa.Integer(), nullable=False),
    sa.Column('step', sa.String(length=100), nullable=False),
    sa.Column('name', sa.String(length=100), nullable=False),
    sa.Column('value', sa.Float(), nullable=True),
    sa.Column('low', sa.Float(), nullable=True),
    sa.Column('high', sa.Float(), nullable=True),
    sa.Column('std', sa.Float(), nullable=True),
    sa.Column('unit', sa.String(length=20), nullable=False),
    sa.Column('passed', sa.Boolean(), nullable=False),
    sa.ForeignKeyConstraint(['run_unit_id'], ['run_units.id'], name=op.f('fk_limit_checks_run_unit_id_run_units')),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_limit_checks'))
    )
    op.create_index(op.f('ix_limit_checks_run_unit_id'), 'limit_checks', ['run_unit_id'], unique=False)
    op.create_table('parameter_sets',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('run_unit_id', sa.Integer(), nullable=False),
    sa.Column('unit_id', sa.Integer(), nullable=False),
    sa.Column('format', sa.String(length=50), nullable=False),
    sa.Column('sha256', sa.String(length=64), nullable=False),
    sa.Column('params_json', sa.Text(), nullable=False),
    sa.Column('uncertainties_json', sa.Text(), nullable=False),
    sa.Column('path', sa.String(length=1000), nullable=False),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.ForeignKeyConstraint(['run_unit_id'], ['run_units.id'], name=op.f('fk_parameter_sets_run_unit_id_run_units')),
    sa.ForeignKeyConstraint(['unit_id'], ['units.id'], name=op.f('fk_parameter_sets_unit_id_units')),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_parameter_sets'))
    )
    op.create_index(op.f('ix_parameter_sets_run_unit_id'), 'parameter_sets', ['run_unit_id'], unique=False)
    op.create_index(op.f('ix_parameter_sets_unit_id'), 'parameter_sets', ['unit_id'], unique=False)
    op.create_table('session_recordings',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('run_unit_id', sa.Integer(), nullable=False),
    sa.Column('path', sa.String(length=1000), nullable=False),
    sa.Column('sha256', sa.String(length=64), nullable=False),
    sa.Column('size_bytes', sa.Integer(), nullable=False),
    sa.ForeignKeyConstraint(['run_unit_id'], ['run_units.id'], name=op.f('fk_session_recordings_run_unit_id_run_units')),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_session_recordings'))
    )
    op.create_index(op.f('ix_session_recordings_run_unit_id'), 'session_recordings', ['run_unit_id'], unique=False)


def downgrade() -> None:
    op.drop_index(op.f('ix_session_recordings_run_unit_id'), table_name='session_recordings')
    op.drop_table('session_recordings')
    op.drop_index(op.f('ix_parameter_sets_unit_id'), table_name='parameter_sets')
    op.drop_index(op.f('ix_parameter_sets_run_unit_id'), table_name='parameter_sets')
    op.drop_table('parameter_sets')
    op.drop_index(op.f('ix_limit_checks_run_unit_id'), table_name='limit_checks')
    op.drop_table('limit_checks')
    op.drop_index(op.f('ix_eeprom_writes_unit_id'), table_name='eeprom_writes')
    op.drop_index(op.f('ix_eeprom_writes_run_unit_id'), table_name='eeprom_writes')
    op.drop_table('eeprom_writes')
    op.drop_index(op.f('ix_step_timings_run_id'), table_name='step_timings')
    op.drop_table('step_timings')
    op.drop_index(op.f('ix_run_units_unit_id'), table_name='run_units')
    op.drop_index(op.f('ix_run_units_run_id'), table_name='run_units')
    op.drop_table('run_units')
    op.drop_index(op.f('ix_runs_station_id'), table_name='runs')
    op.drop_index(op.f('ix_runs_outcome'), table_name='runs')
    op.drop_table('runs')
    op.drop_index(op.f('ix_fixture_slots_station_id'), table_name='fixture_slots')
    op.drop_table('fixture_slots')
    op.drop_index(op.f('ix_dispositions_unit_id'), table_name='dispositions')
    op.drop_table('dispositions')
    op.drop_table('units')
    op.drop_table('stations')
