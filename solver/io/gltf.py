"""Skinned glTF 2.0 importer: a character's skeleton and one walk animation (``.glb``, or ``.gltf``
with its buffers embedded).

Public API::

    read_gltf(path) -> GltfAsset                 # the document and its one binary buffer
    parse_gltf(data, where) -> GltfAsset         # the same from bytes (GLB or glTF JSON)
    gltf_track(path, *, mass=None, joints=None, animation=None, belt_speed=None) -> SkeletonTrack
    load_gltf(path, *, mass=None, lower_only=None, joints=None, animation=None, belt_speed=None) -> Capture

**What is read.** One animation: the first, or ``animation`` (its name, or its index). One
skin: the one whose joints that animation drives most (the first on a tie). The skeleton is
the tree of the skin's joints under their top joint (of several top joints, the one with the
most joints below it; nodes between two joints that are not joints of the skin are joints of
the rig too); the nodes above it (Mixamo's ``Armature``, scale 0.01 and a rotation) are folded
into the ground frame, so the rig lives in its root's parent space, with that space's units:
centimetres for a Mixamo character. Their transforms must be uniform scales, rotations and
translations; an animated node above the skeleton moves its root (its scale may not change).

**Sampling.** The animation's channels on the skeleton's nodes are sampled on a uniform clock
at the animation's own rate (the median interval between its keyframes), from its first to
its last keyframe, each with its sampler's interpolation: ``STEP``, ``LINEAR`` (slerp for
rotations, shortest way), ``CUBICSPLINE`` (cubic Hermite with the sampler's tangents,
rotations normalised); a node the animation does not drive keeps its own TRS. Joints may
carry a constant uniform scale (their children's offsets are scaled); an animated or
non-uniform joint scale is refused. A joint whose translation changes along the clip (a
pelvis under a ``root`` joint) keeps it as a position channel of the rig.

**Roles and landmarks** as the BVH importer's (:mod:`solver.io.roles`, :mod:`solver.io.joint_track`):
joint roles from the names (Mixamo, Unreal, Unity, Blender, …) and the hierarchy, or
``joints`` (role -> joint name); the rest pose is the nodes' own TRS. glTF is Y up and in
metres: the scene's up direction, carried into the skeleton's parent space, is our Z; our X
is the facing direction (perpendicular to the hip line, averaged over the clip; glTF
characters face +Z); the floor is the 2nd percentile of the sole points' heights. A
character whose legs are not 0.45-1.2 m long in the scene is refused. glTF has no subject
mass: pass ``mass`` (kg).

**The rig** (``capture.rig``, format ``"gltf"``): the skeleton's joints, their rest offsets
(parent-space units, joint scales applied), the sampled local rotations and root
translation, and in ``extra`` what the writer (``solver.export.rig_gltf``) needs: the joints'
node indices, the skin, the joints' accumulated scales, and the source asset itself (a GLB,
base64) without its animations and with every buffer and embedded image in its one binary
chunk. Files over :data:`MAX_BYTES` are refused.
"""

from __future__ import annotations

import base64
import json
import logging
import re
import struct
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from solver.capture import Capture, GroundFrame
from solver.errors import InputError
from solver.io.bvh import LEG_RANGE
from solver.io.fit import fit_track
from solver.io.joint_track import JointPose, ground_landmarks, walk_in_place
from solver.io.readers import TrialError
from solver.io.roles import (
    RoleError,
    describe_names,
    joint_roles,
    missing_roles,
    parse_joint_mapping,
    spine_joints,
)
from solver.io.track import SkeletonTrack
from solver.rig import Rig, segment_roles

log = logging.getLogger(__name__)

__all__ = ["MAX_BYTES", "GltfAsset", "GltfError", "gltf_track", "load_gltf", "parse_gltf", "read_gltf"]

#: the largest glTF file accepted (bytes): every motion made from the capture carries the asset
MAX_BYTES = 16 * 1024 * 1024
GLB_MAGIC, GLB_JSON, GLB_BIN = 0x46546C67, 0x4E4F534A, 0x004E4942
_NCOMP = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_CTYPE: dict[int, np.dtype[Any]] = {5120: np.dtype("i1"), 5121: np.dtype("u1"), 5122: np.dtype("<i2"),
                                    5123: np.dtype("<u2"), 5125: np.dtype("<u4"), 5126: np.dtype("<f4")}
#: the extensions whose data this reader cannot carry over into a GLB it writes back
_UNSUPPORTED_EXTENSIONS = ("EXT_meshopt_compression", "KHR_meshopt_compression")
#: a joint's translation "changes" along the clip beyond this fraction of the skeleton's size
_MOVE_TOL = 1e-5


class GltfError(InputError):
    """A glTF file is unreadable, or not a skinned, animated character; the message says why."""


