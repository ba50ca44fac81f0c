"""OpenSim importer: ``.osim`` model + ``.mot``/``.sto`` coordinates (+ GRF ``.mot`` / ExternalLoads ``.xml``).

Public API::

    read_mot(path) -> Storage                                  # any OpenSim .mot/.sto table
    load_opensim(model, motion, *, mass=None, belt_speed=None, grf=None, grf_xml=None,
                 lower_only=None, in_degrees=None, floor_height=None) -> Capture
    opensim_track(model, motion, ...) -> SkeletonTrack         # the same, before fitting
    read_opensim_grf(mot, xml=None, *, times, frame=GroundFrame(), contacts=None,
                     threshold=20.0) -> MeasuredGRF
    estimate_belt_speed(track) -> float                        # treadmill belt (m/s), from the stance feet

**The OpenSim model is evaluated by OpenSim itself** (PyPI ``opensim``): body frames in
ground for every frame (``initSystem``, coordinate values, ``realizePosition``,
``getTransformInGround``). The ``opensim`` wheel ships its own ``libcasadi.so.3.7`` with the
same soname as CasADi's but other symbols, so the two cannot live in one process: OpenSim
runs in a short-lived child process (this module, ``python -c ...``) that exchanges plain
numpy arrays with the caller. Models in the old 3.x format whose upgrade fails
``initSystem()`` (e.g. ``Rajagopal2016_subject05_v30516.osim``: joint sockets ``../pelvis``)
are repaired in memory: socket paths ``../(../)*body`` become ``/bodyset/body`` and the
force set, markers and probes (irrelevant to kinematics and inertia) are dropped.

**Axes.** OpenSim ground: X forward, Y up, Z right. Ours: X forward, Y left, Z up, so
``p_ours = C p_osim`` with ``C = [[1,0,0],[0,0,-1],[0,1,0]]``; body orientations become
``C R C^T`` (OpenSim bodies are ground-aligned in the default pose, as our segments at
q = 0). ``GroundFrame.R = C^T``; ``offset`` = the floor height in OpenSim ground (0 unless
``floor_height`` is given or the GRF file's centre of pressure tells it, e.g. -0.0075 m on
the treadmill trial); ``velocity`` = the belt velocity when ``belt_speed`` is set.

**Body -> segment map** (by name; a body no rule knows is lumped into its parent's segment):

==========================  =============================================================
OpenSim bodies              our segment (orientation taken from the first body listed)
==========================  =============================================================
pelvis                      pelvis
femur_s                     thigh_s
tibia_s (+ patella_s)       shank_s
calcn_s + talus_s           foot_s  (talus: ankle landmark; calcn: heel, orientation)
toes_s                      toes_s
torso                       abdomen + thorax + head (mass split by Winter's ratios
                            0.139 : 0.196 : 0.081 [: clavicles 0.010 each]) — or, without
                            arms in the model (gait2354: the torso body is head, arms and
                            trunk), the abdomen alone, with the body's own mass, centre of
                            mass and inertia (see below)
humerus_s                   upper_arm_s
radius_s + ulna_s           forearm_s
hand_s                      hand_s
==========================  =============================================================

**Landmarks** (all from the evaluated model): pelvis = mid-point of the hip joint centres;
hip/knee/ankle/mtp = centres of the joints whose child is femur/tibia/talus/toes (child
frame origin in ground); lumbar = centre of the joint whose child is the torso; shoulder,
elbow, wrist = centres of the joints whose child is humerus, ulna, hand. The foot's sole is
found from the data: *heel* = the calcn origin moved down along the calcn's vertical to the
sole, *toe* = the toes origin moved forward along the toes' x by twice the toes' centre of
mass abscissa (the far end of the toes, the COM being mid-length) and down to the sole; the
sole lies ``sole`` below the calcn origin, ``sole`` = the calcn origin's height above the
floor at mid-stance (2nd percentile over the trial). Without a torso body the upper body
is absent (capture-lower). A torso body without arms (gait2354) gives a ``capture-full``
skeleton whose abdomen *is* the torso, driven by the lumbar coordinates: the canonical
upper-body landmarks (neck, head top, sternum, shoulders, elbows, wrists, hands: the neutral
pose of ``capture_full`` for the subject's height) ride rigidly on the torso from the lumbar
joint, and the thorax, head, clavicle and arm segments are placeholders of negligible mass
(``PLACEHOLDER_MASS_FRACTION`` of the subject each, taken from the torso: MuJoCo refuses
massless moving bodies). The trunk thus keeps its real motion and mass distribution;
``lower_only=True`` lumps it into the pelvis (``merge_segments``). With arms, the torso carries neck (on the torso's
vertical through the shoulder centres, 6 % of body height above them), head top (13 %
above the neck) and sternum (between the shoulders, 4 % of height forward and 8 % down):
they are rigidly attached to the torso, so they only set the neck/head lengths of the
capture skeleton (OpenSim's torso includes the head). Hand tip = wrist + twice the hand's
COM offset. Body height, when the source does not give it, is estimated by the fit.
"""

from __future__ import annotations

import json
import logging
import math
import os
import re
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from solver.capture import Capture, GroundFrame, MeasuredGRF
from solver.io.track import SkeletonTrack

log = logging.getLogger(__name__)

__all__ = [
    "OpenSimError",
    "Storage",
    "read_mot",
    "load_opensim",
    "opensim_track",
    "read_opensim_grf",
    "estimate_belt_speed",
    "C_OSIM",
]


class OpenSimError(ValueError):
    """An OpenSim input is unreadable or inconsistent; the message names the problem."""


