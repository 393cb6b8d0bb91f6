"""Provisioning and conformance: EEPROM writes record written / read back / verified on the rig and the
image bytes; limit checks record their verdict and coverage factor; rig locks (one run per rig).

Revision ID: 0002
Revises: 0001
Create Date: 2026-11-24
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = '0002'
down_revision = '0001'
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table('eeprom_writes') as batch:
        batch.add_column(sa.Column('written', sa.Boolean(), server_default=sa.true(), nullable=False))
        batch.add_column(sa.Column('read_back_ok', sa.Boolean(), server_default=sa.true(), nullable=False))
        batch.add_column(sa.Column('verified_on_rig', sa.Boolean(), nullable=True))
        batch.add_column(sa.Column('image', sa.LargeBinary(), nullable=True))
    with op.batch_alter_table('limit_checks') as batch:
        batch.add_column(sa.Column('verdict', sa.String(length=12), nullable=True))
        batch.add_column(sa.Column('k', sa.Float(), nullable=True))
    op.create_table('rig_locks',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('rig_url', sa.String(length=300), nullable=False),
    sa.Column('station', sa.String(length=100), nullable=False),
    sa.Column('host', sa.String(length=255), nullable=False),
    sa.Column('pid', sa.Integer(), nullable=False),
    sa.Column('since', sa.DateTime(timezone=True), nullable=False),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_rig_locks')),
    sa.UniqueConstraint('rig_url', name=op.f('uq_rig_locks_rig_url'))
    )


def downgrade() -> None:
    op.drop_table('rig_locks')
    with op.batch_alter_table('limit_checks') as batch:
        batch.drop_column('k')
        batch.drop_column('verdict')
    with op.batch_alter_table('eeprom_writes') as batch:
        batch.drop_column('image')
        batch.drop_column('verified_on_rig')
        batch.drop_column('read_back_ok')
        batch.drop_column('written')