# --- the container ------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class GltfAsset:
    """A glTF document with all of its binary data in one buffer (buffer 0, a GLB's BIN chunk):
    embedded buffers merged, embedded images moved into buffer views."""

    doc: dict[str, Any]
    bin: bytes = b""
    where: str = "glTF"
    _cache: dict[int, np.ndarray] = field(default_factory=dict, repr=False)

    def accessor(self, i: Any) -> np.ndarray:
        """Accessor ``i`` as floats (count, components); normalised integers scaled to [0, 1] or
        [-1, 1]; sparse substitutions applied."""
        if not isinstance(i, int) or isinstance(i, bool) or not 0 <= i < len(self.doc.get("accessors", [])):
            raise GltfError(f"{self.where}: accessor {i!r} does not exist")
        if i not in self._cache:
            self._cache[i] = self._read_accessor(i)
        return self._cache[i]

    def _view_bytes(self, v: Any) -> tuple[bytes, int, int | None]:
        views = self.doc.get("bufferViews", [])
        if not isinstance(v, int) or not 0 <= v < len(views):
            raise GltfError(f"{self.where}: buffer view {v!r} does not exist")
        view = views[v]
        off, length = int(view.get("byteOffset", 0)), int(view["byteLength"])
        if off + length > len(self.bin):
            raise GltfError(f"{self.where}: buffer view {v} reads past the end of its buffer")
        return self.bin[off:off + length], off, view.get("byteStride")

    def _read_accessor(self, i: int) -> np.ndarray:
        acc = self.doc["accessors"][i]
        try:
            dt = _CTYPE[acc["componentType"]]
            nc = _NCOMP[acc["type"]]
            count = int(acc["count"])
        except (KeyError, TypeError, ValueError):
            raise GltfError(f"{self.where}: accessor {i} is malformed") from None
        if acc["type"] in ("MAT2", "MAT3") and dt.itemsize < 4:
            raise GltfError(f"{self.where}: accessor {i}: padded {acc['type']} matrices are not supported")

        def read(view: Any, offset: int, n: int, dtype: np.dtype, comps: int) -> np.ndarray:
            data, _, stride = self._view_bytes(view)
            stride = int(stride or comps * dtype.itemsize)
            end = offset + (n - 1) * stride + comps * dtype.itemsize
            if n and end > len(data):
                raise GltfError(f"{self.where}: accessor {i} reads past its buffer view")
            if n == 0:
                return np.zeros((0, comps))
            raw = np.frombuffer(data, dtype=np.uint8, count=end - offset, offset=offset)
            out = np.lib.stride_tricks.as_strided(raw, shape=(n, comps * dtype.itemsize), strides=(stride, 1))
            return np.ascontiguousarray(out).view(dtype).reshape(n, comps).astype(float)

        if "bufferView" in acc:
            arr = read(acc["bufferView"], int(acc.get("byteOffset", 0)), count, dt, nc)
        else:
            arr = np.zeros((count, nc))
        sparse = acc.get("sparse")
        if sparse:
            try:
                n = int(sparse["count"])
                idx_t = _CTYPE[sparse["indices"]["componentType"]]
                idx = read(sparse["indices"]["bufferView"], int(sparse["indices"].get("byteOffset", 0)), n, idx_t,
                           1)[:, 0].astype(np.int64)
                vals = read(sparse["values"]["bufferView"], int(sparse["values"].get("byteOffset", 0)), n, dt, nc)
            except (KeyError, TypeError, ValueError):
                raise GltfError(f"{self.where}: accessor {i} has a malformed sparse part") from None
            if n and (idx.min() < 0 or idx.max() >= count):
                raise GltfError(f"{self.where}: accessor {i}: sparse indices out of range")
            arr[idx] = vals
        if acc.get("normalized") and dt.kind in "iu":
            top = float(np.iinfo(dt).max)
            arr = np.maximum(arr / top, -1.0)
        return arr


def _data_uri(uri: str, where: str, what: str) -> tuple[bytes, str]:
    m = re.match(r"data:([^,;]*)(;base64)?,", uri)
    if not m or not m.group(2):
        raise GltfError(f"{where}: {what} is an external file ({uri[:60]!r}); give a .glb, or a .gltf with its "
                        "buffers and images embedded (base64 data URIs)")
    try:
        return base64.b64decode(uri[m.end():], validate=False), m.group(1)
    except ValueError:
        raise GltfError(f"{where}: {what} has a malformed base64 data URI") from None


def split_glb(data: bytes, where: str) -> tuple[dict, bytes | None]:
    """A GLB's JSON document and binary chunk (None when it has none); ``where`` starts the
    messages of the GltfError it raises when the bytes are not a GLB 2.0."""
    if len(data) < 20:
        raise GltfError(f"{where}: truncated GLB (shorter than its header)")
    magic, version, length = struct.unpack_from("<III", data, 0)
    if magic != GLB_MAGIC:
        raise GltfError(f"{where}: not a GLB file (bad magic)")
    if version != 2:
        raise GltfError(f"{where}: GLB version {version}; only glTF 2.0 is supported")
    if length > len(data):
        raise GltfError(f"{where}: truncated GLB (the header says {length} bytes, the file has {len(data)})")
    doc, blob, off = None, None, 12
    while off + 8 <= length:
        clen, ctype = struct.unpack_from("<II", data, off)
        chunk = data[off + 8: off + 8 + clen]
        if len(chunk) != clen:
            raise GltfError(f"{where}: truncated GLB chunk")
        if ctype == GLB_JSON and doc is None:
            doc = _json(chunk, where)
        elif ctype == GLB_BIN and blob is None:
            blob = bytes(chunk)
        off += 8 + clen + (-clen % 4)
    if doc is None:
        raise GltfError(f"{where}: GLB without a JSON chunk")
    return doc, blob


def _json(data: bytes, where: str) -> dict:
    try:
        doc = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as e:
        raise GltfError(f"{where}: the glTF JSON is unreadable ({e})") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("asset"), dict):
        raise GltfError(f"{where}: not a glTF document (no 'asset')")
    version = str(doc["asset"].get("version", ""))
    if not version.startswith("2."):
        raise GltfError(f"{where}: glTF version {version or '?'}; only glTF 2.0 is supported")
    return doc


def parse_gltf(data: bytes, where: str = "glTF") -> GltfAsset:
    """A GLB or a glTF JSON document (buffers and images embedded as data URIs) as one
    :class:`GltfAsset`: every buffer merged into buffer 0, embedded images moved into buffer views."""
    if len(data) > MAX_BYTES:
        raise GltfError(f"{where}: {len(data) / 2**20:.1f} MB; glTF characters of at most {MAX_BYTES // 2**20} MB "
                        "are accepted (every motion made from it carries the asset)")
    if data[:4] == struct.pack("<I", GLB_MAGIC):
        doc, blob = split_glb(data, where)
    else:
        doc, blob = _json(data, where), None
    if not isinstance(doc.get("buffers", []), list) or not isinstance(doc.get("bufferViews", []), list):
        raise GltfError(f"{where}: malformed buffers or bufferViews")
    for ext in doc.get("extensionsUsed", []) or []:
        if ext in _UNSUPPORTED_EXTENSIONS:
            raise GltfError(f"{where}: the extension {ext} is not supported; export the character without it")
    merged = bytearray()
    bases = []
    for k, buf in enumerate(doc.get("buffers", [])):
        uri = buf.get("uri") if isinstance(buf, dict) else None
        if uri is None:
            if k != 0 or blob is None:
                raise GltfError(f"{where}: buffer {k} has no data (no uri and no GLB binary chunk)")
            chunk = blob
        else:
            chunk, _ = _data_uri(str(uri), where, f"buffer {k}")
        if len(chunk) < int(buf.get("byteLength", 0)):
            raise GltfError(f"{where}: buffer {k} is shorter than its byteLength")
        merged += b"\0" * (-len(merged) % 16)
        bases.append(len(merged))
        merged += chunk[: int(buf.get("byteLength", len(chunk)))]
    for v, view in enumerate(doc.get("bufferViews", [])):
        try:
            b = int(view.get("buffer", -1))
            view["byteOffset"] = bases[b] + int(view.get("byteOffset", 0))
        except (IndexError, TypeError, ValueError, AttributeError):
            raise GltfError(f"{where}: buffer view {v} refers to no buffer") from None
        view["buffer"] = 0
    for k, img in enumerate(doc.get("images", []) or []):
        uri = img.get("uri") if isinstance(img, dict) else None
        if uri is None:
            continue
        raw, mime = _data_uri(str(uri), where, f"image {k}")
        merged += b"\0" * (-len(merged) % 4)
        doc.setdefault("bufferViews", []).append({"buffer": 0, "byteOffset": len(merged), "byteLength": len(raw)})
        merged += raw
        del img["uri"]
        img["bufferView"] = len(doc["bufferViews"]) - 1
        img["mimeType"] = mime or ("image/png" if raw[:4] == b"\x89PNG" else "image/jpeg")
    merged += b"\0" * (-len(merged) % 4)
    doc["buffers"] = [{"byteLength": len(merged)}] if merged else []
    check_references(doc, len(merged), where)
    return GltfAsset(doc, bytes(merged), where)


