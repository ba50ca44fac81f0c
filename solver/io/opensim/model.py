"""OpenSim model -> landmarks, segment orientations, masses and inertias (a :class:`SkeletonTrack`).

The model is evaluated by OpenSim itself (:mod:`solver.io.opensim.worker`); this module
maps its bodies to our segments and places the landmarks (see the package doc for every
convention). The coordinates come from a ``.mot``/``.sto`` (IK result) or from the
inverse kinematics of a ``.trc`` (:mod:`solver.io.opensim.ik`).
"""

from __future__ import annotations

import logging
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from solver.capture import GroundFrame
from solver.character import capture_full
from solver.io.fit import HIP_HEIGHT_FRACTION, SEGMENT_LANDMARKS, THORAX_JOINT_FRACTION
from solver.io.opensim.base import C_OSIM, OpenSimError, to_ours_p, to_ours_R
from solver.io.opensim.external_loads import floor_from_grf
from solver.io.opensim.ik import solve_ik
from solver.io.opensim.storage import Storage, read_mot
from solver.io.opensim.treadmill import belt_shift
from solver.io.track import SkeletonTrack, add_pelvis, rescaled_masses, split_mass
from solver.kinematics import points_world

log = logging.getLogger(__name__)

_SEGMENT_RULES: list[tuple[str, str]] = [
    # (regex on the OpenSim body name, our segment; {s} = side)
    (r"pelvis", "pelvis"),
    (r"femur_(?P<s>[rl])", "thigh_{s}"),
    (r"(tibia|patella)_(?P<s>[rl])", "shank_{s}"),
    (r"(calcn|talus)_(?P<s>[rl])", "foot_{s}"),
    (r"toes_(?P<s>[rl])", "toes_{s}"),
    (r"torso", "torso"),
    (r"humerus_(?P<s>[rl])", "upper_arm_{s}"),
    (r"(radius|ulna)_(?P<s>[rl])", "forearm_{s}"),
    (r"hand_(?P<s>[rl])", "hand_{s}"),
]
#: which body gives the segment's orientation
_ORIENTING = {"pelvis": "pelvis", "thigh": "femur", "shank": "tibia", "foot": "calcn", "toes": "toes",
              "upper_arm": "humerus", "forearm": "radius", "hand": "hand", "abdomen": "torso"}
#: torso mass split (Winter's ratios) between the trunk segments of a model with arms; each part
#: gets the torso body's centre of mass and its share of the torso's inertia, so that the trunk,
#: rigid with the torso in the data, has the torso body's mass distribution exactly
_TORSO_SPLIT = {"abdomen": 0.139, "thorax": 0.196, "head": 0.081}
#: the trunk segments' origins (a virtual landmark for the thorax, see solver.io.fit)
_TRUNK_ORIGINS = {"abdomen": "lumbar", "thorax": "@thorax_joint", "head": "neck"}
#: the shoulder girdle has no body of its own in such a model (the humerus hangs on the torso):
#: placeholders of negligible mass, rigid with the torso
_CLAVICLES = ("clavicle_r", "clavicle_l")
#: canonical upper-body segments an arm-less model (gait2354: one torso body for head, arms and
#: trunk) does not have: rigid with its torso in the data, they exist for the topology only
_ARMLESS_PLACEHOLDERS = ("thorax", "head") + tuple(
    f"{s}_{side}" for side in "rl" for s in ("clavicle", "upper_arm", "forearm", "hand"))
#: mass of such a placeholder segment, as a fraction of the subject's mass: negligible (the
#: torso body keeps its own mass distribution), yet not zero — MuJoCo refuses massless moving bodies
PLACEHOLDER_MASS_FRACTION = 1e-6


def _segment_of(body: str) -> str | None:
    for pat, seg in _SEGMENT_RULES:
        m = re.fullmatch(pat, body)
        if m:
            return seg.format(s=m.groupdict().get("s", ""))
    return None


