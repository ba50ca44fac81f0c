"""Re-import: our own exports (JSON clip, glTF 2.0 ``.glb``/``.gltf``, BVH) back to a motion's
generalized coordinates for a given character.

Every format stores, per frame and segment, the *local* transform parent <- segment
(``solver.export.local_transforms``: ``orientation · R(axis₁, q₁) · R(axis₂, q₂) · …`` and
``offset`` + slides). Reading a file back is therefore, per segment and frame:

1. express the file's local rotation R and translation t in our Z-up axes
   (``Y_UPᵀ R Y_UP``, ``Y_UPᵀ t`` for glTF, BVH and Y-up clips) and in the file's units;
2. decompose M = orientationᵀ · R into the segment's hinge sequence
   R(a₁, θ₁) R(a₂, θ₂) … about its fixed axes: closed form for 1, 2 and 3 hinges about any
   axes where consecutive axes are not parallel (Paden-Kahan subproblems; a 3-hinge chain
   has two solutions, the one in the joint limits, then the one nearest the previous frame,
   is kept), then two Gauss-Newton steps on the rotation error (least squares, for files
   that are not exactly representable: float32, rounded decimals);
3. solve the slides (root translation) by least squares from the translation;
4. make each angle continuous in time (a hinge angle is only known modulo 2π) and shift
   the whole trajectory by a multiple of 2π into the joint's limits, else to start in (-π, π].

The skeleton in the file (segment names, parents, rest offsets, rest rotations where the
format has them) must be the character's, and every frame's rotations and translations
must be reproduced by the character's joints to ``rot_tol`` (rad) / ``len_tol`` (m):
otherwise the file is for another character and a :class:`ReimportError` says where.

``motion_from_clip``, ``motion_from_gltf``, ``motion_from_bvh`` and ``motion_from_file``
(which recognises the format) return a :class:`Reimported` (``q`` (n, T), ``fps``, the
largest residuals, and ``.motion()`` to get a :class:`~solver.motion.Motion`).
"""

from __future__ import annotations

import base64
import json
import math
import re
from dataclasses import dataclass
from typing import Any

import numpy as np

from solver import hinges as hinge_chains
from solver import spatial as sp
from solver.character import Character
from solver.export import Y_UP, ExportError
from solver.export.clip import FORMAT, validate_clip
from solver.io.bvh import BvhError, parse_bvh
from solver.motion import Motion

__all__ = [
    "LEN_TOL",
    "ROT_TOL",
    "ReimportError",
    "Reimported",
    "decompose_hinges",
    "motion_from_bvh",
    "motion_from_clip",
    "motion_from_file",
    "motion_from_gltf",
    "quaternion_to_matrix",
]

#: default tolerances: largest rotation (rad) and translation / offset (m) mismatch accepted
ROT_TOL = 5e-3
LEN_TOL = 2e-3


class ReimportError(ExportError):
    """A file cannot be read back, or it does not match the character."""


@dataclass(frozen=True, eq=False)
class Reimported:
    """A motion read back from a file.

    ``q`` (n, T): the character's generalized coordinates (``character.coordinate_names``
    order), ``fps`` the frame rate; ``rotation_residual`` (rad) and ``translation_residual``
    (m): the largest mismatch between the file's local transforms and the character's joints
    at ``q`` (0 up to the file's precision); ``source`` the format read.
    """

    character: Character
    fps: float
    q: np.ndarray
    rotation_residual: float
    translation_residual: float
    source: str

    @property
    def T(self) -> int:
        return int(self.q.shape[1])

    def motion(self, **fields: Any) -> Motion:
        """The :class:`Motion` (kinematics only; ``fields`` are passed on, e.g. provenance)."""
        return Motion(character=self.character, fps=self.fps, q=self.q, **fields)


# --- rotation helpers ------------------------------------------------------------------------


