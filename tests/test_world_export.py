"""The world a walk was made for, in every export (``solver.export.world``).

One tutor (the CMU BVH walk on HalfBoy, 15 fps) and its optima at λ = 1: slope +10° and −10°,
stairs of 0.15 m risers, a 90° curve. Each is exported in the default world (gravity down)
and read back by readers that are not the writer: pygltflib and numpy forward kinematics of the
written GLB (``test_gltf_rig.glb_fk``), bvhio for the BVH, our re-import module for the GLB. The
ground is taken from the file itself — the GLB's ``ground`` mesh (a vertical ray cast onto its
triangles, written here), or the BVH's sidecar description (a plane, or tread polygons) — and

- every contact point the motion has on the ground, at every stance frame, lies on that ground
  within 1 cm;
- a slope's root rises by its horizontal travel × tan(slope) within 10 % (stairs: by the
  treads' rise), a curve's root path is the motion's own;
- the same holds on the input's own skeleton (``rig="source"``: the CMU skeleton's GLB and BVH),
  for its ankle joints' heights above the ground;
- ``world="ground"`` gives back the solver's frame (today's files) exactly.
"""

from __future__ import annotations

import json
import math
import time

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from test_export import bvhio, motionx
from test_gltf_rig import _accessor, glb_fk

import solver
from solver import kinematics as K
from solver.environment import ground_of
from solver.export import Y_UP, ExportError, export_motion, game
from solver.export import reimport as RI
from solver.export.gltf import to_library_glb
from solver.export.world import WORLDS, ground_json
from solver.motion import FEET, Motion
from solver.rig import SkeletonRig, retarget

TRIAL = "cmu16_bvh/16_15_walk.bvh"
TARGETS = {"up10": {"slope_deg": 10.0}, "down10": {"slope_deg": -10.0}, "stairs": {"step_height_m": 0.15},
           "curve90": {"curve_deg": 90.0}}
#: feet on the ground (m) and a slope's rise against travel × tan(slope) (relative)
FEET_TOL_M, RISE_TOL = 0.01, 0.10


@pytest.fixture(scope="module")
def walks(shared_data) -> dict[str, Motion]:
    t0 = time.perf_counter()
    tutor = solver.make_tutor(solver.load_trial([shared_data / TRIAL], mass=70.0), character="halfboy", fps=15.0)
    assert tutor.status == "succeeded", tutor.message
    out = {"tutor": tutor.motion}
    t1 = time.perf_counter()
    for name, target in TARGETS.items():
        res = solver.extrapolate(tutor.motion, solver.Target(**target))
        # HalfBoy's tight curve may end at an impasse at its last natural λ (docs/naturalness.md)
        assert res.lam_reached == 1.0 or (name == "curve90" and res.lam_reached > 0.4), (name, res.message)
        out[name] = res.steps[-1].motion
    print(f"\nCMU walk: tutor {t1 - t0:.1f} s, four optima {time.perf_counter() - t1:.1f} s")
    return out


# --- the ground as the files give it --------------------------------------------------------------

