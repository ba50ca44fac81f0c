"""Compatibility: gait processing lives in :mod:`solver.gait`; this module re-exports it."""

from solver.gait import (
    LOOP_PERIOD_S,
    GaitError,
    PreprocessError,
    contacts_from_plates,
    detect_contacts,
    extract_cycle,
    gait_events,
    lowpass,
    resample,
    unroll_loop,
)
from solver.gait.base import _unwrapped

__all__ = [
    "LOOP_PERIOD_S",
    "GaitError",
    "PreprocessError",
    "_unwrapped",
    "contacts_from_plates",
    "detect_contacts",
    "extract_cycle",
    "gait_events",
    "lowpass",
    "resample",
    "unroll_loop",
]
