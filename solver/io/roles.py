"""Joint roles of a character skeleton from its joint names and hierarchy (the BVH importer's and
the glTF skin importer's).

Public API::

    joint_roles(names, parents, mapping=None, *, rest=None) -> dict[str, int]   # role -> joint index
    spine_joints(parents, roles) -> list[int]                                  # hips (excl.) .. neck/head (excl.)
    parse_joint_mapping(spec) -> dict[str, str]                                 # "hip_l=Thigh_L,..." -> role -> name
    missing_roles(roles) -> list[str]                                          # the required roles not found
    classify(name) -> (word class, side) | None                                # one name, no hierarchy

**Roles** (:data:`ROLES`): ``hips`` (the pelvis joint), ``lumbar`` (the first spine joint more than
3 cm from the hip joints' mid-point), ``neck``, ``head``, and per side ``_r`` / ``_l``: ``hip``,
``knee``, ``ankle``, ``mtp`` (toe base; alias ``toe``), ``clavicle``, ``shoulder``, ``elbow``,
``wrist``. Required (:data:`REQUIRED`): ``hips`` and ``hip``/``knee``/``ankle`` of both sides.

**Names.** Case-insensitive; a namespace (``mixamorig:``, ``Armature|``) and the prefixes
``Bip01``/``Bip001``, ``Character1_``, ``DEF-``, ``CC_Base_`` are ignored; a Blender duplicate
suffix (``.001``) and trailing digits (``Spine1``, ``spine_01``, ``Toe0``) too. The side is a
separated suffix (``thigh_l``, ``thigh.L``, ``Thigh_Left``), a separated prefix (``L_Thigh``,
``Bip01 L Thigh``), ``Left``/``Right`` before or after the name (``LeftUpLeg``, ``KneeLeft``),
``l``/``r`` before a capital (``lThigh``, ``LHipJoint``), or ``l``/``r`` glued to a known name
(``lfemur``). Words per role (:data:`SIDED_WORDS`, :data:`CENTRAL_WORDS`) cover CMU/ASF,
Mixamo/MotionBuilder, Unreal, Unity, Blender (Rigify), 3ds Max Biped and DAZ skeletons.

**Hierarchy.** A limb joint must lie below the joint of the role before it (knee below hip,
ankle below knee, toe below ankle, shoulder below clavicle, elbow below shoulder, wrist below
elbow): of several joints named alike, the first below wins. A knee (elbow) that no name gives
is the single joint between hip and ankle (shoulder and wrist). A ``…Shoulder`` joint with an
elbow but no upper-arm joint below it is the shoulder (no clavicle). ``hips`` is the deepest
joint named hips/pelvis above both hip joints, else their nearest common ancestor, else a
hips-named joint, else the root. ``lumbar``: the spine chain is the joints from the hips (not
included) to the neck or head (not included) — whatever their names; with ``rest`` (rest-pose
joint positions in metres) the first of them more than 3 cm from the hip joints' mid-point,
otherwise the first.

A user ``mapping`` (role -> joint name; an empty name: do not use the role) overrides the
detection role by role; names match exactly, else case-insensitively, else without namespace.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from solver.errors import InputError

__all__ = ["CENTRAL_WORDS", "REQUIRED", "ROLES", "SIDED_WORDS", "RoleError", "classify", "describe_names",
           "joint_roles", "missing_roles", "parse_joint_mapping", "spine_joints"]


class RoleError(InputError):
    """A joint mapping is malformed or names a role or joint that does not exist."""


#: per-side roles (``hip_r``, ``hip_l``, …) -> the words naming them (lower case, no separators)
SIDED_WORDS: Mapping[str, tuple[str, ...]] = {
    "hip": ("upleg", "hip", "thigh", "upperleg", "femur", "thighbend", "uprleg"),
    "knee": ("leg", "knee", "shin", "calf", "lowerleg", "tibia", "shank", "loleg", "lowleg", "shinbend"),
    "ankle": ("foot", "ankle"),
    "mtp": ("toebase", "toe", "toes", "ball", "toesbase"),
    "clavicle": ("shoulder", "collar", "clavicle", "clav"),
    "shoulder": ("arm", "uparm", "upperarm", "humerus", "shldr", "shldrbend"),
    "elbow": ("forearm", "elbow", "lowerarm", "radius", "forearmbend", "loarm"),
    "wrist": ("hand", "wrist"),
}
#: central roles -> their words (``spine`` marks spine joints; the role is ``lumbar``)
CENTRAL_WORDS: Mapping[str, tuple[str, ...]] = {
    "hips": ("hips", "hip", "pelvis"),
    "spine": ("spine", "chest", "upperchest", "back", "lowerback", "upperback", "torso", "abdomen",
              "abdomenlower", "abdomenupper", "chestlower", "chestupper", "thorax", "waist"),
    "neck": ("neck", "lowerneck", "upperneck", "necklower", "neckupper"),
    "head": ("head",),
}
#: every role, in the order the importer reports them
ROLES: tuple[str, ...] = ("hips", "lumbar", "neck", "head",
                          *(f"{r}_{s}" for r in SIDED_WORDS for s in "rl"))
#: the roles an import cannot do without (the toes may come from the ankle's End Site or child)
REQUIRED: tuple[str, ...] = ("hips", *(f"{r}_{s}" for s in "rl" for r in ("hip", "knee", "ankle")))
#: accepted spellings of roles in a mapping
_ALIASES = {**{f"toe_{s}": f"mtp_{s}" for s in "rl"}}

_WORD_ROLE = {w: r for r, ws in SIDED_WORDS.items() for w in ws}
_CENTRAL_ROLE = {w: r for r, ws in CENTRAL_WORDS.items() for w in ws}
_PREFIX = re.compile(r"^(?:bip\d*|character\d*|mixamorig\d*|def|cc_base)(?:[\s_.\-]+|(?=(?-i:[A-Z])))", re.I)
_SEP = r"[\s_.\-]+"


def _core(text: str) -> str:
    """Lower case, no separators, no trailing digits: ``spine_01`` -> ``spine``, ``Toe0`` -> ``toe``."""
    return re.sub(r"\d+$", "", re.sub(r"[\s_.\-]", "", text).lower())


def _strip(name: str) -> str:
    """The name without namespace, tool prefix and Blender duplicate suffix."""
    s = re.split(r"[:|]", name)[-1].strip()
    s = _PREFIX.sub("", s, count=1)
    return re.sub(r"\.\d{3}$", "", s)


def classify(name: str) -> tuple[str, str | None] | None:
    """(role word class, side ``"r"``/``"l"`` or None) of one joint name: ``("hip", "l")`` for
    ``thigh.L``, ``("spine", None)`` for ``Spine1``; None when no role has the name."""
    s = _strip(name)
    if not s:
        return None
    side_core = None
    for pat, flags in ((rf"(.+?){_SEP}(l|r|left|right)", re.I), (rf"(l|r|left|right){_SEP}(.+)", re.I),
                       (r"(left|right)(.+)", re.I), (r"(.+?)(left|right)", re.I), (r"([lLrR])([A-Z].*)", 0)):
        m = re.fullmatch(pat, s, flags)
        if m:
            a, b = m.group(1), m.group(2)
            side, core = (b, a) if a.lower() not in ("l", "r", "left", "right") else (a, b)
            side_core = (side[0].lower(), _core(core))
            break
    if side_core is None:
        m = re.fullmatch(r"([lr])(.+)", s, re.I)
        if m and _core(m.group(2)) in _WORD_ROLE:  # ASF: lfemur, rtibia
            side_core = (m.group(1).lower(), _core(m.group(2)))
    if side_core is not None and side_core[1] in _WORD_ROLE:
        return _WORD_ROLE[side_core[1]], side_core[0]
    core = _core(s)  # not a limb: a central joint (LOWERBACK), or none (LHipJoint, LeftHandIndex1)
    return (_CENTRAL_ROLE[core], None) if core in _CENTRAL_ROLE else None


def parse_joint_mapping(spec: str | Path | Mapping[str, str] | None) -> dict[str, str]:
    """A user mapping role -> joint name: a dict, ``"hip_l=Thigh_L,knee_l=Shin_L"``, or a file (JSON
    object, or one ``ROLE=NAME`` per line, ``#`` comments). Roles are checked (:data:`ROLES`,
    ``toe_r``/``toe_l`` for ``mtp_r``/``mtp_l``); an empty name means "do not use this role"."""
    if spec is None:
        return {}
    if isinstance(spec, Mapping):
        items = [(str(k), str(v) if v is not None else "") for k, v in spec.items()]
    else:
        text = str(spec)
        p = Path(text)
        if "=" not in text and p.suffix and not p.is_file():
            raise RoleError(f"joint mapping file not found: {p}")
        items = []
        if "=" not in text and p.is_file():
            body = p.read_text(errors="replace")
            try:
                d = json.loads(body)
            except json.JSONDecodeError:
                d = None
            if isinstance(d, dict):
                items = [(str(k), str(v)) for k, v in d.items()]
            else:
                for ln in (ln.split("#", 1)[0].strip() for ln in body.splitlines()):
                    if ln:
                        k, sep, v = ln.partition("=")
                        if not sep:
                            raise RoleError(f"joint mapping {p}: line {ln!r} is not ROLE=NAME")
                        items.append((k, v))
        else:
            for part in text.split(","):
                if not part.strip():
                    continue
                k, sep, v = part.partition("=")
                if not sep:
                    raise RoleError(f"joint mapping {part.strip()!r} is not ROLE=NAME "
                                    "(e.g. hip_l=Thigh_L,knee_l=Shin_L)")
                items.append((k, v))
    out: dict[str, str] = {}
    for k, v in items:
        key = k.strip().lower()
        key = _ALIASES.get(key, key)
        if key not in ROLES:
            raise RoleError(f"joint mapping: unknown role {k.strip()!r}; roles are {', '.join(ROLES)}")
        out[key] = v.strip()
    return out


def describe_names(names: Sequence[str], limit: int = 200) -> str:
    """The joint names, comma-separated, cut to about ``limit`` characters."""
    text = ", ".join(names)
    return text if len(text) <= limit else text[: limit - 1].rstrip(", ") + "…"


def _find(name: str, names: Sequence[str]) -> int:
    if name in names:
        return list(names).index(name)
    for key in (str.lower, lambda n: re.split(r"[:|]", n)[-1].lower()):
        hits = [j for j, n in enumerate(names) if key(n) == key(name)]
        if len(hits) == 1:
            return hits[0]
        if len(hits) > 1:
            raise RoleError(f"joint mapping: {name!r} matches several joints "
                            f"({', '.join(names[j] for j in hits)}); give the exact name")
    raise RoleError(f"joint mapping: no joint named {name!r} among: {describe_names(names)}")


def _ancestors(parents: Sequence[int], j: int) -> list[int]:
    """j's ancestors, nearest first (j excluded)."""
    out = []
    p = parents[j]
    while p >= 0:
        out.append(p)
        p = parents[p]
    return out


