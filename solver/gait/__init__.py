"""Gait processing: domain logic on a captured walk, outside the readers (solver/io/).

    resample(capture, fps) -> Capture                                   (solver.gait.base)
    lowpass(x, fps, cutoff_hz, *, order=4, axis=-1) -> ndarray            (solver.gait.base)
    detect_contacts(character, q, fps, ...) -> (P, T) bool               (solver.gait.contacts)
    contacts_from_plates(measured, *, threshold=20.0, ...) -> (P, T) bool (solver.gait.contacts)
    gait_events(contacts, times) -> dict                                  (solver.gait.contacts)
    ensure_double_support(character, q, contacts) -> (contacts, changes)  (solver.gait.contacts)
    tighten_contacts(character, q, contacts) -> (contacts, changes)       (solver.gait.contacts)
    extract_cycle(capture, fps=None, *, start=..., contacts=None, cycle=0)
        -> (Capture, contacts (P, T))                                     (solver.gait.cycles)
    unroll_loop(capture, repeats=2) -> Capture                            (solver.gait.cycles)
    close_loop(q) -> q periodic over the cycle (its seam blended)          (solver.gait.cycles)
    periodic_lowpass(q, fps) -> a closed cycle low-passed as a periodic signal (solver.gait.cycles)

    belt_speed(times, feet, *, stance=None) -> m/s                        (solver.gait.belt)
    unwrap_hinges(character, q) -> q with continuous hinge angles         (solver.gait.base)

Every failure is a :class:`GaitError`, an :class:`solver.errors.InputError`. The treadmill reader
(solver/io/opensim/treadmill.py) takes the belt speed from here and shifts its marker track.
"""

from solver.gait.base import GaitError, lowpass, resample, unwrap_hinges
from solver.gait.belt import belt_speed
from solver.gait.contacts import (
    contacts_from_plates,
    detect_contacts,
    ensure_double_support,
    gait_events,
    tighten_contacts,
)
from solver.gait.cycles import LOOP_PERIOD_S, close_loop, extract_cycle, periodic_lowpass, unroll_loop

__all__ = [
    "LOOP_PERIOD_S",
    "GaitError",
    "belt_speed",
    "close_loop",
    "contacts_from_plates",
    "detect_contacts",
    "ensure_double_support",
    "extract_cycle",
    "gait_events",
    "lowpass",
    "periodic_lowpass",
    "resample",
    "tighten_contacts",
    "unroll_loop",
    "unwrap_hinges",
]
