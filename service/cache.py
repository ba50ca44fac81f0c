"""A small in-process LRU for exported motions (a clip is a pure function of a stored,
immutable motion, its format and options), bounded by total bytes: a ``cachetools.LRUCache``
weighed by each body's length, behind a lock (the API's threads share it)."""

from __future__ import annotations

import threading
from collections.abc import Hashable

from cachetools import LRUCache


def _size(item: tuple[bytes, str]) -> int:
    return len(item[0])


class BytesLRU:
    def __init__(self, max_bytes: int = 64 * 1024 * 1024) -> None:
        self.max_bytes = max_bytes
        self._items: LRUCache[Hashable, tuple[bytes, str]] = LRUCache(maxsize=max_bytes, getsizeof=_size)
        self._lock = threading.Lock()

    def get(self, key: Hashable) -> tuple[bytes, str] | None:
        with self._lock:
            return self._items.get(key)

    def put(self, key: Hashable, data: bytes, media_type: str) -> None:
        if len(data) > self.max_bytes // 4:  # one large body would evict many small ones
            return
        with self._lock:
            self._items[key] = (data, media_type)