#: a column varying by less than this (its own units: degrees, radians or metres) is constant
CONSTANT_COLUMN_TOL = 1e-6


def check_motion(sto: Storage, res: Mapping[str, Any], model_path: str) -> dict[str, float]:
    """Columns against the model's coordinates, as OpenSim's tools read a ``.mot``.

    OpenSim reads the columns naming its coordinates and ignores the others. A column for a
    coordinate the model does not have is ignored here too when it is **constant** (a joint
    welded or locked in this model — e.g. a scaled Rajagopal model with subtalar, mtp and
    wrists welded whose IK still carries those columns at 0): it is logged as a warning and
    returned (name -> value). A varying one is motion the model cannot follow: refused,
    naming the columns. A model coordinate without a column is refused unless it is locked
    or constrained (``knee_angle_r_beta``).
    """
    names = list(res["coord_names"])
    unknown = [c for c in sto.labels if c not in names]
    ignored: dict[str, float] = {}
    varying: list[str] = []
    for c in unknown:
        col = sto.column(c)
        if float(np.ptp(col)) <= CONSTANT_COLUMN_TOL:
            ignored[c] = float(col[0])
        else:
            varying.append(c)
    if varying:
        ranges = ", ".join(f"{c} {sto.column(c).min():.4g}..{sto.column(c).max():.4g}" for c in varying)
        raise OpenSimError(
            f"model/motion mismatch: {sto.path} has columns {varying} that are not coordinates of "
            f"{model_path} and vary over the motion ({ranges}): the model cannot follow them (is it the "
            f"model the motion was computed with?). Model coordinates: {names}"
        )
    if ignored:
        log.warning("%s: ignoring %d constant column(s) that are not coordinates of %s (welded or locked joints, "
                    "as OpenSim does): %s", sto.path, len(ignored), Path(model_path).name,
                    ", ".join(f"{k}={v:g}" for k, v in ignored.items()))
    missing = [c for c, constrained in zip(names, res["coord_constrained"]) if c not in sto.labels and not constrained]
    if missing:
        raise OpenSimError(f"model/motion mismatch: {sto.path} lacks the model's coordinates {missing}")
    return ignored


def _angles_in_degrees(sto: Storage, in_degrees: bool | None) -> bool | None:
    if in_degrees is not None:
        return bool(in_degrees)
    if sto.in_degrees is not None:
        return sto.in_degrees
    if re.search(r"angles are in degrees", sto.header_text, re.I):
        return True
    if re.search(r"angles are in radians", sto.header_text, re.I):
        return False
    log.warning("%s: the header does not say whether angles are in degrees (inDegrees=yes/no): inferring it "
                "from the values (pass in_degrees=True/False to decide)", sto.path)
    return None


def _evaluate(model: str, motion: str | Path, in_degrees: bool | None, ik_weights: Mapping[str, float] | None,
              ik_reweight: int | None) -> tuple[dict[str, Any], np.ndarray, dict[str, Any]]:
    """OpenSim's evaluation of the model along the motion (coordinates, or a ``.trc``'s inverse
    kinematics): the worker's result (``coordinates``: the columns evaluated and their values
    (T, K) in the model's units, radians and metres, added), the times and what the source
    records of it."""
    from solver.io.opensim.worker import run_worker  # lazy: the child-process launcher, only when OpenSim runs

    src_extra: dict[str, Any] = {}
    if Path(motion).suffix.lower() == ".trc":
        res, src_extra = solve_ik(model, motion, weights=ik_weights, reweight=ik_reweight)
        res["coordinates"] = (list(res["coord_names"]), np.asarray(res["ik_q"], dtype=float))
        return res, np.asarray(res["ik_times"], dtype=float), src_extra
    if ik_weights is not None or ik_reweight is not None:
        raise OpenSimError("ik_weights / ik_reweight only apply to a .trc marker file, not to coordinates")
    sto = read_mot(motion)
    if len(sto.time) < 2:
        raise OpenSimError(f"{motion}: a motion needs at least 2 frames, got {len(sto.time)}")
    deg = _angles_in_degrees(sto, in_degrees)
    res = run_worker(model, sto.labels, sto.data, deg)
    ignored = check_motion(sto, res, model)
    names = list(res["coord_names"])
    cols = [k for k, c in enumerate(sto.labels) if c in names]
    values = np.array(sto.data[:, cols], dtype=float)
    for j, k in enumerate(cols):
        if res["in_degrees"] and res["coord_rotational"][names.index(sto.labels[k])]:
            values[:, j] = np.radians(values[:, j])
    res["coordinates"] = ([sto.labels[k] for k in cols], values)
    if ignored:
        src_extra["ignored_columns"] = ignored
        res["notes"] = list(res.get("notes", [])) + [
            f"constant columns that are not model coordinates ignored (welded/locked joints): {sorted(ignored)}"]
    return res, sto.time.astype(float), src_extra


