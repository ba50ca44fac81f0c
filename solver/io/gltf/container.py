"""The glTF container: a GLB or a glTF JSON document (buffers and images embedded) read into
one :class:`GltfAsset` with all of its binary data in one buffer and its accessors read as
arrays; a GLB written back, and the asset without its animations (what the rig carries)."""

from __future__ import annotations

import base64
import json
import re
import struct
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from solver.io.gltf.base import _CTYPE, _NCOMP, GLB_BIN, GLB_JSON, GLB_MAGIC, GltfError
from solver.io.gltf.references import check_references

#: the largest glTF file accepted (bytes): every motion made from the capture carries the asset
MAX_BYTES = 16 * 1024 * 1024
#: the extensions whose data this reader cannot carry over into a GLB it writes back
_UNSUPPORTED_EXTENSIONS = ("EXT_meshopt_compression", "KHR_meshopt_compression")


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