#: the most elements one accessor may have (a 16 MB file holds at most 4 M floats)
MAX_ACCESSOR_COUNT = 1 << 24


def _index(v: Any, n: int) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and 0 <= v < n


def check_references(doc: Mapping[str, Any], size: int, where: str) -> None:
    """Refuse a document whose buffer views, accessors (sparse parts included), images, meshes,
    skins, nodes or animations refer to what does not exist or read outside their data: so no
    broken index or range (a bufferView 99999, a count of 2^31) is ever carried into a GLB this
    package writes. ``size``: the length of buffer 0 (every buffer merged)."""
    views = doc.get("bufferViews", []) or []
    accessors = doc.get("accessors", []) or []
    if not isinstance(accessors, list):
        raise GltfError(f"{where}: malformed accessors")
    for v, view in enumerate(views):
        if not isinstance(view, dict):
            raise GltfError(f"{where}: buffer view {v} is malformed")
        off, length, stride = view.get("byteOffset", 0), view.get("byteLength"), view.get("byteStride")
        if not (_index(off, size + 1) and isinstance(length, int) and not isinstance(length, bool) and length >= 1
                and off + length <= size):
            raise GltfError(f"{where}: buffer view {v} lies outside its buffer ({size} bytes)")
        if stride is not None and not (isinstance(stride, int) and 4 <= stride <= 252 and stride % 4 == 0):
            raise GltfError(f"{where}: buffer view {v} has an invalid byteStride")

    def view_range(i: int, what: str, ref: Any, offset: Any, count: int, elem: int, align: int) -> None:
        if not _index(ref, len(views)):
            raise GltfError(f"{where}: accessor {i}: {what} refers to buffer view {ref!r}, which does not exist")
        if not (isinstance(offset, int) and not isinstance(offset, bool) and offset >= 0 and offset % align == 0):
            raise GltfError(f"{where}: accessor {i}: {what} has an invalid byteOffset")
        stride = views[ref].get("byteStride") or elem
        if count and offset + (count - 1) * stride + elem > views[ref]["byteLength"]:
            raise GltfError(f"{where}: accessor {i}: {what} reads past the end of buffer view {ref}")

    for i, acc in enumerate(accessors):
        if not isinstance(acc, dict):
            raise GltfError(f"{where}: accessor {i} is malformed")
        ctype, kind, count = acc.get("componentType"), acc.get("type"), acc.get("count")
        if ctype not in _CTYPE or kind not in _NCOMP:
            raise GltfError(f"{where}: accessor {i} has an unknown componentType or type")
        if not (isinstance(count, int) and not isinstance(count, bool) and 1 <= count <= MAX_ACCESSOR_COUNT):
            raise GltfError(f"{where}: accessor {i} has a count of {str(count)[:20]}; from 1 to {MAX_ACCESSOR_COUNT} "
                            "elements are accepted")
        dt, nc = _CTYPE[ctype], _NCOMP[kind]
        if "bufferView" in acc:
            view_range(i, "its data", acc["bufferView"], acc.get("byteOffset", 0), count, dt.itemsize * nc,
                       dt.itemsize)
        for bound in ("min", "max"):
            b = acc.get(bound)
            if b is not None and not (isinstance(b, list) and len(b) == nc
                                      and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                              and np.isfinite(x) for x in b)):
                raise GltfError(f"{where}: accessor {i} has a malformed {bound} ({nc} finite numbers expected)")
        sparse = acc.get("sparse")
        if sparse is not None:
            try:
                n, idx, vals = int(sparse["count"]), sparse["indices"], sparse["values"]
                itype = _CTYPE[idx["componentType"]]
            except (KeyError, TypeError, ValueError):
                raise GltfError(f"{where}: accessor {i} has a malformed sparse part") from None
            if not 1 <= n <= count or itype.kind != "u":
                raise GltfError(f"{where}: accessor {i} has a malformed sparse part")
            view_range(i, "its sparse indices", idx.get("bufferView"), idx.get("byteOffset", 0), n, itype.itemsize,
                       itype.itemsize)
            view_range(i, "its sparse values", vals.get("bufferView"), vals.get("byteOffset", 0), n,
                       dt.itemsize * nc, dt.itemsize)

    def acc_ref(v: Any, what: str) -> None:
        if not _index(v, len(accessors)):
            raise GltfError(f"{where}: {what} refers to accessor {str(v)[:20]}, which does not exist")

    for k, img in enumerate(doc.get("images", []) or []):
        if isinstance(img, dict) and "bufferView" in img and not _index(img["bufferView"], len(views)):
            raise GltfError(f"{where}: image {k} refers to a buffer view that does not exist")
    for m, mesh in enumerate(doc.get("meshes", []) or []):
        for p, prim in enumerate((mesh or {}).get("primitives", []) or []):
            for name, v in ((prim or {}).get("attributes") or {}).items():
                acc_ref(v, f"mesh {m} primitive {p} attribute {str(name)[:40]}")
            if "indices" in prim:
                acc_ref(prim["indices"], f"mesh {m} primitive {p} indices")
            for target in prim.get("targets", []) or []:
                for v in (target or {}).values():
                    acc_ref(v, f"mesh {m} primitive {p} morph target")
    for k, skin in enumerate(doc.get("skins", []) or []):
        if isinstance(skin, dict) and "inverseBindMatrices" in skin:
            acc_ref(skin["inverseBindMatrices"], f"skin {k} inverseBindMatrices")
            if accessors[skin["inverseBindMatrices"]].get("type") != "MAT4":
                raise GltfError(f"{where}: skin {k}: its inverseBindMatrices are not 4x4 matrices")
    nodes = doc.get("nodes", []) or []
    for k, node in enumerate(nodes):
        if not isinstance(node, dict):
            raise GltfError(f"{where}: node {k} is malformed")
        for key, coll in (("mesh", "meshes"), ("skin", "skins"), ("camera", "cameras")):
            if key in node and not _index(node[key], len(doc.get(coll, []) or [])):
                raise GltfError(f"{where}: node {k} refers to a {key} that does not exist")
    for a, anim in enumerate(doc.get("animations", []) or []):
        samplers = (anim or {}).get("samplers", []) or []
        for smp in samplers:
            acc_ref((smp or {}).get("input"), f"animation {a} sampler input")
            acc_ref((smp or {}).get("output"), f"animation {a} sampler output")
        for ch in (anim or {}).get("channels", []) or []:
            if not _index((ch or {}).get("sampler"), len(samplers)):
                raise GltfError(f"{where}: animation {a} has a channel without its sampler")