def _below(parents: Sequence[int], j: int, anc: int) -> bool:
    return anc in _ancestors(parents, j)


def _between(parents: Sequence[int], top: int, bottom: int) -> list[int] | None:
    """The joints strictly between ``top`` and its descendant ``bottom``, top to bottom (None when
    ``bottom`` is not below ``top``)."""
    up = _ancestors(parents, bottom)
    if top not in up:
        return None
    return up[: up.index(top)][::-1]


def _check_tree(names: Sequence[str], parents: Sequence[int]) -> None:
    if len(names) != len(parents):
        raise RoleError(f"{len(names)} joint names but {len(parents)} parents")
    for j, p in enumerate(parents):
        if not (-1 <= p < len(parents)) or p == j:
            raise RoleError(f"joint {names[j]!r} has an invalid parent index {p}")
    for j in range(len(parents)):
        seen = {j}
        p = parents[j]
        while p >= 0:
            if p in seen:
                raise RoleError(f"the joint hierarchy has a cycle through {names[j]!r}")
            seen.add(p)
            p = parents[p]


def joint_roles(names: Sequence[str], parents: Sequence[int], mapping: Mapping[str, str] | None = None, *,
                rest: np.ndarray | None = None) -> dict[str, int]:
    """Role -> joint index for a skeleton (names and parent indices, -1 for a root); the rules are
    in the module doc. ``mapping``: role -> joint name, overriding detection (parse a text with
    :func:`parse_joint_mapping`). ``rest``: (J, 3) rest-pose joint positions in metres (places
    ``lumbar`` 3 cm clear of the hips). Roles that cannot be found are absent
    (:func:`missing_roles` lists the required ones)."""
    names, parents = list(names), [int(p) for p in parents]
    _check_tree(names, parents)
    user: dict[str, int | None] = {}
    for role, name in parse_joint_mapping(mapping).items():
        user[role] = _find(name, names) if name else None
    depth = [len(_ancestors(parents, j)) for j in range(len(names))]
    order = sorted(range(len(names)), key=lambda j: (depth[j], j))  # shallow first
    cands: dict[str, list[int]] = {}
    for j in order:
        c = classify(names[j])
        if c is not None:
            cands.setdefault(c[0] if c[1] is None else f"{c[0]}_{c[1]}", []).append(j)

    roles: dict[str, int] = {}

    def pick(role: str, above: int | None) -> int | None:
        """The user's joint, else the first candidate below ``above`` (any, when ``above`` is None)."""
        if role in user:
            return user[role]
        return next((c for c in cands.get(role, []) if above is None or _below(parents, c, above)), None)

    for s in "rl":
        # legs: hip (preferring one with a knee below it), knee, ankle, toes
        if f"hip_{s}" in user:
            hip = user[f"hip_{s}"]
        else:
            hs = cands.get(f"hip_{s}", [])
            hip = next((h for h in hs if any(_below(parents, k, h) for k in cands.get(f"knee_{s}", []))),
                       hs[0] if hs else None)
        knee = pick(f"knee_{s}", hip)
        ankle = pick(f"ankle_{s}", knee if knee is not None else hip)
        if knee is None and hip is not None and ankle is not None and f"knee_{s}" not in user:
            mid = _between(parents, hip, ankle)
            knee = mid[0] if mid is not None and len(mid) == 1 else None
        mtp = pick(f"mtp_{s}", ankle) if ankle is not None or f"mtp_{s}" in user else None
        if mtp is None and ankle is not None and f"mtp_{s}" not in user:  # LeftAnkle -> LeftFoot: the foot is the toes
            mtp = next((c for c in cands.get(f"ankle_{s}", []) if _below(parents, c, ankle)), None)
        # arms: clavicle, shoulder, elbow, wrist
        clav = pick(f"clavicle_{s}", None)
        shoulder = pick(f"shoulder_{s}", clav)
        if (shoulder is None and clav is not None and f"shoulder_{s}" not in user and f"clavicle_{s}" not in user
                and pick(f"elbow_{s}", clav) is not None):  # RightShoulder -> RightElbow: no clavicle joint
            clav, shoulder = None, clav
        elbow = pick(f"elbow_{s}", shoulder)
        wrist = pick(f"wrist_{s}", elbow if elbow is not None else shoulder)
        if elbow is None and shoulder is not None and wrist is not None and f"elbow_{s}" not in user:
            mid = _between(parents, shoulder, wrist)
            elbow = mid[0] if mid is not None and len(mid) == 1 else None
        for role, joint in (("hip", hip), ("knee", knee), ("ankle", ankle), ("mtp", mtp), ("clavicle", clav),
                        ("shoulder", shoulder), ("elbow", elbow), ("wrist", wrist)):
            if joint is not None:
                roles[f"{role}_{s}"] = joint

    # hips: the deepest hips-named common ancestor of the hip joints, else their nearest common ancestor
    if "hips" in user:
        hips = user["hips"]
    elif "hip_r" in roles and "hip_l" in roles:
        common = [a for a in _ancestors(parents, roles["hip_r"]) if a in _ancestors(parents, roles["hip_l"])]
        named = [a for a in common if a in cands.get("hips", [])]
        hips = named[0] if named else (common[0] if common else None)
    else:
        hips = None
    if hips is None and "hips" not in user:
        hips = cands["hips"][0] if cands.get("hips") else parents.index(-1)
    if hips is not None:
        roles["hips"] = hips

    # head, neck (the neck above the head)
    head = pick("head", hips)
    if head is None and "head" not in user:
        head = pick("head", None)
    if "neck" in user:
        neck = user["neck"]
    else:
        neck = next((c for c in cands.get("neck", []) if head is None or _below(parents, head, c)), None)
    for role, joint in (("head", head), ("neck", neck)):
        if joint is not None:
            roles[role] = joint

    # lumbar: the first spine joint clear of the hips
    if "lumbar" in user:
        if user["lumbar"] is not None:
            roles["lumbar"] = user["lumbar"]
    else:
        chain = spine_joints(parents, roles, cands.get("spine", []))
        if rest is not None and chain and "hip_r" in roles and "hip_l" in roles:
            P = np.asarray(rest, dtype=float)
            mid = 0.5 * (P[roles["hip_r"]] + P[roles["hip_l"]])
            chain = [j for j in chain if np.linalg.norm(P[j] - mid) > 0.03]
        if chain:
            roles["lumbar"] = chain[0]
    return {r: roles[r] for r in ROLES if r in roles}


def spine_joints(parents: Sequence[int], roles: Mapping[str, int], named: Sequence[int] = ()) -> list[int]:
    """The spine chain: the joints from the hips (excluded) up to the neck, else the head
    (excluded), below the hips' and the top's nearest common ancestor; without a neck or head
    the ``named`` spine joints below the hips. Ordered hips -> head."""
    parents = [int(p) for p in parents]
    hips = roles.get("hips")
    top = roles.get("neck", roles.get("head"))
    if hips is None:
        return []
    if top is None:
        return [j for j in named if _below(parents, j, hips)]
    up = _ancestors(parents, top)
    hips_line = {hips, *_ancestors(parents, hips)}
    cut = next((i for i, a in enumerate(up) if a in hips_line), len(up))
    return up[:cut][::-1]


def missing_roles(roles: Mapping[str, int]) -> list[str]:
    """The required roles (:data:`REQUIRED`) absent from ``roles``."""
    return [r for r in REQUIRED if r not in roles]
