"""What every part of the OpenSim importer shares: its error and OpenSim's ground axes."""

from __future__ import annotations

import numpy as np

from solver.errors import InputError


class OpenSimError(InputError):
    """An OpenSim input is unreadable or inconsistent; the message names the problem."""


#: OpenSim ground (X forward, Y up, Z right) -> ours (X forward, Y left, Z up).
C_OSIM = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def to_ours_R(R: np.ndarray) -> np.ndarray:
    """OpenSim (T, 3, 3) body rotations -> ours (3, 3, T)."""
    return np.moveaxis(C_OSIM @ R @ C_OSIM.T, 0, -1)


def to_ours_p(p: np.ndarray) -> np.ndarray:
    """OpenSim (T, 3) points -> ours (3, T)."""
    return (p @ C_OSIM.T).T