def _body_segments(res: Mapping[str, Any], model: str) -> tuple[dict[str, str | None], bool, bool]:
    """Each OpenSim body's segment of ours (unknown bodies ride with their parent's segment; the
    trunk and arms as the model has them), whether it has a torso body and arms."""
    names = list(res["body_names"])
    seg_of = {b: _segment_of(b) for b in names}
    parent_of = dict(zip(res["joint_child"], res["joint_parent"]))
    for b in names:  # unknown bodies ride with their parent's segment
        seen = set()
        cur = b
        while seg_of.get(cur) is None and cur in parent_of and cur not in seen:
            seen.add(cur)
            cur = parent_of[cur]
        if seg_of[b] is None:
            seg_of[b] = seg_of.get(cur)
            log.info("OpenSim body %r has no segment rule: lumped into %r", b, seg_of[b])
    for need in ("pelvis", "femur_r", "femur_l", "tibia_r", "tibia_l", "calcn_r", "calcn_l", "toes_r", "toes_l"):
        if need not in seg_of:
            raise OpenSimError(f"{model}: body {need!r} not found; the importer needs a gait-model leg "
                               f"(pelvis, femur, tibia, talus, calcn, toes per side); bodies: {names}")
    has_torso = "torso" in seg_of
    has_arms = has_torso and all(f"{b}_{s}" in seg_of for b in ("humerus", "ulna", "radius", "hand") for s in "rl")
    arm = ("upper_arm", "forearm", "hand")
    if not has_torso:  # no trunk body: anything above the hips rides with the pelvis (capture-lower)
        seg_of = {b: ("pelvis" if (s or "").startswith(arm) else s) for b, s in seg_of.items()}
    elif not has_arms:  # the torso body is head, arms and trunk (gait2354): the abdomen carries it whole
        seg_of = {b: ("abdomen" if s == "torso" or (s or "").startswith(arm) else s) for b, s in seg_of.items()}
    return seg_of, has_torso, has_arms