def quaternion_to_matrix(quat: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of quaternions (..., 4) in (x, y, z, w) order (normalised first)."""
    qv = np.asarray(quat, dtype=float)
    if not np.all(np.isfinite(qv)) or np.any(np.linalg.norm(qv, axis=-1) < 1e-6):
        raise ReimportError("a rotation quaternion is zero or not finite")
    return sp.quaternion_to_matrix(qv)


def decompose_hinges(M: np.ndarray, axes: list[np.ndarray], lower: np.ndarray | None = None,
                     upper: np.ndarray | None = None, *, polish: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """:func:`solver.hinges.decompose_hinges`, its errors as :class:`ReimportError`."""
    try:
        return hinge_chains.decompose_hinges(M, axes, lower, upper, polish=polish)
    except hinge_chains.HingeError as e:
        raise ReimportError(str(e)) from None


def _continuous(theta: np.ndarray, lower: float, upper: float) -> np.ndarray:
    """Unwrap one angle trajectory (T,) and shift it by 2πk into [lower, upper] as far as
    possible; among equally good shifts, the one starting nearest 0."""
    th = np.unwrap(theta)
    th = th - 2.0 * np.pi * np.round(th[0] / (2.0 * np.pi))  # starts in [-π, π]
    best, best_cost = th, None
    for k in range(-3, 4):
        cand = th + 2.0 * np.pi * k
        viol = float(np.sum(np.maximum(lower - cand, 0.0) + np.maximum(cand - upper, 0.0)))
        cost = (round(viol, 9), abs(float(cand[0])))
        if best_cost is None or cost < best_cost:
            best, best_cost = cand, cost
    return best


# --- from local transforms to q ----------------------------------------------------------------


def _coordinates(character: Character, rot: np.ndarray, pos: np.ndarray, *, rot_tol: float, len_tol: float,
                 source: str, fps: float, where: str) -> Reimported:
    """q from the local rotations (S, T, 3, 3) and translations (S, T, 3) in our axes, character order."""
    _check_tol(rot_tol, len_tol)
    T = rot.shape[1]
    q = np.zeros((character.n, T))
    worst_rot, worst_len = 0.0, 0.0
    k0 = 0
    for i, seg in enumerate(character.segments):
        hinges = [(j, d) for j, d in enumerate(seg.dofs) if d.kind == "hinge"]
        slides = [(j, d) for j, d in enumerate(seg.dofs) if d.kind == "slide"]
        M = seg.orientation.T @ rot[i]
        axes = [d.axis for _, d in hinges]
        lo = np.array([d.lower for _, d in hinges])
        hi = np.array([d.upper for _, d in hinges])
        try:
            theta, res = decompose_hinges(M, axes, lo, hi)
        except ReimportError as e:
            raise ReimportError(f"segment {seg.name!r}: {e}") from None
        bad = int(np.argmax(res))
        if res[bad] > rot_tol:
            names = ", ".join(d.name for _, d in hinges) or "no hinge"
            raise ReimportError(
                f"{where} does not match character {character.name!r}: segment {seg.name!r} ({names}) cannot "
                f"take the file's rotations (off by {res[bad]:.3g} rad > {rot_tol:g} at frame {bad}); "
                "was it exported for another character?")
        worst_rot = max(worst_rot, float(res.max()))
        for h, (j, d) in enumerate(hinges):
            q[k0 + j] = _continuous(theta[:, h], d.lower, d.upper)
        # translation: offset + Σ (orientation · hinges before the slide) axis · value
        target = pos[i] - seg.offset
        if slides:
            cols = []
            for j, d in slides:
                before = [a for jj, a in zip([jj for jj, _ in hinges], axes) if jj < j]
                P, _ = hinge_chains.product(before, theta[:, : len(before)])
                cols.append(seg.orientation @ P @ d.axis)  # (T, 3)
            A = np.stack(cols, axis=-1)  # (T, 3, m)
            AtA = np.swapaxes(A, 1, 2) @ A
            if np.min(np.linalg.eigvalsh(AtA)) < 1e-9:
                raise ReimportError(f"segment {seg.name!r}: its slide axes are not independent")
            vals = np.linalg.solve(AtA, np.einsum("tim,ti->tm", A, target)[..., None])[..., 0]
            for m, (j, _) in enumerate(slides):
                q[k0 + j] = vals[:, m]
            target = target - np.einsum("tim,tm->ti", A, vals)
        err = np.linalg.norm(target, axis=1)
        bad = int(np.argmax(err))
        if err[bad] > len_tol:
            raise ReimportError(
                f"{where} does not match character {character.name!r}: segment {seg.name!r} is "
                f"{err[bad]:.3g} m from where the character's joints can put it (> {len_tol:g} m at frame {bad}); "
                "was it exported for another character?")
        worst_len = max(worst_len, float(err.max()))
        k0 += len(seg.dofs)
    return Reimported(character, float(fps), q, worst_rot, worst_len, source)


def _check_tol(rot_tol: Any, len_tol: Any) -> None:
    for name, v in (("rot_tol", rot_tol), ("len_tol", len_tol)):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
            raise ReimportError(f"{name} must be a positive number, got {v!r}")


def _where(what: str, file_character: Any) -> str:
    return f"{what} (exported for {file_character!r})" if isinstance(file_character, str) and file_character else what


def _match_skeleton(character: Character, names: list[str], parents: list[str | None], where: str) -> list[int]:
    """Index in the file of each character segment; refuses another skeleton with what differs."""
    ours = [s.name for s in character.segments]
    if len(set(names)) != len(names):
        raise ReimportError(f"{where} has duplicate segment names")
    missing = [n for n in ours if n not in names]
    extra = [n for n in names if n not in ours]
    if missing or extra:
        parts = []
        if missing:
            parts.append(f"missing segments {missing}")
        if extra:
            parts.append(f"unknown segments {extra}")
        raise ReimportError(f"{where} does not match character {character.name!r}: " + "; ".join(parts))
    index = [names.index(n) for n in ours]
    for s, i in zip(character.segments, index):
        if parents[i] != s.parent:
            raise ReimportError(f"{where} does not match character {character.name!r}: segment {s.name!r} "
                                f"hangs from {parents[i]!r} in the file, from {s.parent!r} in the character")
    return index


def _check_rest(character: Character, offsets: np.ndarray | None, rest_rot: np.ndarray | None, where: str,
                rot_tol: float, len_tol: float, skip_root_offset: bool = False) -> None:
    """Rest offsets (S, 3) and rest rotations (S, 3, 3) of the file, our axes and character order."""
    for i, s in enumerate(character.segments):
        if offsets is not None and not (i == 0 and skip_root_offset):
            d = float(np.linalg.norm(offsets[i] - s.offset))
            if d > len_tol:
                raise ReimportError(f"{where} does not match character {character.name!r}: segment {s.name!r} "
                                    f"has its joint {d:.3g} m from the character's (> {len_tol:g} m)")
        if rest_rot is not None:
            a = float(hinge_chains.rotation_angle(rest_rot[i] @ s.orientation.T))
            if a > rot_tol:
                raise ReimportError(f"{where} does not match character {character.name!r}: segment {s.name!r} "
                                    f"has a rest orientation {a:.3g} rad from the character's")


def _fps_from(value: float) -> float:
    """A frame rate read back through a float32 or a reciprocal: snapped to an integer when
    it is one to 1e-6 (relative)."""
    r = round(value)
    return float(r) if r > 0 and abs(value - r) <= 1e-6 * value else float(value)


# --- JSON clip ----------------------------------------------------------------------------------


def motion_from_clip(clip: dict | str | bytes, character: Character, *, rot_tol: float = ROT_TOL,
                     len_tol: float = LEN_TOL) -> Reimported:
    """Read a motionx JSON clip (a dict or its JSON text), Z-up or Y-up."""

    if isinstance(clip, (str, bytes)):
        try:
            clip = json.loads(clip)
        except ValueError as e:
            raise ReimportError(f"the clip is not JSON: {e}") from None
    if not isinstance(clip, dict) or clip.get("format") != FORMAT:
        raise ReimportError(f"not a motionx clip (expected \"format\": \"{FORMAT}\")")
    try:
        validate_clip(clip)
    except ExportError as e:
        raise ReimportError(str(e)) from None
    where = _where("the clip", clip.get("character"))
    skel = clip["skeleton"]
    names = [s["name"] for s in skel]
    index = _match_skeleton(character, names, [s["parent"] for s in skel], where)
    conv = Y_UP if clip["axes"]["up"] == "+y" else np.eye(3)
    offsets = np.array([skel[i]["offset"] for i in index], dtype=float) @ conv
    rest = conv.T @ quaternion_to_matrix(np.array([skel[i]["rotation"] for i in index], dtype=float)) @ conv
    _check_rest(character, offsets, rest, where, rot_tol, len_tol)
    T = clip["frame_count"]
    rots = np.array(clip["rotations"], dtype=float)[:, index].transpose(1, 0, 2)  # (S, T, 4)
    rot = conv.T @ quaternion_to_matrix(rots) @ conv
    pos = np.broadcast_to(offsets[:, None, :], (len(index), T, 3)).copy()
    pos[0] = np.array(clip["root_translation"], dtype=float) @ conv
    for name, tr in clip.get("translations", {}).items():
        if name in names:
            pos[[s.name for s in character.segments].index(name)] = np.array(tr, dtype=float) @ conv
    return _coordinates(character, rot, pos, rot_tol=rot_tol, len_tol=len_tol, source="clip",
                        fps=float(clip["fps"]), where=where)


# --- glTF 2.0 -----------------------------------------------------------------------------------

_NCOMP = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}
_CTYPE = {5126: np.dtype("<f4"), 5121: np.dtype("u1"), 5123: np.dtype("<u2"), 5125: np.dtype("<u4")}


def _parse_glb(data: bytes) -> tuple[dict, bytes | None]:
    from solver.io.gltf import GltfError
    from solver.io.gltf.container import split_glb

    try:
        return split_glb(data, "GLB")
    except GltfError as e:
        raise ReimportError(str(e)) from None


def _buffer(doc: dict, i: int, blob: bytes | None) -> bytes:
    try:
        buf = doc["buffers"][i]
    except (KeyError, IndexError, TypeError):
        raise ReimportError(f"glTF buffer {i} does not exist") from None
    uri = buf.get("uri")
    if uri is None:
        if blob is None or i != 0:
            raise ReimportError(f"glTF buffer {i} has no data (no uri and no GLB BIN chunk)")
        return blob
    m = re.match(r"data:[^,;]*(;base64)?,", uri)
    if not m or not m.group(1):
        raise ReimportError(f"glTF buffer {i} is an external file ({uri[:60]!r}): pass the .glb, or a .gltf "
                            "with its buffer embedded")
    return base64.b64decode(uri[m.end():])


def _accessor(doc: dict, i: int, blobs: dict, blob: bytes | None) -> np.ndarray:
    """The float data (count, components) of accessor ``i``."""
    try:
        acc = doc["accessors"][i]
        view = doc["bufferViews"][acc["bufferView"]]
        dt = _CTYPE[acc["componentType"]]
        nc = _NCOMP[acc["type"]]
        count = int(acc["count"])
    except (KeyError, IndexError, TypeError):
        raise ReimportError(f"glTF accessor {i} is missing or malformed") from None
    if "sparse" in acc:
        raise ReimportError(f"glTF accessor {i} is sparse (not supported)")
    if dt != np.dtype("<f4"):
        raise ReimportError(f"glTF accessor {i}: animation data must be FLOAT")
    b = view.get("buffer", 0)
    if b not in blobs:
        blobs[b] = _buffer(doc, b, blob)
    data = blobs[b]
    dt = np.dtype("<f4")  # the only type accepted above
    stride = view.get("byteStride") or nc * dt.itemsize
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    end = start + (count - 1) * stride + nc * dt.itemsize
    if count < 1 or end > view.get("byteOffset", 0) + view["byteLength"] or end > len(data):
        raise ReimportError(f"glTF accessor {i} reads past its buffer view")
    arr = np.lib.stride_tricks.as_strided(
        np.frombuffer(data, dtype=dt, count=(end - start) // dt.itemsize, offset=start),
        shape=(count, nc), strides=(stride, dt.itemsize))
    return np.array(arr, dtype=float)


def motion_from_gltf(data: bytes | str | dict, character: Character, *, animation: int = 0,
                     rot_tol: float = ROT_TOL, len_tol: float = LEN_TOL) -> Reimported:
    """Read a glTF 2.0 file: ``.glb`` bytes, ``.gltf`` JSON text (buffer embedded) or its parsed dict.

    Segment nodes are found by name; the animation's rotation and translation channels give
    the local transforms at its key times (one shared set of times, uniformly spaced), the
    node's rest TRS where a segment has no channel. The frame rate is ``asset.extras.fps``
    when present (our exports), else from the key times.
    """
    blob = None
    if isinstance(data, (bytes, bytearray, memoryview)):
        data = bytes(data)
        if data[:4] == b"glTF":
            doc, blob = _parse_glb(data)
        else:
            try:
                doc = json.loads(data.decode("utf-8"))
            except (UnicodeDecodeError, ValueError):
                raise ReimportError("neither a GLB nor glTF JSON") from None
    elif isinstance(data, str):
        try:
            doc = json.loads(data)
        except ValueError as e:
            raise ReimportError(f"glTF JSON is not JSON: {e}") from None
    else:
        doc = data
    if not isinstance(doc, dict) or not str(doc.get("asset", {}).get("version", "")).startswith("2."):
        raise ReimportError("not a glTF 2.0 document (asset.version)")
    nodes = doc.get("nodes") or []
    extras = doc["asset"].get("extras") or {}
    where = _where("the glTF file", extras.get("character") if isinstance(extras, dict) else None)
    parent_of = {c: i for i, n in enumerate(nodes) for c in n.get("children", [])}
    seg_names = {s.name for s in character.segments}
    node_of: dict[str, int] = {}
    for i, n in enumerate(nodes):
        nm = n.get("name")
        if nm in seg_names or ("mesh" not in n and "camera" not in n and nm is not None and "skin" not in n):
            if nm in node_of:
                raise ReimportError(f"{where} has two nodes named {nm!r}")
            node_of[nm] = i
    names = list(node_of)
    parents = [nodes[parent_of[i]].get("name") if i in parent_of else None for i in node_of.values()]
    _match_skeleton(character, names, parents, where)
    node_ids = [node_of[s.name] for s in character.segments]
    root_node = node_ids[0]
    if root_node in parent_of:
        raise ReimportError(f"{where}: the root segment's node has a parent node "
                            f"{nodes[parent_of[root_node]].get('name')!r}; its transform is not supported")

    S = len(node_ids)
    rest_rot = np.empty((S, 3, 3))
    rest_pos = np.empty((S, 3))
    for k, i in enumerate(node_ids):
        n = nodes[i]
        if "matrix" in n:
            m = np.array(n["matrix"], dtype=float).reshape(4, 4).T
            rest_rot[k], rest_pos[k] = m[:3, :3], m[:3, 3]
        else:
            rest_rot[k] = quaternion_to_matrix(n.get("rotation", [0.0, 0.0, 0.0, 1.0]))
            rest_pos[k] = n.get("translation", [0.0, 0.0, 0.0])
            if not np.allclose(n.get("scale", [1.0, 1.0, 1.0]), 1.0, atol=1e-6):
                raise ReimportError(f"{where}: node {n.get('name')!r} is scaled")
    offsets = rest_pos @ Y_UP  # Y-up -> ours: v_ours = Y_UPᵀ v
    rest_ours = Y_UP.T @ rest_rot @ Y_UP
    _check_rest(character, offsets, rest_ours, where, rot_tol, len_tol)

    anims = doc.get("animations") or []
    if not isinstance(animation, int) or not 0 <= animation < len(anims):
        raise ReimportError(f"{where} has no animation {animation} ({len(anims)} animations)")
    anim = anims[animation]
    blobs: dict[int, bytes] = {}
    times = None
    tracks: dict[tuple[int, str], np.ndarray] = {}
    for ch in anim.get("channels", []):
        tgt = ch.get("target", {})
        node, path = tgt.get("node"), tgt.get("path")
        if node not in node_ids or path not in ("rotation", "translation"):
            continue
        smp = anim["samplers"][ch["sampler"]]
        t = _accessor(doc, smp["input"], blobs, blob)[:, 0]
        out = _accessor(doc, smp["output"], blobs, blob)
        if smp.get("interpolation", "LINEAR") == "CUBICSPLINE":
            out = out.reshape(len(t), 3, -1)[:, 1]  # in-tangent, value, out-tangent
        if len(out) != len(t):
            raise ReimportError(f"{where}: a {path} channel has {len(out)} values for {len(t)} key times")
        if times is None:
            times = t
        elif len(t) != len(times) or np.max(np.abs(t - times)) > 1e-5:
            raise ReimportError(f"{where}: the channels do not share their key times (resample the animation)")
        tracks[(node, path)] = out
    if times is None:
        raise ReimportError(f"{where}: animation {animation} animates no segment")
    T = len(times)
    if T >= 2:
        dt = np.diff(times)
        if np.any(dt <= 0) or np.max(np.abs(dt - dt.mean())) > 1e-4 * dt.mean() + 1e-6:
            raise ReimportError(f"{where}: key times are not uniformly spaced (resample the animation)")
    fps = extras.get("fps") if isinstance(extras, dict) else None
    if not (isinstance(fps, (int, float)) and fps > 0 and abs((T - 1) / fps - (times[-1] - times[0])) < 1e-4):
        if T < 2:
            raise ReimportError(f"{where}: one key time gives no frame rate")
        fps = _fps_from((T - 1) / float(times[-1] - times[0]))
    rot = np.empty((S, T, 3, 3))
    pos = np.empty((S, T, 3))
    for k, i in enumerate(node_ids):
        r = tracks.get((i, "rotation"))
        rot[k] = quaternion_to_matrix(r) if r is not None else rest_rot[k]
        p = tracks.get((i, "translation"))
        pos[k] = p if p is not None else rest_pos[k]
    rot = Y_UP.T @ rot @ Y_UP
    pos = pos @ Y_UP
    return _coordinates(character, rot, pos, rot_tol=rot_tol, len_tol=len_tol, source="gltf", fps=fps, where=where)


# --- BVH ----------------------------------------------------------------------------------------

_UNITS = {"m": 1.0, "cm": 100.0, "mm": 1000.0}


def motion_from_bvh(text: str | bytes, character: Character, *, units: str = "auto", rot_tol: float = ROT_TOL,
                    len_tol: float = LEN_TOL) -> Reimported:
    """Read a BVH file (Y-up; any rotation channel order). ``units``: "cm", "m", "mm", or
    "auto" (the one that makes the file's joint offsets the character's)."""
    if isinstance(text, bytes):
        text = text.decode("utf-8", errors="replace")
    try:
        clip = parse_bvh(text, "BVH")
    except BvhError as e:
        raise ReimportError(str(e)) from None
    T = clip.T
    where = "the BVH file"
    names = list(clip.names)
    parents = [clip.names[p] if p >= 0 else None for p in clip.parents]
    index = _match_skeleton(character, names, parents, where)
    raw_off = clip.offsets[index] @ Y_UP  # ours, file units
    if units == "auto":
        ours = np.array([s.offset for s in character.segments[1:]])
        fit = {u: float(np.abs(raw_off[1:] / f - ours).max()) if len(ours) else 0.0 for u, f in _UNITS.items()}
        units = min(fit, key=lambda u: fit[u]) if len(ours) else "cm"
    if units not in _UNITS:
        raise ReimportError(f"units must be 'auto' or one of {sorted(_UNITS)}, got {units!r}")
    scale = _UNITS[units]
    offsets = raw_off / scale
    _check_rest(character, offsets, None, where, rot_tol, len_tol, skip_root_offset=True)
    S = len(index)
    rot = np.empty((S, T, 3, 3))
    pos = np.empty((S, T, 3))
    for k, i in enumerate(index):
        r, p = clip.local(i)
        rot[k] = Y_UP.T @ r @ Y_UP
        pos[k] = (p @ Y_UP) / scale
    ftime = clip.frame_time
    return _coordinates(character, rot, pos, rot_tol=rot_tol, len_tol=len_tol, source="bvh",
                        fps=_fps_from(1.0 / ftime), where=where)


# --- any of them ---------------------------------------------------------------------------------


def motion_from_file(data: bytes | str | dict, character: Character, **options: Any) -> Reimported:
    """Recognise the format (GLB magic, BVH ``HIERARCHY``, glTF JSON ``asset``, motionx clip)
    and read it with the matching reader (``options`` are passed on)."""
    if isinstance(data, (bytes, bytearray, memoryview)):
        data = bytes(data)
        if data[:4] == b"glTF":
            return motion_from_gltf(data, character, **options)
        try:
            data = data.decode("utf-8")
        except UnicodeDecodeError:
            raise ReimportError("unrecognised file: binary but not a GLB") from None
    if isinstance(data, str):
        head = data.lstrip()[:16]
        if head.startswith("HIERARCHY"):
            return motion_from_bvh(data, character, **options)
        try:
            data = json.loads(data)
        except ValueError:
            raise ReimportError("unrecognised file: not a GLB, a BVH or JSON") from None
    if isinstance(data, dict) and "asset" in data:
        return motion_from_gltf(data, character, **options)
    if isinstance(data, dict) and "format" in data:
        return motion_from_clip(data, character, **options)
    raise ReimportError("unrecognised file: JSON but neither glTF nor a motionx clip")
