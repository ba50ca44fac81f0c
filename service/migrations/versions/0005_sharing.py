"""sharing: each motion's stored size (per-key storage quota) and an index for per-key job counts

Revision ID: 0005
Revises: 0004
Create Date: 2026-12-07 04:00:00
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = '0005'
down_revision = '0004'
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table('motions') as batch:
        batch.add_column(sa.Column('size', sa.Integer(), nullable=False, server_default='0'))
    op.execute("UPDATE motions SET size = length(data)")
    op.create_index('ix_jobs_owner_status', 'jobs', ['owner', 'status'], unique=False)
    op.create_index('ix_motions_parent', 'motions', ['parent_id'], unique=False)


def downgrade() -> None:
    op.drop_index('ix_motions_parent', table_name='motions')
    op.drop_index('ix_jobs_owner_status', table_name='jobs')
    with op.batch_alter_table('motions') as batch:
        batch.drop_column('size')