class _Bodies:
    """The evaluated model's body frames and joint centres, as our landmarks (floor at z = 0)."""

    def __init__(self, res: Mapping[str, Any], model: str, off: np.ndarray) -> None:
        self.res, self.model, self.off = res, model, off
        self.bi = {b: i for i, b in enumerate(res["body_names"])}
        self.Rb, self.Pb, self.JC = res["R"], res["P"], res["JC"]  # (T, B, 3, 3), (T, B, 3), (T, J, 3): OpenSim ground
        self.jchild = list(res["joint_child"])

    def joint_centre(self, child: str) -> np.ndarray:
        if child not in self.jchild:
            raise OpenSimError(f"{self.model}: no joint has body {child!r} as its child")
        return self.JC[:, self.jchild.index(child)]

    def ours(self, p_osim: np.ndarray) -> np.ndarray:
        return to_ours_p(p_osim - self.off)

    def legs(self) -> dict[str, np.ndarray]:
        """Hip, knee, ankle, mtp joint centres, heel and toe on the sole (see the package doc), pelvis."""
        bi, Rb, Pb, off = self.bi, self.Rb, self.Pb, self.off
        lm: dict[str, np.ndarray] = {}
        for s in "rl":
            lm[f"hip_{s}"] = self.ours(self.joint_centre(f"femur_{s}"))
            lm[f"knee_{s}"] = self.ours(self.joint_centre(f"tibia_{s}"))
            ankle_child = f"talus_{s}" if f"talus_{s}" in bi else f"calcn_{s}"
            lm[f"ankle_{s}"] = self.ours(self.joint_centre(ankle_child))
            lm[f"mtp_{s}"] = self.ours(self.joint_centre(f"toes_{s}"))
            # sole: the calcn origin's height above the floor at mid-stance
            c = bi[f"calcn_{s}"]
            calcn_o = Pb[:, c] - off
            up_c = Rb[:, c, :, 1]  # calcn y axis in ground
            sole = float(np.percentile(calcn_o[:, 1], 2))
            heel = calcn_o - sole * up_c
            t_i = bi[f"toes_{s}"]
            toes_com_x = float(self.res["body_com"][t_i][0])
            if toes_com_x <= 0.005:
                raise OpenSimError(f"{self.model}: toes_{s} centre of mass x={toes_com_x} m does not point forward; "
                                   "cannot place the toe tip")
            toe = (Pb[:, t_i] - off) + 2 * toes_com_x * Rb[:, t_i, :, 0]
            toe = toe - (np.einsum("ti,ti->t", toe - heel, up_c))[:, None] * up_c  # onto the sole plane
            lm[f"heel_{s}"] = to_ours_p(heel)
            lm[f"toe_{s}"] = to_ours_p(toe)
        add_pelvis(lm)
        return lm

    def orientations(self, seg_of: Mapping[str, str | None]) -> dict[str, np.ndarray]:
        """Each segment's orientation from its orienting body (_ORIENTING)."""
        ori: dict[str, np.ndarray] = {}
        for b, i in self.bi.items():
            seg = seg_of[b]
            if seg is None:
                continue
            kind = seg.rsplit("_", 1)[0] if seg[-2:] in ("_r", "_l") else seg
            if _ORIENTING.get(kind) and b.startswith(_ORIENTING[kind]):
                ori[seg] = to_ours_R(self.Rb[:, i])
        return ori

    def arms(self, lm: dict[str, np.ndarray], ori: dict[str, np.ndarray], height: float | None) -> None:
        """A model with arms: shoulder, elbow, wrist, hand tip; neck, head top and sternum fixed
        to the torso (fractions of the body height, see the package doc)."""
        bi, Rb, Pb = self.bi, self.Rb, self.Pb
        R_t = Rb[:, bi["torso"]]
        for s in "rl":
            lm[f"shoulder_{s}"] = self.ours(self.joint_centre(f"humerus_{s}"))
            lm[f"elbow_{s}"] = self.ours(self.joint_centre(f"ulna_{s}"))
            lm[f"wrist_{s}"] = self.ours(self.joint_centre(f"hand_{s}"))
            h = bi[f"hand_{s}"]
            com_h = np.asarray(self.res["body_com"][h])
            lm[f"hand_{s}"] = self.ours(Pb[:, h] + 2 * np.einsum("tij,j->ti", Rb[:, h], com_h))
        h_est = height or _height_from_legs(lm)
        sh_mid = 0.5 * (self.joint_centre("humerus_r") + self.joint_centre("humerus_l"))
        up_t, fwd_t = R_t[:, :, 1], R_t[:, :, 0]
        neck = sh_mid + 0.06 * h_est * up_t
        lm["neck"] = self.ours(neck)
        lm["head_top"] = self.ours(neck + 0.13 * h_est * up_t)
        lm["sternum"] = self.ours(sh_mid + 0.04 * h_est * fwd_t - 0.08 * h_est * up_t)
        for seg in ("abdomen", "thorax", "head", "clavicle_r", "clavicle_l"):
            ori[seg] = to_ours_R(R_t)

    def armless_torso(self, lm: dict[str, np.ndarray], ori: dict[str, np.ndarray], height: float) -> None:
        """No arms in the model: the canonical upper body (capture_full's neutral pose for the
        subject's height) rides rigidly on the torso from the lumbar joint; its segments other
        than the abdomen are placeholders (see _ARMLESS_PLACEHOLDERS)."""
        R_t = self.Rb[:, self.bi["torso"]]
        lumbar = self.joint_centre("torso")
        for name, v in _neutral_upper_body(height).items():
            lm[name] = self.ours(lumbar + np.einsum("tij,j->ti", R_t, C_OSIM.T @ v))
        for seg in ("abdomen",) + _ARMLESS_PLACEHOLDERS:
            ori[seg] = to_ours_R(R_t)


