"""Compatibility: :class:`InputError` lives in :mod:`solver.errors` (readers and gait processing share it)."""

from solver.errors import InputError

__all__ = ["InputError"]
