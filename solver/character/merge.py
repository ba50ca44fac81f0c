"""Simplification: merging a character's segments into one rigid body."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import replace

import numpy as np

from solver import spatial as sp
from solver.character.base import Character, CharacterError


def merge_segments(ch: Character, names: Iterable[str], name: str | None = None,
                   pose: Mapping[str, float] | None = None) -> Character:
    """Remove segments (and their descendants' coordinates), lumping their mass into the parent.

    The removed segments are frozen relative to the parent they are merged into, in the
    posture given by ``pose`` (coordinate name -> value; missing coordinates at 0), with an
    exact rigid-body inertia composition. Used to turn a whole-body capture into a
    lower-body one whose pelvis carries head, arms and trunk (in the subject's mean
    posture over the cycle).
    """
    pose = dict(pose or {})
    names = set(names)
    by_name = {s.name: s for s in ch.segments}
    unknown = names - set(by_name)
    if unknown:
        raise CharacterError(f"cannot merge unknown segments {sorted(unknown)}")
    # every descendant of a removed segment is removed too
    removed: set[str] = set()
    for s in ch.segments:
        if s.name in names or (s.parent is not None and s.parent in removed):
            removed.add(s.name)
    if ch.segments[0].name in removed:
        raise CharacterError("cannot merge the root segment")
    # pose of every removed segment in the frame of its nearest kept ancestor (q = 0)
    rel: dict[str, tuple[str, np.ndarray, np.ndarray]] = {}
    for s in ch.segments:
        if s.name not in removed:
            rel[s.name] = (s.name, np.eye(3), np.zeros(3))
            continue
        anc, r, p = rel[s.parent]  # type: ignore[index]
        r, p = r @ s.orientation, p + r @ s.offset
        for d in s.dofs:  # the frozen joint values, applied in order like the joints themselves
            v = float(pose.get(d.name, 0.0))
            if d.kind == "hinge":
                r = r @ sp.rotation_about(d.axis, v)
            else:
                p = p + r @ (d.axis * v)
        rel[s.name] = (anc, r, p)
    extra: dict[str, list] = {}
    for s in ch.segments:
        if s.name in removed:
            anc, r, p = rel[s.name]
            extra.setdefault(anc, []).append((s.mass, p + r @ s.com, r @ s.inertia @ r.T))
    segs = []
    for s in ch.segments:
        if s.name in removed:
            continue
        if s.name not in extra:
            segs.append(s)
            continue
        parts = [(s.mass, s.com, s.inertia)] + extra[s.name]
        m = sum(x[0] for x in parts)
        c = sum(x[0] * x[1] for x in parts) / m
        inertia = np.zeros((3, 3))
        for mi, ci, ii in parts:
            d = ci - c
            inertia += ii + mi * (float(d @ d) * np.eye(3) - np.outer(d, d))
        segs.append(replace(s, mass=m, com=c, inertia=0.5 * (inertia + inertia.T)))
    for c in ch.contacts:
        if c.segment in removed:
            raise CharacterError(f"contact point {c.name!r} is on merged segment {c.segment!r}")
    return replace(ch, segments=tuple(segs), name=name or f"{ch.name}-merged")