#: OpenSim ground (X forward, Y up, Z right) -> ours (X forward, Y left, Z up).
C_OSIM = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
WORKER_TIMEOUT_S = 300.0


# --- .mot / .sto -------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Storage:
    """An OpenSim table: header key/values, column labels (without ``time``), data."""

    path: str
    header: Mapping[str, str]
    labels: tuple[str, ...]
    time: np.ndarray  # (T,)
    data: np.ndarray  # (T, C)
    in_degrees: bool | None = None  # from the header (None: not stated)
    header_text: str = ""

    def column(self, name: str) -> np.ndarray:
        try:
            return self.data[:, self.labels.index(name)]
        except ValueError:
            raise OpenSimError(f"{self.path}: no column {name!r}") from None


def read_mot(path: str | Path) -> Storage:
    """Read an OpenSim .mot/.sto file (header ended by ``endheader``; tab or space separated)."""
    p = Path(path)
    if not p.is_file():
        raise OpenSimError(f"file not found: {p}")
    lines = p.read_text(errors="replace").splitlines()
    try:
        end = next(i for i, ln in enumerate(lines) if ln.strip().lower() == "endheader")
    except StopIteration:
        raise OpenSimError(f"{p}: not an OpenSim .mot/.sto file (no 'endheader' line)") from None
    header: dict[str, str] = {}
    for ln in lines[:end]:
        if "=" in ln:
            k, v = ln.split("=", 1)
            header[k.strip()] = v.strip()
    body = [ln for ln in lines[end + 1:] if ln.strip()]
    if not body:
        raise OpenSimError(f"{p}: no column labels after 'endheader'")
    labels = body[0].split("\t") if "\t" in body[0] else body[0].split()
    labels = [s.strip() for s in labels]
    while labels and labels[-1] == "":
        labels.pop()
    if not labels or labels[0].lower() != "time":
        raise OpenSimError(f"{p}: the first column must be 'time', got {labels[:1]}")
    if len(set(labels)) != len(labels):
        dup = sorted({x for x in labels if labels.count(x) > 1})
        raise OpenSimError(f"{p}: duplicate column labels {dup}")
    rows = []
    for k, ln in enumerate(body[1:]):
        parts = ln.split()
        if len(parts) != len(labels):
            raise OpenSimError(f"{p}: data row {k + 1} has {len(parts)} values, expected {len(labels)}")
        try:
            rows.append([float(x) for x in parts])
        except ValueError:
            raise OpenSimError(f"{p}: data row {k + 1} is not numeric: {ln[:80]!r}") from None
    if not rows:
        raise OpenSimError(f"{p}: no data rows")
    arr = np.array(rows)
    bad = ~np.isfinite(arr)
    if np.any(bad):
        r, c = np.argwhere(bad)[0]
        nrows = int(np.any(bad, axis=1).sum())
        raise OpenSimError(f"{p}: {nrows} row(s) contain NaN/inf values (first: row {r + 1}, column {labels[c]!r})")
    t = arr[:, 0]
    if len(t) > 1 and not np.all(np.diff(t) > 0):
        k = int(np.argmax(np.diff(t) <= 0))
        raise OpenSimError(f"{p}: time must increase strictly (row {k + 2}: {t[k + 1]} after {t[k]})")
    if "nRows" in header and header["nRows"].isdigit() and int(header["nRows"]) != len(t):
        log.info("%s: header says nRows=%s but the file has %d rows (using the rows)", p, header["nRows"], len(t))
    deg = header.get("inDegrees")
    in_deg = None if deg is None else deg.strip().lower() in ("yes", "true", "1")
    return Storage(str(p), header, tuple(labels[1:]), t, arr[:, 1:], in_deg, "\n".join(lines[:end]))


# --- OpenSim in a child process --------------------------------------------------------------


def _repair_model_xml(src: str, dst: str) -> None:
    """Rewrite a 3.x-era model whose sockets name bodies as ``../body`` (see module doc)."""
    tree = ET.parse(src)
    root = tree.getroot()
    model = root.find("Model")
    if model is None:
        raise OpenSimError(f"{src}: no <Model> element")
    bodies = {b.get("name") for b in model.iter("Body")}
    for tag in ("ForceSet", "MarkerSet", "ProbeSet", "ContactGeometrySet", "ControllerSet", "ComponentSet"):
        el = model.find(tag)
        objs = el.find("objects") if el is not None else None
        if objs is not None:
            for c in list(objs):
                objs.remove(c)
    for el in model.iter():
        if el.tag.startswith("socket_") and el.tag.endswith("connectee_name") and el.text:
            m = re.fullmatch(r"(?:\.\./)+(\w+)", el.text.strip())
            if m:
                name = m.group(1)
                if name == "ground":
                    el.text = "/ground"
                elif name in bodies:
                    el.text = "/bodyset/" + name
    tree.write(dst)