def mesh_distance(V: np.ndarray, F: np.ndarray, up: np.ndarray, p: np.ndarray) -> float:
    """Distance from ``p`` to the plane of the mesh's triangle straight below or above it (along
    ``up``), signed positive above; NaN when no triangle is there."""
    u = up / np.linalg.norm(up)
    e1 = np.cross(u, [1.0, 0.0, 0.0] if abs(u[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    flat = np.c_[V @ e1, V @ e2]
    a, b, c = flat[F[:, 0]], flat[F[:, 1]], flat[F[:, 2]]
    x = np.array([p @ e1, p @ e2])
    den = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    ok = np.abs(den) > 1e-12  # risers are edge-on from above
    s = ((x[0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (x[1] - a[:, 1])) / np.where(ok, den, 1)
    t = ((b[:, 0] - a[:, 0]) * (x[1] - a[:, 1]) - (x[0] - a[:, 0]) * (b[:, 1] - a[:, 1])) / np.where(ok, den, 1)
    inside = ok & (s >= -1e-9) & (t >= -1e-9) & (s + t <= 1 + 1e-9)
    best = math.nan
    for k in np.flatnonzero(inside):
        A, B, C = V[F[k]]
        n = np.cross(B - A, C - A)
        n = n / np.linalg.norm(n) * np.sign(n @ u)
        d = float((p - A) @ n)
        if math.isnan(best) or abs(d) < abs(best):
            best = d
    return best


def description_distance(ground: dict, p: np.ndarray) -> float:
    """Distance from ``p`` to the ground of a JSON description (a plane, or the tread whose top
    outline holds p seen along the normal)."""
    n = np.array(ground["normal"])
    if ground["kind"] == "plane":
        return float((p - np.array(ground["point"])) @ n)
    e1 = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    for tread in ground["treads"]:
        poly = np.array(tread["top"])
        x, y = p @ e1, p @ e2
        px, py = poly @ e1, poly @ e2
        inside = False
        for i in range(len(poly)):  # even-odd rule
            j = i - 1
            if (py[i] > y) != (py[j] > y) and x < px[j] + (y - py[j]) * (px[i] - px[j]) / (py[i] - py[j]):
                inside = not inside
        if inside:
            return float((p - np.array(tread["point"])) @ n)
    return math.nan


def bvhio_frames(text: str, tmp_path, names: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """World positions (F, J, 3) and rotations (F, J, 3, 3) of the named joints, by bvhio. bvhio
    aligns each joint's frame with its bone at rest; its rest-pose rotation is taken off, which
    leaves the BVH's own joint frames (identity at rest)."""
    f = tmp_path / "read.bvh"
    f.write_text(text)
    root = bvhio.readAsHierarchy(str(f))
    joints = {j.Name: j for j, _, _ in root.layout()}

    def rot(q) -> np.ndarray:
        return Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()

    root.loadRestPose()
    rest = [rot(joints[n].RotationWorld) for n in names]
    frames = bvhio.readAsBvh(str(f)).FrameCount
    P = np.empty((frames, len(names), 3))
    R = np.empty((frames, len(names), 3, 3))
    for k in range(frames):
        root.loadPose(k)
        for i, n in enumerate(names):
            p = joints[n].PositionWorld
            P[k, i] = (p.x, p.y, p.z)
            R[k, i] = rot(joints[n].RotationWorld) @ rest[i].T
    return P, R


def stance_points(motion: Motion):
    """(contact index, frame) of every contact point on the ground."""
    return [(i, t) for i in range(len(motion.character.contacts)) for t in range(motion.T) if motion.contacts[i, t]]


def glb_ground(g, blob: bytes, name: str = "ground") -> tuple[np.ndarray, np.ndarray, dict]:
    """The vertices (scene), triangles and extras of the ground node ``name`` of a GLB (its mesh as
    written; the node has no transform of its own)."""
    (node,) = [n for n in g.nodes if n.name == name]
    assert not node.translation and not node.rotation and not node.scale and not node.matrix
    (prim,) = g.meshes[node.mesh].primitives
    V = _accessor(g, blob, prim.attributes.POSITION).astype(float)
    F = _accessor(g, blob, prim.indices).reshape(-1, 3).astype(int)
    return V, F, node.extras


def rise_check(name: str, motion: Motion, root: np.ndarray, up: np.ndarray) -> tuple[float, float]:
    """(rise, expected) of the root (scene positions (T, 3)) over one cycle, frames 0 → P."""
    P = game.loop_frames(motion)
    d = root[P] - root[0]
    rise = float(d @ up)
    horizontal = float(np.linalg.norm(d - rise * up))
    if name in ("up10", "down10"):
        expected = horizontal * math.tan(math.radians(TARGETS[name]["slope_deg"]))
    elif name == "stairs":
        expected = game.rise(motion)
    else:
        expected = 0.0
    return rise, expected


def _off(rise: float, expected: float) -> str:
    return f"{100 * (rise / expected - 1):+.2f} %" if expected else f"{rise * 1e3:+.2f} mm"


def _assert_rise(name: str, rise: float, expected: float) -> None:
    if expected:
        assert abs(rise - expected) <= RISE_TOL * abs(expected), (name, rise, expected)
    else:
        assert abs(rise) < 0.005, (name, rise)


# --- the character's GLB and BVH ------------------------------------------------------------------

@pytest.mark.parametrize("name", list(TARGETS))
def test_glb_walks_on_the_ground_it_carries(walks, name):
    motion = walks[name]
    data = export_motion(motion, "glb")  # the default world: gravity down
    g, _, W = glb_fk(data)
    blob = g.binary_blob()
    V, F, extras = glb_ground(g, blob)
    assert extras["world"] == "gravity" and g.asset.extras["world"] == "gravity"
    up = np.array([0.0, 1.0, 0.0])  # glTF: gravity points down -Y
    assert g.animations[0].extras["world"]["gravity"] == pytest.approx([0.0, -9.81, 0.0], abs=1e-9)
    seg = {s.name: i for i, s in enumerate(motion.character.segments)}
    errs = []
    for i, t in stance_points(motion):
        c = motion.character.contacts[i]
        M = W[seg[c.segment]][t]
        p = M[:3, :3] @ (Y_UP @ np.asarray(c.position)) + M[:3, 3]
        errs.append(mesh_distance(V, F, up, p))
    errs = np.array(errs)
    assert not np.isnan(errs).any(), f"{name}: {np.isnan(errs).sum()} contact points off the ground mesh"
    worst = float(np.max(np.abs(errs)))
    rise, expected = rise_check(name, motion, W[0][:, :3, 3], up)
    print(f"{name} GLB: feet on the ground ≤ {worst * 1e6:.1f} µm over {len(errs)} stance points; root rise "
          f"{rise:.4f} m, expected {expected:.4f} m ({_off(rise, expected)})")
    assert worst <= FEET_TOL_M
    _assert_rise(name, rise, expected)
    if name == "curve90":  # the path is kept: gravity is already down, the file's root is the motion's
        _, pos = K.segment_frames(motion.character, motion.q)
        np.testing.assert_allclose(W[0][:, :3, 3], pos[0].T @ Y_UP.T, atol=1e-5)
        heading = np.degrees(motion.q[3, game.loop_frames(motion)] - motion.q[3, 0])
        turn = 90.0 * motion.provenance["lambda"]  # the curve reached (its last natural λ)
        assert turn - 10.0 < heading < turn + 10.0


@pytest.mark.parametrize("name", list(TARGETS))
def test_bvh_walks_on_the_ground_of_its_sidecar(walks, name, tmp_path):
    motion = walks[name]
    text = export_motion(motion, "bvh")  # cm, Y up, the default world
    ground = json.loads(ground_json(motion, units="cm"))  # what `motionx export --format bvh` writes beside it
    assert ground["units"] == {"length": "cm"} and ground["world"]["name"] == "gravity"
    feet = sorted({c.segment for c in motion.character.contacts})
    names = [motion.character.segments[0].name, *feet]
    P, R = bvhio_frames(text, tmp_path, names)
    errs = []
    for i, t in stance_points(motion):
        c = motion.character.contacts[i]
        k = 1 + feet.index(c.segment)
        p = P[t, k] + R[t, k] @ (Y_UP @ np.asarray(c.position) * 100.0)
        errs.append(description_distance(ground["ground"], p) / 100.0)
    errs = np.array(errs)
    assert not np.isnan(errs).any(), f"{name}: contact points on no tread"
    worst = float(np.max(np.abs(errs)))
    rise, expected = rise_check(name, motion, P[:, 0] / 100.0, np.array([0.0, 1.0, 0.0]))
    print(f"{name} BVH: feet on the ground ≤ {worst * 1e6:.1f} µm; root rise {rise:.4f} m, expected {expected:.4f} m "
          f"({_off(rise, expected)})")
    assert worst <= FEET_TOL_M
    _assert_rise(name, rise, expected)


def test_reimported_glb_stands_on_the_clips_ground_and_world_ground_is_the_solvers_frame(walks):
    """Our re-import module reads the gravity-world GLB back as coordinates whose contact points
    stand on the JSON clip's ground; with world="ground" it gives back the motion itself."""
    for name in ("up10", "stairs"):
        motion = walks[name]
        ch = motion.character
        back = RI.motion_from_file(export_motion(motion, "glb"), ch)
        clip = json.loads(export_motion(motion, "json"))
        assert clip["world"]["name"] == "gravity" and clip["ground"]["kind"] == ("stairs" if name == "stairs" else
                                                                                    "plane")
        cp = np.asarray(K.contact_points(ch, back.q))
        worst = max(abs(description_distance(clip["ground"], cp[i, :, t])) for i, t in stance_points(motion))
        print(f"{name}: re-imported GLB's contact points on the clip's ground ≤ {worst * 1e6:.1f} µm")
        assert worst <= FEET_TOL_M
        # the solver's frame, as before worlds existed
        level = RI.motion_from_file(export_motion(motion, "glb", world="ground"), ch)
        np.testing.assert_allclose(level.q, motion.q, atol=1e-5)
        flat = json.loads(export_motion(motion, "json", world="ground"))
        assert flat["ground"]["normal"] == [0.0, 0.0, 1.0] and flat["world"]["name"] == "ground"
    up = json.loads(export_motion(walks["up10"], "json", world="ground"))
    g = up["world"]["gravity"]
    assert math.degrees(math.atan2(-g[0], -g[2])) == pytest.approx(10.0)  # tilted gravity, as the solver's


def test_clip_and_game_data_are_in_the_same_world(walks):
    """The clip's game data, points and ground reactions follow the animation into the world: the
    loop transform maps frame 0 onto frame P about the ground's normal, feet are planted on the ground."""
    from solver.export import clip as CL

    motion = walks["up10"]
    clip = CL.to_clip(motion, points=True, decimals=None)
    CL.validate_clip(clip)
    loop = clip["game"]["loop"]
    assert loop["seamless"]
    axis = np.array(loop["transform"]["axis"])
    assert np.degrees(np.arccos(axis[2])) == pytest.approx(10.0)  # the ramp's normal
    rm = clip["game"]["root_motion"]
    P = loop["end_frame"]
    rise = rm["translation"][P][2] - rm["translation"][0][2]
    run = np.linalg.norm(np.subtract(rm["translation"][P][:2], rm["translation"][0][:2]))
    assert rise / run == pytest.approx(math.tan(math.radians(10.0)), rel=1e-3)  # the walk is not quite along +x
    for f, foot in enumerate(FEET):
        pos = [p for p in clip["game"]["foot_contacts"][foot]["position"] if p is not None]
        assert max(abs(description_distance(clip["ground"], np.array(p))) for p in pos) < 1e-6
        cops = [c for c in clip["ground_reaction"][foot]["cop"] if c is not None]
        assert max(abs(description_distance(clip["ground"], np.array(c))) for c in cops) < 1e-6
    assert clip["ground_reaction"]["free_moment_axis"] == "ground_normal"
    # stairs: the loop rises by the cycle's rise, so it is seamless with root motion
    stairs = CL.to_clip(walks["stairs"], decimals=None)
    assert stairs["game"]["loop"]["seamless"]
    assert stairs["game"]["loop"]["transform"]["translation"][2] == pytest.approx(0.30)
    for foot in FEET:
        cops = [c for c in stairs["ground_reaction"][foot]["cop"] if c is not None]
        assert max(abs(description_distance(stairs["ground"], np.array(c))) for c in cops) < 1e-6


# --- on the input's own skeleton --------------------------------------------------------------------

def _ankle_heights(motion: Motion, rig: SkeletonRig, pose) -> tuple[np.ndarray, np.ndarray]:
    """(stance (F, 2) bool, the ankle joints' height above their ground in the solver's frame (F, 2))."""
    s = pose.times * motion.fps
    lo = np.clip(np.floor(s + 1e-9).astype(int), 0, motion.T - 1)
    hi = np.clip(np.ceil(s - 1e-9).astype(int), 0, motion.T - 1)
    feet = motion.foot_contact()
    stance = (feet[:, lo] & feet[:, hi]).T
    return stance, pose.ankle_target[:, :, 2] - ground_of(motion)[:, lo].T


@pytest.mark.parametrize("name", ["up10", "stairs"])
def test_source_rig_glb_and_bvh_climb_their_ground(walks, name, tmp_path):
    motion = walks[name]
    rig = motion.context.rig
    pose = retarget(motion, rig)
    stance, height = _ankle_heights(motion, rig, pose)
    ankles = [rig.names[rig.roles[f"foot_{s}"]] for s in "rl"]
    # the skeleton's GLB: its ankles above the GLB's ground as high as the motion's above its own
    g, times, W = glb_fk(export_motion(motion, "glb", rig="source"))
    V, F, extras = glb_ground(g, g.binary_blob())
    node = {n.name: i for i, n in enumerate(g.nodes)}
    up = np.array([0.0, 1.0, 0.0])
    glb = np.array([[mesh_distance(V, F, up, W[node[a]][f, :3, 3]) for a in ankles] for f in range(times.size)])
    err_glb = float(np.nanmax(np.abs(glb - height)[stance]))
    assert not np.isnan(glb[stance]).any()
    root = rig.names[0]
    # the input's own BVH, read by bvhio, against the ground's description in its own axes and unit
    text = export_motion(motion, "bvh", rig="source")
    ground = json.loads(ground_json(motion, rig="source"))
    P, _ = bvhio_frames(text, tmp_path, ankles + [root])
    frame = motion.frame
    bvh = np.array([[description_distance(ground["ground"], P[f, k]) * frame.unit_m for k in range(2)]
                    for f in range(P.shape[0])])
    assert P.shape[0] == times.size and not np.isnan(bvh[stance]).any()
    err_bvh = float(np.max(np.abs(bvh - height)[stance]))
    # the root climbs: over the cycle it rises by travel × tan(slope) (the treads' rise)
    up_in = frame.R @ np.array([0.0, 0.0, 1.0])  # against gravity, in the input's axes
    d = (P[-1, 2] - P[0, 2]) * frame.unit_m
    rise = float(d @ up_in)
    expected = (np.linalg.norm(d - rise * up_in) * math.tan(math.radians(10.0)) if name == "up10"
                else game.rise(motion))
    print(f"{name} on the CMU skeleton: ankle height above the ground vs the motion's, GLB ≤ {err_glb * 1e6:.1f} µm, "
          f"BVH ≤ {err_bvh * 1e6:.1f} µm; root rise {rise:.4f} m, expected {expected:.4f} m ({_off(rise, expected)})")
    assert err_glb <= FEET_TOL_M and err_bvh <= FEET_TOL_M
    _assert_rise(name, rise, expected)
    assert extras["world"] == "gravity"


# --- libraries, the command line, refusals ------------------------------------------------------------

def test_library_glb_has_each_cells_ground(walks):
    clips = [("slope10", walks["up10"]), ("slope-10", walks["down10"])]
    data = to_library_glb(clips, world="gravity")
    for k, (key, motion) in enumerate(clips):
        g, _, W = glb_fk(data, animation=k)
        V, F, extras = glb_ground(g, g.binary_blob(), f"ground {key}")
        assert extras["animation"] == key and extras["ground"]["kind"] == "plane"
        seg = {s.name: i for i, s in enumerate(motion.character.segments)}
        P = game.loop_frames(motion)
        worst = 0.0
        for i, t in stance_points(motion):
            if t > P:  # the library's animations are one cycle, frames 0 … P
                continue
            c = motion.character.contacts[i]
            M = W[seg[c.segment]][t]
            worst = max(worst, abs(mesh_distance(V, F, np.array([0.0, 1.0, 0.0]),
                                                 M[:3, :3] @ (Y_UP @ np.asarray(c.position)) + M[:3, 3])))
        assert worst <= FEET_TOL_M, (key, worst)
    (parent,) = [n for n in g.nodes if n.name == "ground"]
    assert [g.nodes[c].name for c in parent.children] == ["ground slope10", "ground slope-10"]


def test_cli_world_option_and_bvh_sidecar(walks, tmp_path):
    src = tmp_path / "up10.motion.json"
    walks["up10"].save(src)
    r = motionx("export", str(src), "--format", "bvh", "--out", str(tmp_path / "up.bvh"))
    assert r.returncode == 0, r.stderr
    line = json.loads(r.stdout)
    assert line["ground"] == str(tmp_path / "up.ground.json")
    assert json.loads((tmp_path / "up.ground.json").read_text()) == json.loads(ground_json(walks["up10"], units="cm"))
    r = motionx("export", str(src), "--format", "json", "--world", "ground", "--out", str(tmp_path / "c.json"))
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "c.json").read_text())["world"]["name"] == "ground"
    r = motionx("export", str(src), "--format", "glb", "--world", "level", "--out", str(tmp_path / "x.glb"))
    assert r.returncode == 2 and "gravity" in r.stderr and not (tmp_path / "x.glb").exists()


def test_unknown_world_is_refused_by_every_exporter(walks):
    motion = walks["up10"]
    for fmt in ("json", "gltf", "glb", "bvh"):
        with pytest.raises(ExportError, match=r"world must be 'gravity'.* or 'ground'.*got 'up'"):
            export_motion(motion, fmt, world="up")
    with pytest.raises(ExportError, match="world must be"):
        export_motion(motion, "bvh", rig="source", world=1)
    with pytest.raises(ExportError, match="world must be"):
        ground_json(motion, world="Gravity")
    assert list(WORLDS) == ["gravity", "ground"]
