"""Write-ahead provisioning: an EEPROM write is committed as an intent (state 'intended', the image's hash,
the target slot and update count) before the first page goes to the unit and completed after the read-back;
an intent left open by a crash is reconciled against the unit (state 'complete' or 'not-applied').
Rows of older versions were recorded after the fact: they are 'complete'.

Revision ID: 0007
Revises: 0006
Create Date: 2026-11-28
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = '0007'
down_revision = '0006'
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table('eeprom_writes') as batch:
        batch.add_column(sa.Column('state', sa.String(length=16), server_default='complete', nullable=False))
        batch.add_column(sa.Column('slot_name', sa.String(length=4), server_default='', nullable=False))
        batch.add_column(sa.Column('update_count', sa.Integer(), nullable=True))
        batch.add_column(sa.Column('intended_at', sa.DateTime(timezone=True), nullable=True))
        batch.add_column(sa.Column('completed_at', sa.DateTime(timezone=True), nullable=True))
        batch.add_column(sa.Column('reconciled', sa.Text(), server_default='', nullable=False))
        batch.create_index(batch.f('ix_eeprom_writes_state'), ['state'], unique=False)


def downgrade() -> None:
    with op.batch_alter_table('eeprom_writes') as batch:
        batch.drop_index(batch.f('ix_eeprom_writes_state'))
        batch.drop_column('reconciled')
        batch.drop_column('completed_at')
        batch.drop_column('intended_at')
        batch.drop_column('update_count')
        batch.drop_column('slot_name')
        batch.drop_column('state')
