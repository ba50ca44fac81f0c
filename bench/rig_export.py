"""Results on the input's own rig (``solver.rig``): a BVH walk on a Mixamo-style rig
(``data/mixamo_style_walk/walk.bvh``: cm, ZXY channels, T-pose, fingers) through the tutor, the
10° slope and 90° curve optima (λ = 1) and a 3 × 3 library (slope −5/0/5°, curve −45/0/45°),
each written back on the rig. Per motion: the worst ankle-joint distance from where the
motion's foot carries it (stance), the worst slide of a contact point carried by the rig's
foot over its contact, the RMS rotation between the exported and the input file's own local
rotations of the joints the synthesis character locked (arms, spine, head, fingers) at the
same gait phase, read back from the written file, and the export's time (best of 3).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

import solver
from bench.trials import best_time, data_dir
from solver.io.bvh import parse_bvh, read_bvh
from solver.rig import SkeletonRig, feet_report, retarget


def _locked_rms_deg(motion, src) -> float:
    rig = motion.context.rig
    assert isinstance(rig, SkeletonRig)
    pose = retarget(motion, rig)
    out = parse_bvh(solver.export_motion(motion, "bvh", rig="source"))
    thighs = (rig.roles["thigh_r"], rig.roles["thigh_l"])
    upper = []
    for j in range(1, len(src.names)):
        a = j
        while a >= 0 and a not in thighs:
            a = src.parents[a]
        if a < 0 and sum(c.endswith("rotation") for c in src.channels[j]) == 3:
            upper.append(j)
    t = np.arange(src.T) * src.frame_time
    errs = []
    for j in upper:
        want = Slerp(t, Rotation.from_matrix(src.local(j)[0]))(np.clip(pose.capture_time, t[0], t[-1]))
        got = Rotation.from_matrix(out.local(j)[0])
        errs.append((want.inv() * got).magnitude())
    return float(np.degrees(np.sqrt(np.mean(np.square(errs)))))


def run() -> dict:
    path = data_dir() / "mixamo_style_walk" / "walk.bvh"
    src = read_bvh(path)
    tutor = solver.make_tutor(solver.load_trial([path], mass=70.0), character="halfboy", fps=15.0).motion
    motions = {"tutor": tutor,
               "slope 10°": solver.extrapolate(tutor, solver.Target(slope_deg=10)).steps[-1].motion,
               "curve 90°": solver.extrapolate(tutor, solver.Target(curve_deg=90)).steps[-1].motion}
    lib = solver.solve_library(tutor, solver.grid_cells({"slope_deg": [-5, 0, 5], "curve_deg": [-45, 0, 45]}))
    cells = {r.cell.key: r.motion for r in lib.cells if r.motion is not None}
    rows = {}
    for name, m in {**motions, **{f"cell {k}": v for k, v in cells.items()}}.items():
        rig = m.context.rig
        assert isinstance(rig, SkeletonRig)
        rep = feet_report(m, rig, retarget(m, rig))
        rows[name] = {
            "ankle_error_mm": round(1e3 * max(r["ankle_error_m"] for r in rep.values()), 2),
            "slide_mm": round(1e3 * max(r["slide_m"] for r in rep.values()), 2),
            "locked_joints_rms_deg": round(_locked_rms_deg(m, src), 4),
            "export_s": round(best_time(lambda m=m: solver.export_motion(m, "bvh", rig="source"), 3), 4),
        }
    return {"rig": {"joints": len(src.names), "channels": int(sum(len(c) for c in src.channels)),
                    "frame_time_s": src.frame_time},
            "library_cells": len(cells), "motions": rows}


if __name__ == "__main__":
    import json

    print(json.dumps(run(), indent=1))