def _segment_masses(body_mass: Mapping[str, float], seg_of: Mapping[str, str | None], model: str,
                    armless_torso: bool) -> dict[str, float]:
    """Our segments' masses: the sum of their bodies' (the torso split by Winter's ratios; an
    arm-less torso's placeholders given a negligible share of it)."""
    seg_mass: dict[str, float] = {}
    for b, m in body_mass.items():
        seg = seg_of[b]
        if seg is None:
            raise OpenSimError(f"{model}: cannot map body {b!r} to a segment")
        if seg == "torso":
            split_mass(m, _TORSO_SPLIT, into=seg_mass)
            eps = PLACEHOLDER_MASS_FRACTION * float(sum(body_mass.values()))
            for c in _CLAVICLES:
                seg_mass[c] = eps
            seg_mass["abdomen"] -= eps * len(_CLAVICLES)
            continue
        seg_mass[seg] = seg_mass.get(seg, 0.0) + m
    if armless_torso:
        eps = PLACEHOLDER_MASS_FRACTION * float(sum(body_mass.values()))
        for seg in _ARMLESS_PLACEHOLDERS:
            seg_mass[seg] = eps
        seg_mass["abdomen"] -= eps * len(_ARMLESS_PLACEHOLDERS)  # the total stays the model's
    return seg_mass


def opensim_track(model: str | Path, motion: str | Path, **options: Any) -> SkeletonTrack:
    """Evaluate the OpenSim model along the motion and return landmarks + orientations (ours).

    ``motion``: coordinates (``.mot``/``.sto``), or marker trajectories (``.trc``) whose
    inverse kinematics OpenSim solves first (:func:`solver.io.opensim.ik.solve_ik`;
    ``ik_weights``, ``ik_reweight``). ``options``: those of :func:`opensim_evaluation`.
    """
    return opensim_evaluation(model, motion, **options)[0]


