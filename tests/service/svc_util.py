"""Helpers shared by the service tests (imported as ``svc_util``)."""

from __future__ import annotations

import secrets

import numpy as np

KEY_A, KEY_B = "test-key-a-" + secrets.token_hex(8), "test-key-b-" + secrets.token_hex(8)


def halfboy_motion(T: int = 12, *, capture: bool = True, seed: int = 0):
    """A small, valid motion file v1 of the reference HalfBoy (upload/validation tests)."""
    from solver.character import reference
    from solver.motion import Motion

    ch = reference("halfboy")
    rng = np.random.default_rng(seed)
    q = 0.05 * rng.standard_normal((ch.n, T))
    return Motion(character=ch, fps=15.0, q=q, reference_name="halfboy",
                  provenance={"step": "capture"} if capture else {})