def read_gltf(path: str | Path) -> GltfAsset:
    """The glTF file at ``path`` (:func:`parse_gltf`); files over :data:`MAX_BYTES` are refused."""
    p = Path(path)
    if not p.is_file():
        raise GltfError(f"glTF file not found: {p}")
    size = p.stat().st_size
    if size > MAX_BYTES:
        raise GltfError(f"{p}: {size / 2**20:.1f} MB; glTF characters of at most {MAX_BYTES // 2**20} MB are "
                        "accepted (every motion made from it carries the asset)")
    return parse_gltf(p.read_bytes(), str(p))


def glb_bytes(doc: Mapping[str, Any], data: bytes) -> bytes:
    """A GLB of a document and its buffer 0 (``buffers[0]`` without a uri)."""
    js = json.dumps(doc, allow_nan=False, separators=(",", ":"), ensure_ascii=False).encode("utf-8")
    js += b" " * (-len(js) % 4)
    data = bytes(data) + b"\0" * (-len(data) % 4)
    chunks = [struct.pack("<II", len(js), GLB_JSON), js]
    if data:
        chunks += [struct.pack("<II", len(data), GLB_BIN), data]
    total = 12 + sum(len(c) for c in chunks)
    return b"".join([struct.pack("<III", GLB_MAGIC, 2, total), *chunks])


def without_animations(asset: GltfAsset) -> GltfAsset:
    """The asset without its animations, and without the accessors and buffer views only they
    used (its binary data rebuilt from the buffer views kept)."""
    doc = json.loads(json.dumps(asset.doc))
    doc.pop("animations", None)
    for key in ("extensionsUsed", "extensionsRequired"):
        if key in doc:
            doc[key] = [e for e in doc[key] if e != "KHR_animation_pointer"]
            if not doc[key]:
                del doc[key]
    accessors = doc.get("accessors", [])
    used: set[int] = set()

    def use(i: Any) -> None:
        if isinstance(i, int) and 0 <= i < len(accessors):
            used.add(i)

    for mesh in doc.get("meshes", []):
        for prim in mesh.get("primitives", []):
            for v in (prim.get("attributes") or {}).values():
                use(v)
            use(prim.get("indices"))
            for target in prim.get("targets", []) or []:
                for v in target.values():
                    use(v)
    for skin in doc.get("skins", []):
        use(skin.get("inverseBindMatrices"))
    for node in doc.get("nodes", []):
        inst = ((node.get("extensions") or {}).get("EXT_mesh_gpu_instancing") or {}).get("attributes") or {}
        for v in inst.values():
            use(v)
    acc_map = {old: new for new, old in enumerate(sorted(used))}

    def remap_acc(i: Any) -> Any:
        return acc_map[i] if isinstance(i, int) and i in acc_map else i

    for mesh in doc.get("meshes", []):
        for prim in mesh.get("primitives", []):
            if "attributes" in prim:
                prim["attributes"] = {k: remap_acc(v) for k, v in prim["attributes"].items()}
            if "indices" in prim:
                prim["indices"] = remap_acc(prim["indices"])
            if prim.get("targets"):
                prim["targets"] = [{k: remap_acc(v) for k, v in t.items()} for t in prim["targets"]]
    for skin in doc.get("skins", []):
        if "inverseBindMatrices" in skin:
            skin["inverseBindMatrices"] = remap_acc(skin["inverseBindMatrices"])
    for node in doc.get("nodes", []):
        inst = ((node.get("extensions") or {}).get("EXT_mesh_gpu_instancing") or {})
        if inst.get("attributes"):
            inst["attributes"] = {k: remap_acc(v) for k, v in inst["attributes"].items()}
    doc["accessors"] = [accessors[i] for i in sorted(used)]
    if not doc["accessors"]:
        del doc["accessors"]
    # buffer views: those of the accessors kept and every other "bufferView" reference
    views = doc.get("bufferViews", [])
    refs: list[dict] = []

    def collect(obj: Any) -> None:
        if isinstance(obj, dict):
            if isinstance(obj.get("bufferView"), int):
                refs.append(obj)
            for v in obj.values():
                collect(v)
        elif isinstance(obj, list):
            for v in obj:
                collect(v)

    collect({k: v for k, v in doc.items() if k != "bufferViews"})
    kept = sorted({r["bufferView"] for r in refs if 0 <= r["bufferView"] < len(views)})
    view_map = {old: new for new, old in enumerate(kept)}
    for r in refs:
        if r["bufferView"] in view_map:
            r["bufferView"] = view_map[r["bufferView"]]
    data = bytearray()
    new_views = []
    for old in kept:
        v = dict(views[old])
        off, length = int(v.get("byteOffset", 0)), int(v["byteLength"])
        data += b"\0" * (-len(data) % 4)
        v["buffer"], v["byteOffset"] = 0, len(data)
        data += asset.bin[off:off + length]
        new_views.append(v)
    data += b"\0" * (-len(data) % 4)
    doc["bufferViews"] = new_views
    if not new_views:
        del doc["bufferViews"]
    doc["buffers"] = [{"byteLength": len(data)}] if data else []
    if not doc["buffers"]:
        del doc["buffers"]
    check_references(doc, len(data), asset.where)  # what is carried into the GLBs written from it
    return GltfAsset(doc, bytes(data), asset.where)