def opensim_evaluation(
    model: str | Path,
    motion: str | Path,
    *,
    mass: float | None = None,
    belt_speed: float | str | None = None,
    grf: str | Path | None = None,
    grf_xml: str | Path | None = None,
    in_degrees: bool | None = None,
    floor_height: float | None = None,
    height: float | None = None,
    ik_weights: Mapping[str, float] | None = None,
    ik_reweight: int | None = None,
) -> tuple[SkeletonTrack, dict[str, Any]]:
    """:func:`opensim_track` and OpenSim's own evaluation it comes from (the worker's result:
    the model's coordinates, bodies, and ``coordinates`` = (columns, values (T, K) in radians
    and metres) along the motion): what the importer keeps for writing results back on the
    model (:func:`solver.io.opensim.rig.opensim_rig`)."""
    model = str(model)
    if not Path(model).is_file():
        raise OpenSimError(f"model file not found: {model}")
    res, times, src_extra = _evaluate(model, motion, in_degrees, ik_weights, ik_reweight)
    seg_of, has_torso, has_arms = _body_segments(res, model)
    # floor height (OpenSim y): given, else from the GRF's centre of pressure, else 0
    floor = floor_height
    if floor is None and grf is not None:
        floor = floor_from_grf(grf, grf_xml)
    floor = 0.0 if floor is None else float(floor)
    off = np.array([0.0, floor, 0.0])
    bodies = _Bodies(res, model, off)
    lm = bodies.legs()
    ori = bodies.orientations(seg_of)
    if has_torso:
        lm["lumbar"] = bodies.ours(bodies.joint_centre("torso"))
    if has_arms:
        bodies.arms(lm, ori, height)
    elif has_torso:
        height = height or _height_from_legs(lm)
        bodies.armless_torso(lm, ori, height)
    body_mass = dict(zip(res["body_names"], (float(m) for m in res["body_mass"])))
    total = model_total = float(sum(body_mass.values()))
    seg_mass = _segment_masses(body_mass, seg_of, model, has_torso and not has_arms)
    if mass is not None and abs(mass - total) > 0.01 * total:
        log.warning("subject mass %.2f kg given, the OpenSim model weighs %.2f kg: using the model's segment masses "
                    "scaled to %.2f kg", mass, total, mass)
        seg_mass, total = rescaled_masses(seg_mass, total, mass)
    frame = GroundFrame(R=C_OSIM.T, offset=off, unit_m=1.0, axes="OpenSim ground: x forward, y up, z right")
    track = SkeletonTrack(
        times=times, landmarks=lm, orientations=ori, frame=frame, mass=total, height=height,
        segment_masses=seg_mass,
        source={
            "format": "opensim",
            "model": str(Path(model).resolve()),
            "motion": str(Path(motion).resolve()),
            "model_name": res.get("model_name"),
            "model_mass_kg": model_total,
            "mass_from": "model" if mass is None else "given",
            "notes": list(res.get("notes", [])),
            "angles_in_degrees": bool(res["in_degrees"]),
            "floor_height_osim_y": floor,
            "body_to_segment": {b: s for b, s in seg_of.items()},
            **src_extra,
        },
    )
    track = _with_segment_inertias(track, res, seg_of, off)
    if belt_speed is not None:
        track = belt_shift(track, belt_speed, grf, grf_xml)
    return track, res


def _neutral_upper_body(height: float) -> dict[str, np.ndarray]:
    """Upper-body landmarks of ``capture_full(height)`` in its neutral pose, relative to the
    lumbar joint, our axes: where an arm-less model's torso carries them."""

    ch = capture_full(height)
    pts = {"lumbar": ("abdomen", np.zeros(3)), "neck": ("head", np.zeros(3)),
           "head_top": ("head", ch.segment("head").marker)}
    for side in "rl":
        pts[f"shoulder_{side}"] = (f"upper_arm_{side}", np.zeros(3))
        pts[f"elbow_{side}"] = (f"forearm_{side}", np.zeros(3))
        pts[f"wrist_{side}"] = (f"hand_{side}", np.zeros(3))
        pts[f"hand_{side}"] = (f"hand_{side}", ch.segment(f"hand_{side}").marker)
    xyz = points_world(ch, np.zeros(ch.n), list(pts.values()))
    out = {k: np.asarray(xyz[i], dtype=float).reshape(3) for i, k in enumerate(pts)}
    lumbar = out.pop("lumbar")
    out = {k: v - lumbar for k, v in out.items()}
    # sternum: as for models with arms, 4 % H forward of and 8 % H below the shoulders' mid-point
    sh = 0.5 * (out["shoulder_r"] + out["shoulder_l"])
    out["sternum"] = sh + height * np.array([0.04, 0.0, -0.08])
    return out


def _height_from_legs(lm: Mapping[str, np.ndarray]) -> float:

    leg = np.nanmedian(lm["hip_r"][2] - np.minimum(lm["heel_r"][2], lm["toe_r"][2]))
    return float(np.nanmax([leg / HIP_HEIGHT_FRACTION, 0.5]))


