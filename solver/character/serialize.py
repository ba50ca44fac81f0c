"""Characters as JSON-ready dicts (motion files carry their character)."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from solver.character.base import Character, CharacterError, ContactPoint, Dof, FootBox, Segment


def _arr(x: np.ndarray) -> list:
    return np.asarray(x, dtype=float).tolist()


def _num(x: float) -> float | None:
    return None if not math.isfinite(x) else float(x)


def character_to_dict(ch: Character) -> dict:
    """A JSON-ready description from which :func:`character_from_dict` rebuilds ``ch`` exactly."""
    return {
        "name": ch.name,
        "height": ch.height,
        "description": ch.description,
        "segments": [
            {
                "name": s.name,
                "parent": s.parent,
                "offset": _arr(s.offset),
                "orientation": _arr(s.orientation),
                "dofs": [
                    {"name": d.name, "kind": d.kind, "axis": _arr(d.axis), "lower": _num(d.lower),
                     "upper": _num(d.upper)}
                    for d in s.dofs
                ],
                "mass": s.mass,
                "com": _arr(s.com),
                "inertia": _arr(s.inertia),
                "length": s.length,
                "direction": _arr(s.direction),
                "radius": s.radius,
            }
            for s in ch.segments
        ],
        "contacts": [
            {"name": c.name, "side": c.side, "segment": c.segment, "position": _arr(c.position)} for c in ch.contacts
        ],
        "feet": [{"side": f.side, "segment": f.segment, "center": _arr(f.center), "half": _arr(f.half)}
                 for f in ch.feet],
    }


def character_from_dict(d: Mapping) -> Character:
    try:
        segs = []
        for s in d["segments"]:
            dofs = tuple(
                Dof(
                    str(j["name"]), str(j["kind"]), np.asarray(j["axis"], dtype=float),
                    -math.inf if j.get("lower") is None else float(j["lower"]),
                    math.inf if j.get("upper") is None else float(j["upper"]),
                )
                for j in s["dofs"]
            )
            segs.append(
                Segment(
                    name=str(s["name"]), parent=s["parent"], offset=np.asarray(s["offset"], dtype=float), dofs=dofs,
                    mass=float(s["mass"]), com=np.asarray(s["com"], dtype=float),
                    inertia=np.asarray(s["inertia"], dtype=float), length=float(s.get("length", 0.0)),
                    direction=np.asarray(s.get("direction", [0, 0, 1]), dtype=float),
                    radius=float(s.get("radius", 0.0)),
                    orientation=np.asarray(s.get("orientation", np.eye(3)), dtype=float),
                )
            )
        contacts = tuple(
            ContactPoint(str(c["name"]), str(c["side"]), str(c["segment"]), np.asarray(c["position"], dtype=float))
            for c in d.get("contacts", [])
        )
        feet = tuple(
            FootBox(str(f["side"]), str(f["segment"]), np.asarray(f["center"], dtype=float),
                    np.asarray(f["half"], dtype=float))
            for f in d.get("feet", [])
        )
    except (KeyError, TypeError, ValueError) as e:
        if isinstance(e, CharacterError):
            raise
        raise CharacterError(f"invalid character description: {e!r}") from None
    return Character(
        name=str(d["name"]), segments=tuple(segs), contacts=contacts, feet=feet,
        height=float(d.get("height", 0.0)), description=str(d.get("description", "")),
    )