# --- nodes ---------------------------------------------------------------------------------------

def node_trs(node: Mapping[str, Any], where: str, index: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A node's (translation (3,), rotation quaternion (x, y, z, w), scale (3,)); a ``matrix`` is
    decomposed (it must be a rotation, a positive scale per axis and a translation)."""
    try:
        if "matrix" in node:
            m = np.asarray(node["matrix"], dtype=float).reshape(4, 4).T  # column-major
            if not np.all(np.isfinite(m)):
                raise GltfError(f"{where}: node {index} has a non-finite matrix")
            t = m[:3, 3].copy()
            s = np.linalg.norm(m[:3, :3], axis=0)
            if np.any(s < 1e-12) or np.linalg.det(m[:3, :3]) < 0:
                raise GltfError(f"{where}: node {index} ({node.get('name', '')!r}) has a degenerate or mirroring "
                                "matrix")
            r = m[:3, :3] / s
            q = Rotation.from_matrix(r).as_quat()
            return t, q, s
        t = np.asarray(node.get("translation", [0, 0, 0]), dtype=float).reshape(3)
        q = np.asarray(node.get("rotation", [0, 0, 0, 1]), dtype=float).reshape(4)
        s = np.asarray(node.get("scale", [1, 1, 1]), dtype=float).reshape(3)
    except (TypeError, ValueError):
        raise GltfError(f"{where}: node {index} has a malformed transform") from None
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(q)) and np.all(np.isfinite(s))):
        raise GltfError(f"{where}: node {index} ({node.get('name', '')!r}) has a non-finite transform")
    n = np.linalg.norm(q)
    if n < 1e-9:
        raise GltfError(f"{where}: node {index} has a zero rotation quaternion")
    return t, q / n, s


def node_parents(doc: Mapping[str, Any], where: str) -> list[int]:
    """Each node's parent index (-1 for a root); a node with two parents or a cycle is refused."""
    nodes = doc.get("nodes", [])
    parent = [-1] * len(nodes)
    for i, n in enumerate(nodes):
        for c in n.get("children", []) or []:
            if not isinstance(c, int) or not 0 <= c < len(nodes) or c == i:
                raise GltfError(f"{where}: node {i} has an invalid child {c!r}")
            if parent[c] >= 0:
                raise GltfError(f"{where}: node {c} has two parents")
            parent[c] = i
    for i in range(len(nodes)):
        seen, p = {i}, parent[i]
        while p >= 0:
            if p in seen:
                raise GltfError(f"{where}: the node hierarchy has a cycle through node {i}")
            seen.add(p)
            p = parent[p]
    return parent


def _ancestors(parent: list[int], i: int) -> list[int]:
    out, p = [], parent[i]
    while p >= 0:
        out.append(p)
        p = parent[p]
    return out


def _matrix(t: np.ndarray, q: np.ndarray, s: np.ndarray) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = Rotation.from_quat(q).as_matrix() * s
    m[:3, 3] = t
    return m


# --- animation sampling --------------------------------------------------------------------------

def _sample_channel(times: np.ndarray, keys: np.ndarray, values: np.ndarray, interp: str, path: str,
                    t: np.ndarray) -> np.ndarray:
    """A sampler's value at times ``t`` (clamped to its keyframes)."""
    n = keys.size
    nc = values.shape[1]
    if interp == "CUBICSPLINE":
        vals = values.reshape(n, 3, nc)
        a_in, v, b_out = vals[:, 0], vals[:, 1], vals[:, 2]
    else:
        v = values
    if path == "rotation" and interp != "CUBICSPLINE":  # the shortest way between keys
        v = v.copy()
        for k in range(1, n):
            if v[k] @ v[k - 1] < 0:
                v[k] = -v[k]
    tc = np.clip(t, keys[0], keys[-1])
    k = np.clip(np.searchsorted(keys, tc, side="right") - 1, 0, max(n - 2, 0))
    if n == 1:
        return np.repeat(v[:1], t.size, axis=0)
    td = keys[k + 1] - keys[k]
    s = np.where(td > 0, (tc - keys[k]) / np.where(td > 0, td, 1.0), 0.0)
    s = np.clip(s, 0.0, 1.0)[:, None]
    if interp == "STEP":
        out = np.where(s >= 1.0, v[k + 1], v[k])
    elif interp == "CUBICSPLINE":
        s2, s3 = s * s, s * s * s
        out = ((2 * s3 - 3 * s2 + 1) * v[k] + (s3 - 2 * s2 + s) * td[:, None] * b_out[k]
               + (-2 * s3 + 3 * s2) * v[k + 1] + (s3 - s2) * td[:, None] * a_in[k + 1])
    elif path == "rotation":
        q0, q1 = v[k], v[k + 1]
        d = np.clip(np.sum(q0 * q1, axis=1), -1.0, 1.0)
        th = np.arccos(d)[:, None]
        sin = np.sin(th)
        small = sin[:, 0] < 1e-6
        w0 = np.where(small[:, None], 1 - s, np.sin((1 - s) * th) / np.where(small[:, None], 1.0, sin))
        w1 = np.where(small[:, None], s, np.sin(s * th) / np.where(small[:, None], 1.0, sin))
        out = w0 * q0 + w1 * q1
    else:
        out = (1 - s) * v[k] + s * v[k + 1]
    if path == "rotation":
        out = out / np.linalg.norm(out, axis=1, keepdims=True)
    return out


@dataclass(frozen=True, eq=False)
class _Clip:
    name: str
    index: int
    times: np.ndarray  # (F,) s from the first keyframe
    # node -> path -> (F, 3 or 4) values at ``times``
    tracks: dict[int, dict[str, np.ndarray]]


def _pick_animation(asset: GltfAsset, animation: int | str | None) -> int:
    anims = asset.doc.get("animations") or []
    where = asset.where
    if not anims:
        raise GltfError(f"{where}: the file has no animation; a walk animation of the character is needed")
    names = [str(a.get("name", "")) for a in anims]
    if animation is None:
        return 0
    if isinstance(animation, str) and animation in names:
        return names.index(animation)
    if isinstance(animation, int) or (isinstance(animation, str) and animation.strip().isdigit()):
        k = int(animation)
        if 0 <= k < len(anims):
            return k
    listed = ", ".join(f"{k}: {n or '(unnamed)'}" for k, n in enumerate(names[:20]))
    raise GltfError(f"{where}: no animation {animation!r}; the file has {len(anims)}: {listed}",
                    parameter="animation")


def _sample(asset: GltfAsset, index: int, nodes: set[int]) -> _Clip:
    """Animation ``index``'s channels on ``nodes``, sampled at its own rate (see the module doc)."""
    where = asset.where
    anim = asset.doc["animations"][index]
    name = str(anim.get("name", "")) or f"animation {index}"
    samplers = anim.get("samplers") or []
    chans = []
    all_keys = []
    for c, ch in enumerate(anim.get("channels") or []):
        target = ch.get("target") or {}
        node, path = target.get("node"), target.get("path")
        if node not in nodes or path not in ("translation", "rotation", "scale"):
            continue
        s = ch.get("sampler")
        if not isinstance(s, int) or not 0 <= s < len(samplers):
            raise GltfError(f"{where}: {name}: channel {c} has no sampler")
        smp = samplers[s]
        keys = asset.accessor(smp.get("input"))[:, 0]
        vals = asset.accessor(smp.get("output"))
        interp = str(smp.get("interpolation", "LINEAR"))
        if interp not in ("LINEAR", "STEP", "CUBICSPLINE"):
            raise GltfError(f"{where}: {name}: sampler {s} has the unknown interpolation {interp!r}")
        per_key = 3 if interp == "CUBICSPLINE" else 1
        width = 4 if path == "rotation" else 3
        if keys.size == 0 or vals.shape != (keys.size * per_key, width):
            raise GltfError(f"{where}: {name}: sampler {s} has {keys.size} keyframes but {vals.shape[0]} values of "
                            f"{vals.shape[1]} components (expected {keys.size * per_key} of {width})")
        if not (np.all(np.isfinite(keys)) and np.all(np.isfinite(vals))):
            raise GltfError(f"{where}: {name}: sampler {s} ({path} of node {node}) holds NaN or infinite values")
        if np.any(np.diff(keys) <= 0):
            raise GltfError(f"{where}: {name}: sampler {s}'s keyframe times are not strictly increasing")
        chans.append((node, path, keys, vals, interp))
        all_keys.append(keys)
    if not chans:
        raise GltfError(f"{where}: the animation {name!r} moves none of the skeleton's joints")
    keys = np.unique(np.concatenate(all_keys))
    if keys.size < 2:
        raise GltfError(f"{where}: the animation {name!r} has a single keyframe: a walk needs a clip")
    t0, t1 = float(keys[0]), float(keys[-1])
    dt = float(np.median(np.diff(keys)))
    n = max(int(round((t1 - t0) / dt)), 1)
    times = t0 + (t1 - t0) * np.arange(n + 1) / n
    # the clock's ticks on keyframes (to their float32 rounding) are those keyframes: a STEP key holds from there
    near = np.clip(np.searchsorted(keys, times), 1, keys.size - 1)
    near = np.where(np.abs(keys[near - 1] - times) < np.abs(keys[near] - times), near - 1, near)
    snap = np.abs(keys[near] - times) < 1e-3 * dt
    times[snap] = keys[near[snap]]
    tracks: dict[int, dict[str, np.ndarray]] = {}
    for node, path, k, vals, interp in chans:
        tracks.setdefault(node, {})[path] = _sample_channel(times, k, vals, interp, path, times)
    return _Clip(name, index, times - t0, tracks)


# --- the skeleton --------------------------------------------------------------------------------

def _pick_skin(asset: GltfAsset, anim: int) -> int:
    skins = asset.doc.get("skins") or []
    if not skins:
        raise GltfError(f"{asset.where}: the file has no skin (a skinned character is needed: a mesh bound to a "
                        "skeleton)")
    driven = {(ch.get("target") or {}).get("node") for ch in asset.doc["animations"][anim].get("channels") or []}
    nodes = asset.doc.get("nodes", [])
    best, score = 0, -1
    for k, skin in enumerate(skins):
        joints = skin.get("joints") or []
        if not joints or not all(isinstance(j, int) and 0 <= j < len(nodes) for j in joints):
            raise GltfError(f"{asset.where}: skin {k} has no joints, or joints that are not nodes")
        n = len(set(joints) & driven)
        if n > score:
            best, score = k, n
    return best


def _skeleton(asset: GltfAsset, skin: int, parent: list[int]) -> list[int]:
    """The skeleton's nodes, parents first (depth-first): the skin's joints below its top joint
    with the most joints below it, and the nodes between them."""
    joints = set(asset.doc["skins"][skin]["joints"])
    tops = [j for j in joints if not any(a in joints for a in _ancestors(parent, j))]
    below = {t: [j for j in joints if j == t or t in _ancestors(parent, j)] for t in tops}
    top = max(sorted(tops), key=lambda t: len(below[t]))
    members = set()
    for j in below[top]:
        members.add(j)
        for a in _ancestors(parent, j):
            if a == top:
                break
            members.add(a)
    if len(tops) > 1:
        log.info("%s: skin %d has %d top joints; the skeleton is the one under node %d (%d joints)", asset.where,
                 skin, len(tops), top, len(below[top]))
    nodes = asset.doc["nodes"]
    order: list[int] = []

    def visit(i: int) -> None:
        order.append(i)
        for c in nodes[i].get("children", []) or []:
            if c in members:
                visit(c)

    visit(top)
    return order


@dataclass(frozen=True, eq=False)
class _Skeleton:
    nodes: list[int]  # node index per joint
    names: tuple[str, ...]
    parents: tuple[int, ...]
    times: np.ndarray  # (F,)
    local: np.ndarray  # (F, J, 3, 3) local rotations (parent space)
    translation: np.ndarray  # (F, J, 3) local translations in the parent's scaled units (the rig's offsets)
    rest_local: np.ndarray  # (J, 3, 3)
    rest_translation: np.ndarray  # (J, 3)
    scales: np.ndarray  # (J,) accumulated uniform scale of each joint's frame (its own included)
    up: np.ndarray  # the scene's up direction in the skeleton's parent space
    unit_m: float  # metres per unit of the skeleton's parent space
    moved: bool  # some non-root joint's translation changes along the clip
    clip: _Clip
    skin: int


def _uniform(s: np.ndarray, what: str, where: str) -> float:
    if np.any(s <= 0) or np.ptp(s) > 1e-4 * float(np.max(np.abs(s))):
        raise GltfError(f"{where}: {what} has the scale {np.round(s, 6).tolist()}; only uniform positive scales "
                        "are supported")
    return float(np.mean(s))


def _read_skeleton(asset: GltfAsset, animation: int | str | None) -> _Skeleton:
    where = asset.where
    doc = asset.doc
    nodes = doc.get("nodes") or []
    if not nodes:
        raise GltfError(f"{where}: the file has no nodes")
    parent = node_parents(doc, where)
    anim = _pick_animation(asset, animation)
    skin = _pick_skin(asset, anim)
    order = _skeleton(asset, skin, parent)
    index = {n: j for j, n in enumerate(order)}
    top = order[0]
    above = _ancestors(parent, top)  # nearest first
    clip = _sample(asset, anim, set(order) | set(above))
    F, J = clip.times.size, len(order)
    trs = {i: node_trs(nodes[i], where, i) for i in set(order) | set(above)}

    def animated(i: int, path: str, rest: np.ndarray) -> np.ndarray:
        v = clip.tracks.get(i, {}).get(path)
        return np.broadcast_to(rest, (F, rest.size)) if v is None else v

    # the nodes above the skeleton: their rest transform is the ground frame's, their motion the root's
    M_rest = np.eye(4)
    M_anim = np.broadcast_to(np.eye(4), (F, 4, 4)).copy()
    for i in reversed(above):  # root-most first
        t, q, s = trs[i]
        M_rest = M_rest @ _matrix(t, q, s)
        T_, Q_, S_ = animated(i, "translation", t), animated(i, "rotation", q), animated(i, "scale", s)
        for f in range(F):
            M_anim[f] = M_anim[f] @ _matrix(T_[f], Q_[f], S_[f])
    unit = _uniform(np.linalg.norm(M_rest[:3, :3], axis=0), "the nodes above the skeleton", where)
    R_above = M_rest[:3, :3] / unit
    if np.linalg.det(R_above) < 0:
        raise GltfError(f"{where}: the nodes above the skeleton mirror it (negative scale): not supported")
    D = np.einsum("ij,fjk->fik", np.linalg.inv(M_rest), M_anim)  # the motion of the skeleton's parent space
    for f in range(F):
        sv = np.linalg.svd(D[f, :3, :3], compute_uv=False)
        if np.max(np.abs(sv - 1.0)) > 1e-4:
            raise GltfError(f"{where}: the animation scales the nodes above the skeleton: not supported")
    up = R_above.T @ np.array([0.0, 1.0, 0.0])
    names = tuple(str(nodes[i].get("name") or f"node{i}") for i in order)
    parents = tuple(index[parent[i]] if j else -1 for j, i in enumerate(order))
    local = np.empty((F, J, 3, 3))
    trans = np.empty((F, J, 3))
    rest_local = np.empty((J, 3, 3))
    rest_t = np.empty((J, 3))
    scales = np.empty(J)
    for j, i in enumerate(order):
        t, q, s = trs[i]
        if "scale" in clip.tracks.get(i, {}):
            sc = clip.tracks[i]["scale"]
            if np.max(np.abs(sc - s)) > 1e-4 * max(float(np.max(np.abs(s))), 1e-9):
                raise GltfError(f"{where}: the animation scales the joint {names[j]!r}: not supported")
        own = _uniform(s, f"the joint {names[j]!r}", where)
        p = parents[j]
        scales[j] = own * (scales[p] if p >= 0 else 1.0)
        par_scale = scales[p] if p >= 0 else 1.0
        rest_local[j] = Rotation.from_quat(q).as_matrix()
        rest_t[j] = par_scale * t
        local[:, j] = Rotation.from_quat(animated(i, "rotation", q)).as_matrix()
        trans[:, j] = par_scale * animated(i, "translation", t)
    # the root in the (moving) parent space of the skeleton
    Dr = D[:, :3, :3]
    local[:, 0] = np.einsum("fij,fjk->fik", Dr, local[:, 0])
    trans[:, 0] = np.einsum("fij,fj->fi", Dr, trans[:, 0]) + D[:, :3, 3]
    if not (np.all(np.isfinite(local)) and np.all(np.isfinite(trans))):
        raise GltfError(f"{where}: the skeleton's animation has non-finite values")
    size = float(np.max(np.linalg.norm(rest_t, axis=1))) or 1.0
    moved = J > 1 and bool(np.max(np.abs(trans[:, 1:] - trans[:1, 1:])) > _MOVE_TOL * size)
    return _Skeleton(order, names, parents, clip.times, local, trans, rest_local, rest_t, scales, up, unit, moved,
                     clip, skin)


def _forward(parents: tuple[int, ...], local: np.ndarray, trans: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World rotations (J, F, 3, 3) and positions (J, F, 3) from local rotations (F, J, 3, 3) and
    translations (F, J, 3) (a child's translation in its parent's frame)."""
    F, J = local.shape[:2]
    R = np.empty((J, F, 3, 3))
    P = np.empty((J, F, 3))
    for j, p in enumerate(parents):
        if p < 0:
            R[j], P[j] = local[:, j], trans[:, j]
        else:
            R[j] = R[p] @ local[:, j]
            P[j] = P[p] + np.einsum("fij,fj->fi", R[p], trans[:, j])
    return R, P


def _roles(sk: _Skeleton, P_rest: np.ndarray, path: str | Path,
           joints: str | Path | Mapping[str, str] | None) -> tuple[dict[str, int], list[int]]:
    try:
        roles = joint_roles(sk.names, sk.parents, parse_joint_mapping(joints), rest=P_rest * sk.unit_m)
    except RoleError as e:
        raise GltfError(f"{path}: {e}", parameter="joints") from None
    missing = missing_roles(roles)
    for s in "rl":
        a = roles.get(f"ankle_{s}")
        if a is not None and f"mtp_{s}" not in roles and a not in sk.parents:
            missing.append(f"mtp_{s}")
    if missing:
        raise GltfError(f"{path}: cannot find the joints for the roles {', '.join(missing)} among the skeleton's "
                        f"joints {describe_names(sk.names)}; name them in a joint mapping ROLE=NAME,... (the roles: "
                        "docs/import.md)", parameter="joints")
    return roles, spine_joints(sk.parents, roles)


def _track(asset: GltfAsset, path: str | Path, mass: float | None, joints: str | Path | Mapping[str, str] | None,
           animation: int | str | None, belt_speed: float | str | None = None
           ) -> tuple[SkeletonTrack, _Skeleton, dict[str, int]]:
    sk = _read_skeleton(asset, animation)
    R_rest, P_rest = _forward(sk.parents, sk.rest_local[None], sk.rest_translation[None])
    R, P = _forward(sk.parents, sk.local, sk.translation)
    roles, spines = _roles(sk, P_rest[:, 0], path, joints)
    leg = float(np.mean([np.linalg.norm(P_rest[roles[f"hip_{s}"], 0] - P_rest[roles[f"knee_{s}"], 0])
                         + np.linalg.norm(P_rest[roles[f"knee_{s}"], 0] - P_rest[roles[f"ankle_{s}"], 0])
                         for s in "rl"])) * sk.unit_m
    if not LEG_RANGE[0] <= leg <= LEG_RANGE[1]:
        raise GltfError(f"{path}: the character's legs (hip -> knee -> ankle) are {leg:.4g} m long in the scene; a "
                        f"walking person's are {LEG_RANGE[0]}-{LEG_RANGE[1]} m (glTF lengths are metres: check the "
                        "scale of the nodes above the skeleton)")
    pose = JointPose(sk.parents, R_rest[:, 0], P_rest[:, 0], R, P, {}, sk.up, GltfError)
    g = ground_landmarks(pose, roles, sk.unit_m, None, path)
    if not g.upper_body:
        log.info("%s: no usable upper body (%s missing): lower-body track", path, g.missing_upper)
    frame = GroundFrame(R=g.R.T, offset=g.offset * sk.unit_m, unit_m=sk.unit_m,
                        axes=f"glTF skeleton space (below node {sk.nodes[0]}'s parents): up "
                             f"{np.round(sk.up, 3).tolist()}, facing {np.round(g.facing, 3).tolist()}, "
                             f"{sk.unit_m:g} m per unit")
    track = SkeletonTrack(
        times=sk.times, landmarks=g.landmarks, frame=frame, mass=mass,
        source={"format": "gltf", "file": str(Path(path).resolve()), "animation": sk.clip.name,
                "animation_index": sk.clip.index, "skin": sk.skin, "metres_per_unit": sk.unit_m,
                "frame_time": float(sk.times[1] - sk.times[0]),
                "mass_from": "given" if mass is not None else None,
                "joint_roles": {r: sk.names[j] for r, j in roles.items()},
                "spine_joints": [sk.names[j] for j in spines], "floor_height_file_units": g.floor_height,
                "estimated_tips": list(g.estimated)},
    )
    return walk_in_place(track, belt_speed, GltfError, path), sk, roles


def gltf_track(path: str | Path, *, mass: float | None = None, joints: str | Path | Mapping[str, str] | None = None,
               animation: int | str | None = None, belt_speed: float | str | None = None) -> SkeletonTrack:
    """The landmarks of a skinned glTF character's animation (conventions in the module doc)."""
    return _track(read_gltf(path), path, mass, joints, animation, belt_speed)[0]


def trial_files(paths: list[Path]) -> dict[str, Path]:
    """A glTF trial is one ``.glb`` or ``.gltf`` file (the reader registry's ``trial_files``)."""
    if len(paths) != 1:
        raise TrialError(f"one .glb or .gltf file expected, got {len(paths)}")
    return {"path": paths[0]}


def load_gltf(path: str | Path, *, mass: float | None = None, lower_only: bool | None = None,
              joints: str | Path | Mapping[str, str] | None = None, animation: int | str | None = None,
              belt_speed: float | str | None = None) -> Capture:
    """Import a skinned glTF character's walk as a :class:`Capture` (conventions in the module
    doc), with the character's own skeleton as its rig (format ``"gltf"``). ``animation``: the
    animation's name or index (default: the first); ``joints``: role -> joint name for joints
    whose names are not recognised; ``belt_speed``: an in-place walk's speed (m/s), ``"auto"``, 0 (not
    in place), None: detected (:func:`solver.io.joint_track.walk_in_place`)."""
    asset = read_gltf(path)
    track, sk, roles = _track(asset, path, mass, joints, animation, belt_speed)
    capture = fit_track(track, lower_only=lower_only)
    return capture.evolve(rig=gltf_rig(asset, sk, roles, track))


def gltf_rig(asset: GltfAsset, sk: _Skeleton, roles: Mapping[str, int], track: SkeletonTrack) -> Rig:
    """The character's skeleton and animation as a :class:`solver.rig.Rig` (see the module doc)."""
    J = len(sk.names)
    stripped = without_animations(asset)
    glb = glb_bytes(stripped.doc, stripped.bin)
    offsets = sk.translation[0].copy() if not sk.moved else sk.rest_translation.copy()
    offsets[0] = sk.rest_translation[0]  # the root's translation is the rig's ``root``
    channels = tuple(("Xposition", "Yposition", "Zposition", "quaternion") if j == 0 or sk.moved else ("quaternion",)
                     for j in range(J))
    extra: dict[str, Any] = {
        "frame_time": float(sk.times[1] - sk.times[0]), "nodes": list(sk.nodes), "skin": sk.skin,
        "scales": sk.scales.tolist(), "animation": sk.clip.name, "asset": base64.b64encode(glb).decode("ascii"),
    }
    if sk.moved or roles.get("hips", 0) != 0:  # joints with position channels (a pelvis under a root)
        extra["positions"] = sk.translation.tolist()
    return Rig("gltf", sk.names, sk.parents, offsets, channels, segment_roles(roles), sk.times, sk.local,
               sk.translation[:, 0], track.frame, extra=extra)
