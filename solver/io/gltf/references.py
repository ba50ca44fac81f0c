"""A glTF document's references checked: every index it holds names what exists, and every
byte range it reads lies inside its data (:func:`check_references`)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from solver.io.gltf.base import _CTYPE, _NCOMP, GltfError

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
