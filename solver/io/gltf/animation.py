"""The animation read from a glTF file: which one (:func:`_pick_animation`) and its channels
sampled on a uniform clock at its own rate (:func:`_sample`), each with its sampler's
interpolation (:func:`_sample_channel`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from solver.io.gltf.base import GltfError
from solver.io.gltf.container import GltfAsset


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
