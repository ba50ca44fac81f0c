"""API keys: a new key (only its hash is stored), counted, revoked, and the owner a presented key
stands for (keys given in the settings as well as stored ones)."""

from __future__ import annotations

import hashlib
import secrets
from collections.abc import Sequence

from sqlalchemy import func, select, update
from sqlalchemy.orm import Session

from service.models import ApiKey
from service.store.sql import new_id, now


def hash_key(key: str) -> str:
    return hashlib.sha256(key.encode("utf-8")).hexdigest()


def static_owner(key: str) -> str:
    """Owner id of a key given in the settings (stable across restarts)."""
    return "s_" + hash_key(key)[:32]


def create_api_key(session: Session, *, name: str = "") -> tuple[str, str]:
    """A new API key: returns (owner id, the key). Only its hash is stored."""
    key = "mx_" + secrets.token_urlsafe(32)
    kid = new_id("k")
    session.add(ApiKey(id=kid, name=name, key_hash=hash_key(key), created_at=now()))
    return kid, key


def count_api_keys(session: Session) -> int:
    return session.scalar(select(func.count()).select_from(ApiKey).where(ApiKey.revoked_at.is_(None))) or 0


def revoke_api_key(session: Session, *, key_id: str) -> bool:
    r = session.execute(update(ApiKey).where(ApiKey.id == key_id, ApiKey.revoked_at.is_(None)).values(revoked_at=now()))
    return r.rowcount == 1


def owner_for_key(session: Session, *, key: str, static_keys: Sequence[str] = ()) -> str | None:
    for k in static_keys:
        if secrets.compare_digest(k.encode(), key.encode()):
            return static_owner(k)
    row = session.scalar(select(ApiKey).where(ApiKey.key_hash == hash_key(key), ApiKey.revoked_at.is_(None)))
    return row.id if row else None
