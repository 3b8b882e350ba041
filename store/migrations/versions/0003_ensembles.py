"""Ensembles and their chunks (they lived in Redis before).

Revision ID: 0003_ensembles
Revises: 0002_runner
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op
from sqlalchemy.dialects.postgresql import JSONB

revision = "0003_ensembles"
down_revision = "0002_runner"
branch_labels = None
depends_on = None

Document = sa.JSON().with_variant(JSONB(), "postgresql")


def upgrade() -> None:
    op.create_table(
        "ensembles",
        sa.Column("id", sa.String(64), primary_key=True),
        sa.Column("owner", sa.String(128), nullable=True),
        sa.Column("request", Document, nullable=False),
        sa.Column("chunks", Document, nullable=False),
        sa.Column("created", sa.Float(), nullable=False),
        sa.Column("created_at", sa.String(40), nullable=False),
        sa.Column("cancelled", sa.Boolean(), nullable=False),
        sa.Column("queue", sa.String(200), nullable=True),
        sa.Column("broker_epoch", sa.String(64), nullable=True),
    )
    op.create_index("ix_ensembles_created", "ensembles", ["created"])
    op.create_table(
        "ensemble_chunks",
        sa.Column("ensemble_id", sa.String(64), primary_key=True),
        sa.Column("chunk", sa.Integer(), primary_key=True),
        sa.Column("done", sa.Boolean(), nullable=False),
        sa.Column("members_done", sa.Integer(), nullable=False),
        sa.Column("starts", sa.Integer(), nullable=False),
        sa.Column("worker", sa.String(200), nullable=True),
        sa.Column("members", Document, nullable=True),
        sa.Column("digests", Document, nullable=True),
    )
    op.create_index("ix_ensemble_chunks_pending", "ensemble_chunks", ["ensemble_id", "done"])


def downgrade() -> None:
    op.drop_table("ensemble_chunks")
    op.drop_table("ensembles")
