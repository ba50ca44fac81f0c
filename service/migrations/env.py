"""Alembic environment: the URL comes from the caller (service.db.upgrade) or the settings."""

from __future__ import annotations

from alembic import context
from sqlalchemy import text

from service.db import get_database
from service.models import Base

config = context.config
target_metadata = Base.metadata


def _url() -> str:
    url = config.attributes.get("motionx_url")
    if url:
        return url
    from service.config import get_settings

    return get_settings().sqlalchemy_url


def run_migrations_offline() -> None:
    context.configure(url=_url(), target_metadata=target_metadata, literal_binds=True, render_as_batch=True)
    with context.begin_transaction():
        context.run_migrations()


def run_migrations_online() -> None:
    db = get_database(_url())
    with db.engine.connect() as connection:
        if connection.dialect.name == "postgresql":
            # concurrent `motionx serve` processes: one migrates, the others wait
            connection.execute(text("SELECT pg_advisory_lock(727001)"))
            connection.commit()
        try:
            context.configure(connection=connection, target_metadata=target_metadata, render_as_batch=True)
            with context.begin_transaction():
                context.run_migrations()
        finally:
            if connection.dialect.name == "postgresql":
                connection.execute(text("SELECT pg_advisory_unlock(727001)"))
                connection.commit()


if context.is_offline_mode():
    run_migrations_offline()
else:
    run_migrations_online()