def _with_segment_inertias(track: SkeletonTrack, res, seg_of, off) -> SkeletonTrack:
    """Per-segment COM and inertia (segment frame, about the COM) from the OpenSim bodies.

    Composite of every body mapped to the segment, at the model's default pose, expressed
    in the orienting body's axes (relabelled to ours) relative to the segment's origin
    landmark (measured in that body's frame, median over the trial).
    """

    names = list(res["body_names"])
    bi = {b: i for i, b in enumerate(names)}
    R0, P0 = res["R0"], res["P0"]
    Rb, Pb = res["R"], res["P"]
    out: dict[str, dict] = {}

    def origin_in_body(landmark: np.ndarray, i: int) -> np.ndarray:
        """A segment origin (ours, (3, T)) in body i's frame (OpenSim axes), median over the trial."""
        o_ground = (np.asarray(landmark).T @ C_OSIM) + off  # ours -> OpenSim ground
        return np.median(np.einsum("tji,tj->ti", Rb[:, i], o_ground - Pb[:, i]), axis=0)

    if "torso" in seg_of.values() and "lumbar" in track.landmarks and "neck" in track.landmarks:
        # a torso split between trunk segments: each part at the torso's centre of mass with its share of
        # the torso's inertia (the composite is the torso body's mass, centre of mass and inertia)
        t_i = bi[next(b for b, sg in seg_of.items() if sg == "torso")]
        lm = dict(track.landmarks)
        lm["@thorax_joint"] = lm["lumbar"] + THORAX_JOINT_FRACTION * (lm["neck"] - lm["lumbar"])
        m_t = float(res["body_mass"][t_i])
        com_t = np.asarray(res["body_com"][t_i], dtype=float)
        inertia_t = C_OSIM @ np.asarray(res["body_inertia"][t_i], dtype=float) @ C_OSIM.T
        for seg, origin in _TRUNK_ORIGINS.items():
            share = float((track.segment_masses or {}).get(seg, 0.0)) / m_t if m_t > 0 else 0.0
            out[seg] = {"com": C_OSIM @ (com_t - origin_in_body(lm[origin], t_i)), "inertia": share * inertia_t}
    groups: dict[str, list[str]] = {}
    for b, s in seg_of.items():
        if s is not None and s != "torso":
            groups.setdefault(s, []).append(b)
    for seg, bodies in groups.items():
        kind = seg.rsplit("_", 1)[0] if seg[-2:] in ("_r", "_l") else seg
        main = next((b for b in bodies if b.startswith(_ORIENTING.get(kind, "\0"))), None)
        if main is None or seg not in SEGMENT_LANDMARKS:
            continue
        origin_name = SEGMENT_LANDMARKS[seg][0]
        if origin_name not in track.landmarks:
            continue
        m_i = bi[main]
        o_body = origin_in_body(track.landmarks[origin_name], m_i)  # the segment origin in the main body's frame
        M = 0.0
        mc = np.zeros(3)
        parts = []
        for b in bodies:
            i = bi[b]
            m = float(res["body_mass"][i])
            # body i's COM and inertia in the main body's frame, default pose
            Rrel = R0[m_i].T @ R0[i]
            prel = R0[m_i].T @ (P0[i] - P0[m_i])
            c = prel + Rrel @ np.asarray(res["body_com"][i])
            Ic = Rrel @ np.asarray(res["body_inertia"][i]) @ Rrel.T
            parts.append((m, c, Ic))
            M += m
            mc += m * c
        if M <= 0:
            continue
        com = mc / M
        inertia = np.zeros((3, 3))
        for m, c, Ic in parts:
            d = c - com
            inertia += Ic + m * (float(d @ d) * np.eye(3) - np.outer(d, d))
        # the segment's mass over its bodies' (a subject mass given, placeholders): inertia scaled alike
        k = float((track.segment_masses or {}).get(seg, M)) / M
        out[seg] = {"com": C_OSIM @ (com - o_body), "inertia": k * (C_OSIM @ inertia @ C_OSIM.T)}
    return track.evolve(source_update={"segment_inertias": out})

