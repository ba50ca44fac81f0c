"""tutor claims: each tutor made by one job

Revision ID: 0003
Revises: 0002
Create Date: 2026-11-28 09:00:00
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = '0003'
down_revision = '0002'
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table('tutor_claims',
    sa.Column('parent_id', sa.String(length=40), nullable=False),
    sa.Column('tutor_key', sa.String(length=100), nullable=False),
    sa.Column('job_id', sa.String(length=40), nullable=False),
    sa.Column('token', sa.String(length=200), nullable=False),
    sa.Column('state', sa.String(length=16), nullable=False),
    sa.Column('message', sa.Text(), nullable=False),
    sa.Column('claimed_at', sa.Float(), nullable=False),
    sa.Column('ended_at', sa.Float(), nullable=True),
    sa.PrimaryKeyConstraint('parent_id', 'tutor_key')
    )


def downgrade() -> None:
    op.drop_table('tutor_claims')
