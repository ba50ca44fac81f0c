"""simulations: forward simulations of stored motions, and the job kind that runs them

Revision ID: 0004
Revises: 0003
Create Date: 2026-11-28 12:30:00
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = '0004'
down_revision = '0003'
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table('jobs') as batch:
        batch.add_column(sa.Column('kind', sa.String(length=16), nullable=False, server_default='extrapolate'))
    op.create_table('simulations',
    sa.Column('id', sa.String(length=40), nullable=False),
    sa.Column('owner', sa.String(length=40), nullable=False),
    sa.Column('motion_id', sa.String(length=40), nullable=False),
    sa.Column('job_id', sa.String(length=40), nullable=False),
    sa.Column('cycles', sa.Integer(), nullable=False),
    sa.Column('status', sa.String(length=16), nullable=False),
    sa.Column('message', sa.Text(), nullable=False),
    sa.Column('report', sa.JSON(), nullable=True),
    sa.Column('created_at', sa.Float(), nullable=False),
    sa.Column('started_at', sa.Float(), nullable=True),
    sa.Column('finished_at', sa.Float(), nullable=True),
    sa.ForeignKeyConstraint(['job_id'], ['jobs.id'], ondelete='CASCADE'),
    sa.ForeignKeyConstraint(['motion_id'], ['motions.id'], ondelete='CASCADE'),
    sa.PrimaryKeyConstraint('id')
    )
    op.create_index('ix_simulations_motion_created', 'simulations', ['motion_id', 'created_at'], unique=False)
    op.create_index(op.f('ix_simulations_job_id'), 'simulations', ['job_id'], unique=False)
    op.create_table('simulation_files',
    sa.Column('simulation_id', sa.String(length=40), nullable=False),
    sa.Column('name', sa.String(length=40), nullable=False),
    sa.Column('media_type', sa.String(length=100), nullable=False),
    sa.Column('size', sa.Integer(), nullable=False),
    sa.Column('data', sa.LargeBinary(), nullable=False),
    sa.ForeignKeyConstraint(['simulation_id'], ['simulations.id'], ondelete='CASCADE'),
    sa.PrimaryKeyConstraint('simulation_id', 'name')
    )


def downgrade() -> None:
    op.drop_table('simulation_files')
    op.drop_index(op.f('ix_simulations_job_id'), table_name='simulations')
    op.drop_index('ix_simulations_motion_created', table_name='simulations')
    op.drop_table('simulations')
    with op.batch_alter_table('jobs') as batch:
        batch.drop_column('kind')