def _worker_main() -> None:  # pragma: no cover - runs in the child process (exercised by every OpenSim test)
    """Child process: evaluate an OpenSim model along a coordinate trajectory."""
    import opensim as osim  # first import of the process: its casadi wins

    osim.Logger.setLevelString("error")
    req = json.loads(sys.stdin.read())
    out: dict[str, Any] = {}
    notes: list[str] = []

    def load(path: str):
        m = osim.Model(path)
        s = m.initSystem()
        return m, s

    try:
        try:
            model, state = load(req["model"])
        except Exception as first:  # noqa: BLE001 - OpenSim raises RuntimeError subclasses
            fd, tmp = tempfile.mkstemp(suffix=".osim")
            os.close(fd)
            try:
                _repair_model_xml(req["model"], tmp)
                model, state = load(tmp)
            except Exception as second:  # noqa: BLE001
                raise RuntimeError(f"OpenSim cannot initialize the model: {first}; after repair: {second}") from None
            finally:
                os.unlink(tmp)
            notes.append("model repaired in memory (3.x socket paths -> /bodyset/...; forces/markers dropped)")
        cs = model.getCoordinateSet()
        coords = [cs.get(i) for i in range(cs.getSize())]
        names = [c.getName() for c in coords]
        rot = [c.getMotionType() == osim.Coordinate.Rotational for c in coords]
        out["coord_names"] = names
        out["coord_rotational"] = rot
        out["coord_constrained"] = [bool(c.isConstrained(state)) or bool(c.getLocked(state)) for c in coords]
        out["coord_default"] = [c.getDefaultValue() for c in coords]
        bodies = [model.getBodySet().get(i) for i in range(model.getBodySet().getSize())]
        out["body_names"] = [b.getName() for b in bodies]
        out["body_mass"] = [b.getMass() for b in bodies]
        out["body_com"] = [list(b.getMassCenter().to_numpy()) for b in bodies]
        inert = []
        for b in bodies:
            i = b.getInertia()
            mo, pr = i.getMoments().to_numpy(), i.getProducts().to_numpy()
            inert.append([[mo[0], pr[0], pr[1]], [pr[0], mo[1], pr[2]], [pr[1], pr[2], mo[2]]])
        out["body_inertia"] = inert  # about the body's COM, body axes (OpenSim convention)
        joints = [model.getJointSet().get(i) for i in range(model.getJointSet().getSize())]
        out["joint_names"] = [j.getName() for j in joints]

        def base_body(frame) -> str:
            return frame.findBaseFrame().getName()

        out["joint_child"] = [base_body(j.getChildFrame()) for j in joints]
        out["joint_parent"] = [base_body(j.getParentFrame()) for j in joints]
        values = np.asarray(req["values"], dtype=float).reshape(len(req["values"]), -1)  # (T, K)
        cols = req["columns"]
        known = [k for k, c in enumerate(cols) if c in names]  # the parent reports the others
        idx = [names.index(cols[k]) for k in known]
        values = values[:, known] if values.size else np.zeros((0, 0))
        deg = req.get("in_degrees")
        if deg is None:  # the header does not say: rotations beyond 2π can only be degrees
            rot_cols = [j for j, c_i in enumerate(idx) if rot[c_i]]
            deg = bool(rot_cols) and float(np.abs(values[:, rot_cols]).max()) > 2 * np.pi
            notes.append(f"angle unit not stated in the header: {'degrees' if deg else 'radians'} "
                         "inferred from the values")
        out["in_degrees"] = bool(deg)
        if deg:
            for j, c_i in enumerate(idx):
                if rot[c_i]:
                    values[:, j] = np.radians(values[:, j])
        T = values.shape[0]
        B, J = len(bodies), len(joints)
        R = np.zeros((T, B, 3, 3))
        P = np.zeros((T, B, 3))
        JC = np.zeros((T, J, 3))

        def snapshot(st, k: int) -> None:
            model.realizePosition(st)
            for b_i, b in enumerate(bodies):
                tr = b.getTransformInGround(st)
                R[k, b_i] = _mat33(tr.R())
                P[k, b_i] = tr.p().to_numpy()
            for j_i, j in enumerate(joints):
                JC[k, j_i] = j.getChildFrame().getPositionInGround(st).to_numpy()

        for k in range(T):
            for c_i, v in zip(idx, values[k]):
                coords[c_i].setValue(state, float(v), False)
            snapshot(state, k)
        # default pose (composite inertias, offsets)
        st0 = model.initializeState()
        R0, P0 = np.zeros((1, B, 3, 3)), np.zeros((1, B, 3))
        model.realizePosition(st0)
        for b_i, b in enumerate(bodies):
            tr = b.getTransformInGround(st0)
            R0[0, b_i] = _mat33(tr.R())
            P0[0, b_i] = tr.p().to_numpy()
        out["model_name"] = model.getName()
        out["total_mass"] = model.getTotalMass(state)
        out["notes"] = notes
        np.savez(req["out"], R=R, P=P, JC=JC, R0=R0[0], P0=P0[0], meta=json.dumps(out))
    except Exception as e:  # noqa: BLE001 - reported to the parent as one line
        with open(req["out"] + ".err", "w") as f:
            f.write(str(e))
        sys.exit(3)


def _mat33(rot) -> np.ndarray:  # pragma: no cover - child process
    return np.array([[rot.get(i, j) for j in range(3)] for i in range(3)])


