"""The generic OpenSim model for motions of other sources: OpenSim's gait2354 model scaled to the
motion's character and given its mass distribution, as an OpenSim rig (:func:`generic_rig`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from solver.export.opensim.base import OpenSimExportError, _cycle
from solver.export.opensim.child import run_child
from solver.io.opensim.rig import OpenSimRig
from solver.kinematics import segment_frames
from solver.motion import Motion

#: the generic model for motions of other sources: the OpenSim gait2354 model as scaled for the
#: example subject01 (1.80 m, 72.6 kg; opensim-core, Apache-2.0; see solver/export/models/README.md),
#: scaled again to the motion's character at export
GENERIC_MODEL = Path(__file__).parents[1] / "models" / "gait2354_subject01.osim"
#: frames of the generic model's calibration "trial" (its default pose, repeated over the cycle)
_GENERIC_FRAMES = 10


def generic_rig(motion: Motion, scratch: str | Path) -> OpenSimRig:
    """An OpenSim rig for a motion of another source (BVH, C3D, DeepMimic…): the generic model
    (:data:`GENERIC_MODEL`) scaled to the motion's character — pelvis by the hip width, each
    femur, tibia and foot by our thigh, shank and foot lengths, the torso by the legs' mean —
    and given the character's mass distribution (pelvis, thighs, shanks, feet, toes on the
    corresponding bodies, every other segment on the torso; a HalfBoy's pelvis carries its
    upper body, so its torso is left nearly massless); calibrated in the default
    standing pose (the model's coordinates at their defaults, ours at zero: both stand with the
    segments aligned), the model's hip mid-point on ours. The rig is an
    :class:`~solver.io.opensim.rig.OpenSimRig` like an imported one, with ``generic`` set; the
    motion is then written in OpenSim's own axes."""
    from solver.capture import GroundFrame as Frame
    from solver.io.opensim.base import C_OSIM
    from solver.io.opensim.model import _body_segments
    from solver.io.opensim.rig import pack_model
    from solver.io.opensim.worker import run_worker

    ch = motion.character
    names = [sg.name for sg in ch.segments]
    need = ["pelvis", "thigh_r", "thigh_l", "shank_r", "shank_l", "foot_r", "foot_l"]
    if [n for n in need if n not in names]:
        raise OpenSimExportError(f"the generic OpenSim model needs a character with a pelvis, thighs, shanks and feet; "
                                 f"{ch.name!r} has {names}")
    R0, P0 = segment_frames(ch, np.zeros(ch.n))
    ours = {n: P0[names.index(n)] for n in need}
    heel_toe = {side: ch.sole(side).length if ch.has_soles else None for side in ("right", "left")}
    # the generic model's own default geometry (OpenSim ground)
    base = run_worker(str(GENERIC_MODEL), ["pelvis_ty"], np.array([[0.0]]), False)
    jc = {c: np.asarray(base["JC"])[0, k] for k, c in enumerate(base["joint_child"])}
    bc = {b: np.asarray(base["body_com"])[k] for k, b in enumerate(base["body_names"])}
    Pm = {b: np.asarray(base["P"])[0, k] for k, b in enumerate(base["body_names"])}

    def ratio(a: float, b: float) -> float:
        return float(a / b) if b > 1e-6 else 1.0

    factors: dict[str, list[float]] = {}
    hip = ratio(float(np.linalg.norm(ours["thigh_r"] - ours["thigh_l"])),
                float(np.linalg.norm(jc["femur_r"] - jc["femur_l"])))
    factors["pelvis"] = [hip] * 3
    legs = []
    for s, side in (("r", "right"), ("l", "left")):
        thigh = ratio(float(np.linalg.norm(ours[f"shank_{s}"] - ours[f"thigh_{s}"])),
                      float(np.linalg.norm(jc[f"tibia_{s}"] - jc[f"femur_{s}"])))
        shank = ratio(float(np.linalg.norm(ours[f"foot_{s}"] - ours[f"shank_{s}"])),
                      float(np.linalg.norm(jc[f"talus_{s}"] - jc[f"tibia_{s}"])))
        tip = Pm[f"toes_{s}"] + np.array([2.0 * bc[f"toes_{s}"][0], 0.0, 0.0])
        length = heel_toe[side]
        foot = ratio(length, float(np.linalg.norm((tip - Pm[f"calcn_{s}"])[[0, 2]]))) if length else shank
        factors[f"femur_{s}"] = [thigh] * 3
        factors[f"tibia_{s}"] = [shank] * 3
        for b in (f"talus_{s}", f"calcn_{s}", f"toes_{s}"):
            factors[b] = [foot] * 3
        legs += [thigh, shank]
    factors["torso"] = [float(np.mean(legs))] * 3
    scaled = Path(scratch) / "generic_scaled.osim"
    run_child({"job": "scale", "model": str(GENERIC_MODEL), "factors": factors, "mass": ch.total_mass,
               "name": f"gait2354_scaled_{ch.name}".replace("-", "_"), "out": str(scaled)})
    res = run_worker(str(scaled), ["pelvis_ty"], np.array([[0.0]]), False)
    coords = list(res["coord_names"])
    default = np.array(res["coord_default"], dtype=float)
    default[coords.index("pelvis_ty")] = 0.0
    jc = {c: np.asarray(res["JC"])[0, k] for k, c in enumerate(res["joint_child"])}
    # the model's hip mid-point on ours (OpenSim ground = C_OSIM^T ours)
    target = C_OSIM.T @ (0.5 * (ours["thigh_r"] + ours["thigh_l"]))
    delta = target - 0.5 * (jc["femur_r"] + jc["femur_l"])
    for k, c in enumerate(("pelvis_tx", "pelvis_ty", "pelvis_tz")):
        default[coords.index(c)] += delta[k]
    seg_of, _, _ = _body_segments(res, str(scaled))
    # the character's mass distribution on the model's bodies (default pose, hip mid-points together):
    # pelvis <- our pelvis; femur, tibia, calcn, toes <- thigh, shank, foot, toes; torso <- every other
    # segment of ours (none for a HalfBoy, whose pelvis carries the upper body); talus (and an empty
    # torso) a negligible mass
    R_b = {b: C_OSIM @ np.asarray(res["R"])[0, k] for k, b in enumerate(res["body_names"])}
    p_b = {b: C_OSIM @ (np.asarray(res["P"])[0, k] + delta) for k, b in enumerate(res["body_names"])}
    groups: dict[str, list[str]] = {"pelvis": ["pelvis"], "torso": []}
    for s, _ in (("r", 0), ("l", 1)):
        groups.update({f"femur_{s}": [f"thigh_{s}"], f"tibia_{s}": [f"shank_{s}"], f"calcn_{s}": [f"foot_{s}"],
                       f"toes_{s}": [f"toes_{s}"] if f"toes_{s}" in names else [], f"talus_{s}": []})
    used = {x for v in groups.values() for x in v}
    groups["torso"] = [n for n in names if n not in used]
    eps = 1e-3
    props: dict[str, tuple[float, list[float], list[list[float]]]] = {}
    for body, segs in groups.items():
        if body not in R_b:
            continue
        m, mc = 0.0, np.zeros(3)
        parts = []
        for sname in segs:
            sg = ch.segments[names.index(sname)]
            i_s = names.index(sname)
            c_w = P0[i_s] + R0[i_s] @ np.asarray(sg.com)
            parts.append((sg.mass, c_w, R0[i_s] @ np.asarray(sg.inertia) @ R0[i_s].T))
            m += sg.mass
            mc += sg.mass * c_w
        if m <= eps:
            props[body] = (eps, [0.0, 0.0, 0.0], (1e-6 * np.eye(3)).tolist())
            continue
        com = mc / m
        inertia = sum(ii + mi * (float((c - com) @ (c - com)) * np.eye(3) - np.outer(c - com, c - com))
                      for mi, c, ii in parts)
        Rb = R_b[body]
        props[body] = (m, (Rb.T @ (com - p_b[body])).tolist(), (Rb.T @ inertia @ Rb).tolist())
    massed = Path(scratch) / "generic_massed.osim"
    run_child({"job": "masses", "model": str(scaled), "bodies": props, "out": str(massed)})
    scaled = massed
    t_start, period = _cycle(motion)
    times = t_start + period * np.arange(_GENERIC_FRAMES) / _GENERIC_FRAMES
    return OpenSimRig.from_dict({
        "format": "opensim",
        "generic": {"model": GENERIC_MODEL.name, "scale_factors": {b: round(f[0], 4) for b, f in factors.items()},
                    "mass_kg": ch.total_mass},
        "model": {"file": f"gait2354_scaled_{ch.name}.osim", "name": f"gait2354 scaled to {ch.name}",
                  "sha256": None, "osim_xz_b64": pack_model(scaled.read_bytes())},
        "model_coordinates": coords,
        "coordinates": {"names": coords, "values": np.tile(default, (_GENERIC_FRAMES, 1)).tolist()},
        "times": times.tolist(),
        "fit": {"names": list(ch.coordinate_names), "q": np.zeros((ch.n, _GENERIC_FRAMES)).tolist()},
        "bodies": list(res["body_names"]),
        "body_segments": dict(seg_of),
        "feet": {"right": "calcn_r", "left": "calcn_l"},
        "frame": Frame(R=C_OSIM.T, axes="OpenSim ground: x forward, y up, z right").to_dict(),
    })
