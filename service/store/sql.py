"""What the store's modules share: new ids, the clock, the dialect's own INSERT (for upserts), and
stored blobs read in SQL a chunk at a time."""

from __future__ import annotations

import time
import uuid

from sqlalchemy import func, select
from sqlalchemy.orm import Session


def new_id(prefix: str) -> str:
    return f"{prefix}_{uuid.uuid4().hex}"


def now() -> float:
    return time.time()


def insert_for(session: Session, table):
    """The dialect's INSERT construct (both have ``on_conflict_do_update/nothing``)."""
    if session.get_bind().dialect.name == "postgresql":
        from sqlalchemy.dialects.postgresql import insert  # the dialect's own upsert
    else:
        from sqlalchemy.dialects.sqlite import insert  # the dialect's own upsert
    return insert(table)


def blob_size(session: Session, column, key_column, key) -> int | None:
    """The length of one stored blob (``column`` of the row whose ``key_column`` is ``key``)."""
    return session.scalar(select(func.length(column)).where(key_column == key))


def blob_chunk(session: Session, column, where, offset: int, size: int) -> bytes:
    """``size`` bytes of a stored blob from ``offset``, read in SQL (``substr``: SQLite and
    PostgreSQL alike), so a download never holds the whole blob in the API's memory."""
    out = session.scalar(select(func.substr(column, offset + 1, size)).where(*where))
    return bytes(out or b"")
