"""A motion's validation report, whole: plausibility, realism, naturalness and the replays.

``solver.plausibility.report`` computes our checks (root residual, contacts, friction, realism,
naturalness). Replays with independent physics plug in through the entry-point group
``motionx.replay`` (``pyproject.toml``): ``mjcf`` registers the MuJoCo inverse-dynamics replay
(``mjcf.validate.validate``), whose ``mujoco_replay`` check section (``solver.checks``) our
report then runs too, so this package reaches MuJoCo without importing ``mjcf`` (which imports it).
"""

from __future__ import annotations

from functools import cache
from importlib.metadata import EntryPoint, entry_points
from typing import Any

from solver.motion import Motion
from solver.plausibility import Tolerances, report

#: the entry-point group of replays: ``name = "module:function"``, function(motion, tolerances) -> report
REPLAY_GROUP = "motionx.replay"


@cache
def _replays() -> tuple[EntryPoint, ...]:
    """The installed replays (read from the package metadata once per process)."""
    return tuple(sorted(entry_points(group=REPLAY_GROUP), key=lambda e: e.name))


def validate(motion: Motion, tolerances: Tolerances = Tolerances(), *, simulate: bool = False) -> dict[str, Any]:
    """The validation report of ``motion``: our checks, extended by the installed replay (the
    MuJoCo one when the project is installed; ``plausible`` then requires it too). ``simulate``:
    the replay also performs the motion in forward simulation with contacts on (its
    ``simulation`` section reports whether it walks; it does not decide ``plausible``)."""
    replays = _replays()
    if not replays:
        if simulate:
            raise RuntimeError("simulate=True needs the MuJoCo replay (the project installed: pip install -e .)")
        return report(motion, tolerances)
    if len(replays) > 1:
        raise RuntimeError(f"more than one replay installed in {REPLAY_GROUP}: {[e.name for e in replays]}")
    if simulate:
        return replays[0].load()(motion, tolerances, simulate=True)
    return replays[0].load()(motion, tolerances)
