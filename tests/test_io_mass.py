"""The body mass force plates imply (solver.io.mass) and the stance intervals of the input summary."""

import numpy as np
import pytest

from solver.io.mass import G, implied_mass, mass_warning, stances, stride_from_events
from solver.io.summary import stance_intervals

M, STRIDE, STANCE = 68.0, 1.1, 0.66  # kg, s, s (60 % stance: 10 % double support each side)


def walking_forces(t: np.ndarray, mass: float = M) -> np.ndarray:
    """Per-foot vertical forces of steady walking: each stance a double hump (heel, push-off)
    scaled so that one stance per foot per stride carries the weight over the stride."""
    out = np.zeros((2, t.size))
    for k, phase in enumerate((0.0, 0.5)):
        u = ((t / STRIDE - phase) % 1.0) * STRIDE / STANCE  # 0..1 during stance
        on = u < 1.0
        shape = np.where(on, np.sin(np.pi * u) + 0.25 * np.sin(3 * np.pi * u), 0.0)
        impulse = STANCE * (2 / np.pi + 0.25 * 2 / (3 * np.pi))  # ∫ shape dt over a stance
        out[k] = shape * mass * G * STRIDE / 2 / impulse
    return out


def test_whole_cycles_of_continuous_plates_give_the_mass():
    t = np.arange(0.05, 9.0, 1 / 600)
    im = implied_mass(t, walking_forces(t))
    assert im.method == "whole cycles" and im.cycles >= 6 and im.cycle_s == pytest.approx(STRIDE, rel=1e-3)
    assert im.kg == pytest.approx(M, rel=2e-3)
    # a stance of the other foot missing (off the plates) breaks the whole-cycle window there
    f = walking_forces(t)
    f[1, (t > 4.5) & (t < 5.3)] = 0.0
    im2 = implied_mass(t, f)
    assert im2.kg == pytest.approx(M, rel=5e-3) and im2.cycles < im.cycles


def test_one_complete_stance_per_foot_gives_the_mass():
    """Two plates, one stance each (right then left): the impulses over the stride."""
    t = np.arange(0.0, 3.0, 1 / 1000)
    f = walking_forces(t)
    f[0, (t < 0.9) | (t > 1.9)] = 0.0  # the right stance starting at 1.1 s only
    f[1, (t < 1.5) | (t > 2.5)] = 0.0  # the left stance starting at 1.65 s only
    im = implied_mass(t, f)
    assert im.method == "one stance per foot" and im.stride_from == "plates (2 x step)"
    assert im.cycle_s == pytest.approx(STRIDE, abs=2e-3) and im.kg == pytest.approx(M, rel=5e-3)
    # the kinematics' stride is used when it agrees with the plates' (within a quarter)
    assert implied_mass(t, f, stride_s=1.12).stride_from == "kinematics"
    assert implied_mass(t, f, stride_s=2.2).stride_from == "plates (2 x step)"  # a missed strike
    # stances cut by the record's ends are not complete: nothing to say
    assert implied_mass(t[t > 1.2], f[:, t > 1.2]) is None
    assert implied_mass(t, np.zeros((2, t.size))) is None


def test_stances_and_the_warning():
    t = np.arange(0, 2, 0.01)
    f = np.where((t > 0.5) & (t < 1.2), 500.0, 0.0) + np.where(t < 0.3, 400.0, 0.0)  # first run cut by the start
    f[150] = 30.0  # a 0.01 s blip above 20 N is no stance
    assert stances(t, f) == [(51, 119)]
    assert mass_warning(72.6, implied_mass(np.arange(0.05, 9, 1 / 600),
                                           walking_forces(np.arange(0.05, 9, 1 / 600), 72.6))) is None
    im = implied_mass(np.arange(0.05, 9, 1 / 600), walking_forces(np.arange(0.05, 9, 1 / 600), 73.4))
    assert "62.0 kg differs from the 73.4 kg the force plates imply (-16 %)" in mass_warning(62.0, im)
    assert stride_from_events({"right_heel_strike": [0.1, 1.2, 2.3], "left_heel_strike": [0.65]}) == pytest.approx(1.1)
    assert stride_from_events({"right_heel_strike": [0.1]}) is None


def test_stance_intervals_per_foot():
    t = np.arange(6) * 0.1
    c = np.array([[1, 1, 0, 0, 1, 1],   # heel_r
                  [0, 1, 1, 0, 0, 0],   # toe_r
                  [0, 0, 1, 1, 0, 0],   # heel_l
                  [0, 0, 0, 1, 0, 0]],  # toe_l
                 dtype=bool)
    st = stance_intervals(c, t, ("right", "right", "left", "left"))
    assert st == {"right": [[0.0, 0.2], [0.4, 0.5]], "left": [[0.2, 0.3]]}