def _run_worker(model_path: str, columns: Sequence[str], values: np.ndarray, in_degrees: bool | None) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="motionx-osim-") as d:
        out = os.path.join(d, "result.npz")
        req = {"model": str(Path(model_path).resolve()), "columns": list(columns),
               "values": np.asarray(values).tolist(), "in_degrees": in_degrees, "out": out}
        root = str(Path(__file__).resolve().parents[2])
        env = dict(os.environ)
        env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        code = "from solver.io.opensim import _worker_main; _worker_main()"
        try:
            proc = subprocess.run([sys.executable, "-c", code], input=json.dumps(req), text=True,
                                  capture_output=True, env=env, timeout=WORKER_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            raise OpenSimError(f"OpenSim did not finish evaluating {model_path} within {WORKER_TIMEOUT_S:.0f} s") from None
        if proc.returncode != 0:
            err = Path(out + ".err")
            msg = err.read_text() if err.exists() else (proc.stderr.strip().splitlines() or ["(no message)"])[-1]
            if "No module named 'opensim'" in proc.stderr:
                msg = "the 'opensim' package is not installed (pip install opensim)"
            raise OpenSimError(f"OpenSim could not evaluate {model_path}: {msg}")
        with np.load(out) as z:
            res = {k: z[k] for k in ("R", "P", "JC", "R0", "P0")}
            res.update(json.loads(str(z["meta"])))
    return res


# --- model -> landmarks ---------------------------------------------------------------------------

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
#: torso mass split (Winter) when the capture skeleton has an upper body
_TORSO_SPLIT = {"abdomen": 0.139, "thorax": 0.196, "head": 0.081, "clavicle_r": 0.010, "clavicle_l": 0.010}
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


def _to_ours_R(R: np.ndarray) -> np.ndarray:
    """OpenSim (T, 3, 3) body rotations -> ours (3, 3, T)."""
    return np.moveaxis(C_OSIM @ R @ C_OSIM.T, 0, -1)


def _to_ours_p(p: np.ndarray) -> np.ndarray:
    """OpenSim (T, 3) points -> ours (3, T)."""
    return (p @ C_OSIM.T).T


def _check_motion(sto: Storage, res: Mapping[str, Any], model_path: str) -> None:
    names = list(res["coord_names"])
    unknown = [c for c in sto.labels if c not in names]
    if unknown:
        raise OpenSimError(
            f"model/motion mismatch: {sto.path} has columns {unknown} that are not coordinates of "
            f"{model_path} (model coordinates: {names})"
        )
    missing = [c for c, constrained in zip(names, res["coord_constrained"]) if c not in sto.labels and not constrained]
    if missing:
        raise OpenSimError(f"model/motion mismatch: {sto.path} lacks the model's coordinates {missing}")


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


def opensim_track(
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
) -> SkeletonTrack:
    """Evaluate the OpenSim model along the motion and return landmarks + orientations (ours)."""
    model = str(model)
    if not Path(model).is_file():
        raise OpenSimError(f"model file not found: {model}")
    sto = read_mot(motion)
    if len(sto.time) < 2:
        raise OpenSimError(f"{motion}: a motion needs at least 2 frames, got {len(sto.time)}")
    deg = _angles_in_degrees(sto, in_degrees)
    res = _run_worker(model, sto.labels, sto.data, deg)
    _check_motion(sto, res, model)
    times = sto.time.astype(float)

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
    bi = {b: i for i, b in enumerate(names)}
    for need in ("pelvis", "femur_r", "femur_l", "tibia_r", "tibia_l", "calcn_r", "calcn_l", "toes_r", "toes_l"):
        if need not in bi:
            raise OpenSimError(f"{model}: body {need!r} not found; the importer needs a gait-model leg "
                               f"(pelvis, femur, tibia, talus, calcn, toes per side); bodies: {names}")
    has_torso = "torso" in bi
    has_arms = has_torso and all(f"{b}_{s}" in bi for b in ("humerus", "ulna", "radius", "hand") for s in "rl")
    arm = ("upper_arm", "forearm", "hand")
    if not has_torso:  # no trunk body: anything above the hips rides with the pelvis (capture-lower)
        seg_of = {b: ("pelvis" if (s or "").startswith(arm) else s) for b, s in seg_of.items()}
    elif not has_arms:  # the torso body is head, arms and trunk (gait2354): the abdomen carries it whole
        seg_of = {b: ("abdomen" if s == "torso" or (s or "").startswith(arm) else s) for b, s in seg_of.items()}
    Rb = res["R"]  # (T, B, 3, 3) OpenSim ground
    Pb = res["P"]  # (T, B, 3)
    JC = res["JC"]  # (T, J, 3)
    jchild = list(res["joint_child"])

    def joint_centre(child: str) -> np.ndarray:
        if child not in jchild:
            raise OpenSimError(f"{model}: no joint has body {child!r} as its child")
        return JC[:, jchild.index(child)]

    # floor height (OpenSim y): given, else from the GRF's centre of pressure, else 0
    floor = floor_height
    if floor is None and grf is not None:
        floor = _floor_from_grf(grf, grf_xml)
    floor = 0.0 if floor is None else float(floor)
    off = np.array([0.0, floor, 0.0])

    def P_ours(p_osim: np.ndarray) -> np.ndarray:
        return _to_ours_p(p_osim - off)

    lm: dict[str, np.ndarray] = {}
    ori: dict[str, np.ndarray] = {}
    for s in "rl":
        lm[f"hip_{s}"] = P_ours(joint_centre(f"femur_{s}"))
        lm[f"knee_{s}"] = P_ours(joint_centre(f"tibia_{s}"))
        ankle_child = f"talus_{s}" if f"talus_{s}" in bi else f"calcn_{s}"
        lm[f"ankle_{s}"] = P_ours(joint_centre(ankle_child))
        lm[f"mtp_{s}"] = P_ours(joint_centre(f"toes_{s}"))
        # sole: the calcn origin's height above the floor at mid-stance
        c = bi[f"calcn_{s}"]
        calcn_o = Pb[:, c] - off
        up_c = Rb[:, c, :, 1]  # calcn y axis in ground
        sole = float(np.percentile(calcn_o[:, 1], 2))
        heel = calcn_o - sole * up_c
        t_i = bi[f"toes_{s}"]
        toes_com_x = float(res["body_com"][t_i][0])
        if toes_com_x <= 0.005:
            raise OpenSimError(f"{model}: toes_{s} centre of mass x={toes_com_x} m does not point forward; "
                               "cannot place the toe tip")
        toe = (Pb[:, t_i] - off) + 2 * toes_com_x * Rb[:, t_i, :, 0]
        toe = toe - (np.einsum("ti,ti->t", toe - heel, up_c))[:, None] * up_c  # onto the sole plane
        lm[f"heel_{s}"] = _to_ours_p(heel)
        lm[f"toe_{s}"] = _to_ours_p(toe)
    lm["pelvis"] = 0.5 * (lm["hip_r"] + lm["hip_l"])
    for b, i in bi.items():
        seg = seg_of[b]
        if seg is None:
            continue
        kind = seg.rsplit("_", 1)[0] if seg[-2:] in ("_r", "_l") else seg
        if _ORIENTING.get(kind) and b.startswith(_ORIENTING[kind]):
            ori[seg] = _to_ours_R(Rb[:, i])
    if "torso" in bi:
        lm["lumbar"] = P_ours(joint_centre("torso"))
    body_mass = dict(zip(names, (float(m) for m in res["body_mass"])))
    total = float(sum(body_mass.values()))
    if has_arms:
        tor = bi["torso"]
        R_t = Rb[:, tor]
        for s in "rl":
            lm[f"shoulder_{s}"] = P_ours(joint_centre(f"humerus_{s}"))
            lm[f"elbow_{s}"] = P_ours(joint_centre(f"ulna_{s}"))
            lm[f"wrist_{s}"] = P_ours(joint_centre(f"hand_{s}"))
            h = bi[f"hand_{s}"]
            com_h = np.asarray(res["body_com"][h])
            lm[f"hand_{s}"] = P_ours(Pb[:, h] + 2 * np.einsum("tij,j->ti", Rb[:, h], com_h))
        # torso-fixed head/neck/sternum points (see module doc); body height estimate
        h_est = height or _height_from_legs(lm)
        sh_mid = 0.5 * (joint_centre("humerus_r") + joint_centre("humerus_l"))
        up_t, fwd_t = R_t[:, :, 1], R_t[:, :, 0]
        neck = sh_mid + 0.06 * h_est * up_t
        lm["neck"] = P_ours(neck)
        lm["head_top"] = P_ours(neck + 0.13 * h_est * up_t)
        lm["sternum"] = P_ours(sh_mid + 0.04 * h_est * fwd_t - 0.08 * h_est * up_t)
        for seg in ("abdomen", "thorax", "head", "clavicle_r", "clavicle_l"):
            ori[seg] = _to_ours_R(R_t)
    elif has_torso:
        # no arms in the model: the canonical upper body (capture_full's neutral pose for the
        # subject's height) rides rigidly on the torso from the lumbar joint; its segments other
        # than the abdomen are placeholders (see _ARMLESS_PLACEHOLDERS)
        height = height or _height_from_legs(lm)
        R_t = Rb[:, bi["torso"]]
        lumbar = joint_centre("torso")
        for name, v in _neutral_upper_body(height).items():
            lm[name] = P_ours(lumbar + np.einsum("tij,j->ti", R_t, C_OSIM.T @ v))
        for seg in ("abdomen",) + _ARMLESS_PLACEHOLDERS:
            ori[seg] = _to_ours_R(R_t)
    seg_mass: dict[str, float] = {}
    for b, m in body_mass.items():
        seg = seg_of[b]
        if seg is None:
            raise OpenSimError(f"{model}: cannot map body {b!r} to a segment")
        if seg == "torso":
            for k, w in _TORSO_SPLIT.items():
                seg_mass[k] = seg_mass.get(k, 0.0) + m * w / sum(_TORSO_SPLIT.values())
            continue
        seg_mass[seg] = seg_mass.get(seg, 0.0) + m
    if has_torso and not has_arms:
        eps = PLACEHOLDER_MASS_FRACTION * total
        for seg in _ARMLESS_PLACEHOLDERS:
            seg_mass[seg] = eps
        seg_mass["abdomen"] -= eps * len(_ARMLESS_PLACEHOLDERS)  # the total stays the model's
    frame = GroundFrame(R=C_OSIM.T, offset=off, unit_m=1.0, axes="OpenSim ground: x forward, y up, z right")
    if mass is not None and abs(mass - total) > 0.01 * total:
        log.warning("subject mass %.2f kg given, the OpenSim model weighs %.2f kg: using the model's segment masses "
                    "scaled to %.2f kg", mass, total, mass)
        seg_mass = {k: v * mass / total for k, v in seg_mass.items()}
        total = float(mass)
    track = SkeletonTrack(
        times=times, landmarks=lm, orientations=ori, frame=frame, mass=total, height=height,
        segment_masses=seg_mass,
        source={
            "format": "opensim",
            "model": str(Path(model).resolve()),
            "motion": str(Path(motion).resolve()),
            "model_name": res.get("model_name"),
            "notes": list(res.get("notes", [])),
            "angles_in_degrees": bool(res["in_degrees"]),
            "floor_height_osim_y": floor,
            "body_to_segment": {b: s for b, s in seg_of.items()},
        },
    )
    track = _with_segment_inertias(track, res, seg_of, off)
    if belt_speed is not None:
        track = _belt_shift(track, belt_speed, grf, grf_xml)
    return track


def _neutral_upper_body(height: float) -> dict[str, np.ndarray]:
    """Upper-body landmarks of ``capture_full(height)`` in its neutral pose, relative to the
    lumbar joint, our axes: where an arm-less model's torso carries them."""
    from solver.character import capture_full
    from solver.kinematics import points_world

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
    from solver.io.fit import HIP_HEIGHT_FRACTION

    leg = np.nanmedian(lm["hip_r"][2] - np.minimum(lm["heel_r"][2], lm["toe_r"][2]))
    return float(np.nanmax([leg / HIP_HEIGHT_FRACTION, 0.5]))


def _with_segment_inertias(track: SkeletonTrack, res, seg_of, off) -> SkeletonTrack:
    """Per-segment COM and inertia (segment frame, about the COM) from the OpenSim bodies.

    Composite of every body mapped to the segment, at the model's default pose, expressed
    in the orienting body's axes (relabelled to ours) relative to the segment's origin
    landmark (measured in that body's frame, median over the trial).
    """
    from solver.io.fit import SEGMENT_LANDMARKS

    names = list(res["body_names"])
    bi = {b: i for i, b in enumerate(names)}
    R0, P0 = res["R0"], res["P0"]
    Rb, Pb = res["R"], res["P"]
    groups: dict[str, list[str]] = {}
    for b, s in seg_of.items():
        if s is not None and s != "torso":
            groups.setdefault(s, []).append(b)
    out: dict[str, dict] = {}
    for seg, bodies in groups.items():
        kind = seg.rsplit("_", 1)[0] if seg[-2:] in ("_r", "_l") else seg
        main = next((b for b in bodies if b.startswith(_ORIENTING.get(kind, "\0"))), None)
        if main is None or seg not in SEGMENT_LANDMARKS:
            continue
        origin_name = SEGMENT_LANDMARKS[seg][0]
        if origin_name not in track.landmarks:
            continue
        m_i = bi[main]
        # segment origin in the main body's frame (OpenSim axes), median over the trial
        o_ground = (np.asarray(track.landmarks[origin_name]).T @ C_OSIM) + off  # ours -> OpenSim ground
        o_body = np.median(np.einsum("tji,tj->ti", Rb[:, m_i], o_ground - Pb[:, m_i]), axis=0)
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
    src = dict(track.source)
    src["segment_inertias"] = out
    return SkeletonTrack(
        times=track.times, landmarks=track.landmarks, orientations=track.orientations, frame=track.frame,
        mass=track.mass, height=track.height, segment_masses=track.segment_masses, measured=track.measured,
        contacts=track.contacts, source=src,
    )


# --- ground reaction forces ------------------------------------------------------------------------


@dataclass(frozen=True)
class _ForceSpec:
    side: str  # "right" | "left"
    force: str  # column prefix, e.g. "ground_force_v" -> ..._vx/_vy/_vz
    point: str
    torque: str


def _external_loads(xml: str | Path) -> list[_ForceSpec]:
    p = Path(xml)
    if not p.is_file():
        raise OpenSimError(f"ExternalLoads file not found: {p}")
    try:
        root = ET.parse(p).getroot()
    except ET.ParseError as e:
        raise OpenSimError(f"{p}: not valid XML ({e})") from None
    specs = []
    for ef in root.iter("ExternalForce"):
        def txt(tag: str, default: str = "") -> str:
            el = ef.find(tag)
            return (el.text or "").strip() if el is not None and el.text else default

        if txt("appliesForce", "true").lower() == "false" or txt("isDisabled", "false").lower() == "true":
            continue
        body = txt("applied_to_body")
        m = re.search(r"_([rl])$", body)
        if not m:
            raise OpenSimError(f"{p}: ExternalForce {ef.get('name')!r} is applied to {body!r}; "
                               "cannot tell the side (expected a body name ending in _r or _l)")
        for tag in ("force_expressed_in_body", "point_expressed_in_body"):
            if txt(tag, "ground") != "ground":
                raise OpenSimError(f"{p}: ExternalForce {ef.get('name')!r}: {tag} = {txt(tag)!r}; "
                                   "only forces and points expressed in ground are supported")
        specs.append(_ForceSpec("right" if m.group(1) == "r" else "left", txt("force_identifier"),
                                txt("point_identifier"), txt("torque_identifier")))
    if not specs:
        raise OpenSimError(f"{p}: no applied ExternalForce")
    return specs


def _guess_force_specs(sto: Storage) -> list[_ForceSpec]:
    """Column naming without an ExternalLoads file: ``ground_force_r_vx`` / ``ground_force_l_vx``."""
    specs = []
    for side, tag in (("right", "r"), ("left", "l")):
        f = next((lab[:-1] for lab in sto.labels if re.fullmatch(rf"(.*_)?force_{tag}_vx", lab)), None)
        if f is None:
            f = next((lab[:-1] for lab in sto.labels if re.fullmatch(rf"{tag}_(.*_)?force_vx", lab)), None)
        if f is None:
            raise OpenSimError(
                f"{sto.path}: cannot tell which columns belong to the {side} foot (expected e.g. "
                f"'ground_force_{tag}_vx'); pass the ExternalLoads .xml (grf_xml=...)"
            )
        p = f[:-1] + "p"
        t = f.replace("force", "torque")[:-2] if f.endswith("_v") else f.replace("force", "torque")
        specs.append(_ForceSpec(side, f, p, t))
    return specs


def _columns(sto: Storage, prefix: str, suffixes: Sequence[str], what: str) -> np.ndarray:
    labs = [prefix + s for s in suffixes]
    missing = [lab for lab in labs if lab not in sto.labels]
    if missing:
        raise OpenSimError(f"{sto.path}: missing {what} columns {missing}")
    return np.stack([sto.column(lab) for lab in labs], axis=1)


def _grf_arrays(mot: str | Path, xml: str | Path | None):
    sto = read_mot(mot)
    specs = _external_loads(xml) if xml is not None else _guess_force_specs(sto)
    sides = {s.side for s in specs}
    if sides != {"right", "left"} or len(specs) != 2:
        raise OpenSimError(f"{mot}: expected one force per foot (right, left), got {[s.side for s in specs]}")
    specs = sorted(specs, key=lambda s: 0 if s.side == "right" else 1)
    F = np.stack([_columns(sto, s.force, ("x", "y", "z"), f"{s.side} force") for s in specs])  # (2, N, 3)
    P = np.stack([_columns(sto, s.point, ("x", "y", "z"), f"{s.side} point") for s in specs])
    tq = []
    for s in specs:
        cand = [s.torque + "_", s.torque]
        for c in cand:
            if all(c + a in sto.labels for a in "xyz"):
                tq.append(_columns(sto, c, ("x", "y", "z"), f"{s.side} torque"))
                break
        else:
            raise OpenSimError(f"{sto.path}: missing {s.side} torque columns {s.torque}_x/_y/_z")
    return sto, F, P, np.stack(tq)


def _floor_from_grf(mot: str | Path, xml: str | Path | None, threshold: float = 100.0) -> float | None:
    """Floor height in OpenSim ground = median COP height while a foot is loaded."""
    _, F, P, _ = _grf_arrays(mot, xml)
    loaded = F[:, :, 1] > threshold
    if not np.any(loaded):
        return None
    return float(np.median(P[:, :, 1][loaded]))


def read_opensim_grf(
    mot: str | Path,
    xml: str | Path | None = None,
    *,
    times: np.ndarray,
    frame: GroundFrame | None = None,
    contacts: np.ndarray | None = None,
    threshold: float = 20.0,
) -> MeasuredGRF:
    """Measured ground reactions of an OpenSim GRF .mot, per foot, on ``times``, in OUR frame.

    Side assignment from the ExternalLoads ``xml`` (``applied_to_body`` ``*_r`` / ``*_l``),
    or without it from column names ``*_force_r_*`` / ``*_force_l_*``. Forces are low-passed
    (zero-phase Butterworth, 0.4 × the target rate) before being sampled at ``times`` when the
    file's rate is over 2.5 times higher; the centre of pressure is interpolated as is and is
    NaN where that foot's vertical force is below ``threshold`` N (it is meaningless there).
    ``free_moment`` is the vertical component of the torque columns.

    ``valid`` marks frames inside the GRF record where the measured reaction is complete:
    with ``contacts`` (4, T) (heel_r, toe_r, heel_l, toe_l, e.g. from kinematics), every foot
    in contact must carry more than ``threshold`` N; without it, every frame of the record is
    taken as complete (true for a treadmill or when every stance is on a plate).
    """
    frame = frame or GroundFrame(R=C_OSIM.T)
    times = np.asarray(times, dtype=float)
    if times.ndim != 1 or times.size == 0:
        raise OpenSimError("read_opensim_grf: times must be a non-empty 1-D array")
    sto, F, P, TQ = _grf_arrays(mot, xml)
    t = sto.time
    inside = (times >= t[0] - 1e-9) & (times <= t[-1] + 1e-9)
    if not np.any(inside):
        raise OpenSimError(f"{mot}: GRF record {t[0]:.3f}-{t[-1]:.3f} s does not overlap the kinematics "
                           f"{times[0]:.3f}-{times[-1]:.3f} s")
    fs = 1.0 / float(np.median(np.diff(t)))
    fk = 1.0 / float(np.median(np.diff(times))) if times.size > 1 else fs
    Ff, TQf = F, TQ
    if fs > 2.5 * fk and len(t) > 30:
        from solver.io.preprocess import lowpass

        cut = 0.4 * fk
        Ff = np.stack([lowpass(F[k].T, fs, cut).T for k in range(2)])
        TQf = np.stack([lowpass(TQ[k].T, fs, cut).T for k in range(2)])
    tc = np.clip(times, t[0], t[-1])

    def interp(a: np.ndarray) -> np.ndarray:  # (N, 3) -> (3, T)
        return np.stack([np.interp(tc, t, a[:, i]) for i in range(a.shape[1])])

    force = np.zeros((2, 3, times.size))
    cop = np.full((2, 3, times.size), np.nan)
    free = np.zeros((2, times.size))
    raw_fy = np.zeros((2, times.size))
    for k in range(2):
        f_os = interp(Ff[k])  # OpenSim axes
        force[k] = frame.vector_from_input(f_os.T).T
        raw_fy[k] = np.interp(tc, t, F[k][:, 1])
        p_os = interp(P[k])
        p = frame.point_from_input(p_os.T, times).T
        loaded = raw_fy[k] > threshold
        cop[k][:, loaded] = p[:, loaded]
        tq = frame.vector_from_input(interp(TQf[k]).T).T
        free[k] = tq[2]
    force[:, :, ~inside] = 0.0
    free[:, ~inside] = 0.0
    cop[:, :, ~inside] = np.nan
    valid = inside.copy()
    if contacts is not None:
        c = np.asarray(contacts, dtype=bool)
        if c.shape != (4, times.size):
            raise OpenSimError(f"contacts must be (4, T={times.size}), got {c.shape}")
        for k in range(2):
            on = c[2 * k] | c[2 * k + 1]
            valid &= ~on | (raw_fy[k] > threshold)
    horiz = float(np.max(np.abs(TQ[:, :, [0, 2]]))) if TQ.size else 0.0
    if horiz > 1.0:
        log.info("%s: torque columns have horizontal components up to %.1f N·m (kept: vertical free moment only)",
                 mot, horiz)
    return MeasuredGRF(force=force, cop=cop, free_moment=free, valid=valid,
                       source=f"opensim:{Path(mot).name}" + (f"+{Path(xml).name}" if xml else ""))


# --- treadmill ---------------------------------------------------------------------------------


def estimate_belt_speed(track: SkeletonTrack, *, stance: np.ndarray | None = None) -> float:
    """Belt speed (m/s) of a treadmill trial: median backward speed of the stance foot.

    The stance foot is, at each frame, the foot whose heel/mtp are lower (or ``stance``
    (2, T) bool per foot when known, e.g. from force plates); its forward velocity is
    -v_belt. Frames with the foot moving vertically faster than 0.1 m/s are skipped.
    """
    t = np.asarray(track.times, dtype=float)
    if t.size < 5:
        raise OpenSimError("estimate_belt_speed: at least 5 frames are needed")
    vals = []
    for k, s in enumerate("rl"):
        p = 0.5 * (np.asarray(track.landmarks[f"heel_{s}"]) + np.asarray(track.landmarks[f"mtp_{s}"]))
        v = np.gradient(p, t, axis=1)
        other = "l" if s == "r" else "r"
        po = 0.5 * (np.asarray(track.landmarks[f"heel_{other}"]) + np.asarray(track.landmarks[f"mtp_{other}"]))
        if stance is not None:
            on = np.asarray(stance, dtype=bool)[k]
        else:
            low = p[2] < np.nanpercentile(p[2], 5) + 0.03
            on = low & (p[2] < po[2]) & (np.abs(v[2]) < 0.1)
        vals.append(-v[0][on])
    allv = np.concatenate(vals)
    allv = allv[np.isfinite(allv)]
    if allv.size < 3:
        raise OpenSimError("estimate_belt_speed: no stance frames found (is this a walking trial?)")
    return float(np.median(allv))


def _belt_shift(track: SkeletonTrack, belt_speed: float | str, grf, grf_xml) -> SkeletonTrack:
    if isinstance(belt_speed, str):
        if belt_speed != "auto":
            raise OpenSimError(f"belt_speed must be a number (m/s) or 'auto', got {belt_speed!r}")
        stance = None
        if grf is not None:
            g = read_opensim_grf(grf, grf_xml, times=track.times, frame=track.frame)
            stance = g.force[:, 2] > 200.0
        v = estimate_belt_speed(track, stance=stance)
        how = "auto (stance-foot velocity)"
    else:
        v = float(belt_speed)
        if not math.isfinite(v) or abs(v) > 10:
            raise OpenSimError(f"belt_speed {belt_speed!r} m/s is not plausible")
        how = "given"
    t = np.asarray(track.times, dtype=float)
    shift = np.stack([v * t, np.zeros_like(t), np.zeros_like(t)])
    lm = {k: np.asarray(p) + shift for k, p in track.landmarks.items()}
    f = track.frame
    frame = GroundFrame(R=f.R, offset=f.offset, unit_m=f.unit_m, velocity=np.array([v, 0.0, 0.0]),
                        axes=f.axes + "; treadmill frame moving at -velocity")
    src = dict(track.source)
    src["belt_speed_m_s"] = v
    src["belt_speed_from"] = how
    log.info("treadmill: belt speed %.3f m/s (%s): root shifted by v*t (overground-equivalent)", v, how)
    return SkeletonTrack(times=track.times, landmarks=lm, orientations=track.orientations, frame=frame,
                         mass=track.mass, height=track.height, segment_masses=track.segment_masses,
                         measured=track.measured, contacts=track.contacts, source=src)


# --- the importer ------------------------------------------------------------------------------------


def load_opensim(
    model: str | Path,
    motion: str | Path,
    *,
    mass: float | None = None,
    belt_speed: float | str | None = None,
    grf: str | Path | None = None,
    grf_xml: str | Path | None = None,
    lower_only: bool | None = None,
    in_degrees: bool | None = None,
    floor_height: float | None = None,
    height: float | None = None,
) -> Capture:
    """Import an OpenSim trial as a :class:`Capture` (see the module doc for every convention).

    ``mass`` (kg) rescales the model's segment masses when it differs from the model's total
    (the model's own total is used by default). ``belt_speed``: treadmill belt speed (m/s)
    or ``"auto"``; the root is shifted by ``v·t`` and ``GroundFrame.velocity`` records it.
    ``grf``/``grf_xml``: measured ground reactions (``read_opensim_grf``), attached as
    ``capture.measured`` with ``valid`` computed from the kinematic contact schedule.
    """
    from solver.io.fit import fit_track

    track = opensim_track(model, motion, mass=mass, belt_speed=belt_speed, grf=grf, grf_xml=grf_xml,
                          in_degrees=in_degrees, floor_height=floor_height, height=height)
    cap = fit_track(track, lower_only=lower_only)
    if grf is not None:
        from solver.io.preprocess import detect_contacts

        contacts = detect_contacts(cap.character, cap.q, cap.fps)
        measured = read_opensim_grf(grf, grf_xml, times=cap.times, frame=cap.frame, contacts=contacts)
        src = dict(cap.source)
        src["grf"] = str(Path(grf).resolve())
        src["grf_valid_frames"] = int(measured.valid.sum())
        cap = cap.evolve(measured=measured, source=src)
    return cap
