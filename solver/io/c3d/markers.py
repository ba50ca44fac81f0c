"""Marker sets: which label in the file plays which anatomical role.

Every landmark the reader builds comes from *roles* named as in Plug-in Gait (``ASI``,
``KNE``, ``HEE``, ..., sided with an ``L``/``R`` prefix; ``SACR``, ``C7``, ... central).
A label is matched to a role by its normalised form — upper case, subject prefix
(``Name:``) and separators (``_ . - space``) removed, the side as a prefix or suffix
(``L``, ``R``, ``LEFT``, ``RIGHT``) — against the names the supported marker sets use for
that role (:data:`ROLES`). The marker set itself is detected from the labels
(:data:`MARKER_SETS`, :func:`detect_marker_set`) and reported; a user mapping
(``mapping={"LASI": "my_label", ...}``, :func:`parse_mapping`) overrides the names.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from solver.io.c3d.reader import C3DError, _clean_label, _Raw


@dataclass(frozen=True)
class Role:
    """An anatomical role: its Plug-in-Gait-style name, whether it is sided, what it marks,
    and the names (normalised, without side) marker sets give it."""

    name: str
    sided: bool
    what: str
    names: tuple[str, ...]


_ROLE_LIST = (
    # pelvis
    Role("ASI", True, "anterior superior iliac spine", ("ASI", "ASIS", "IAS", "SIAS", "EIAS", "AS")),
    Role("PSI", True, "posterior superior iliac spine", ("PSI", "PSIS", "IPS", "SIPS", "EIPS", "PS")),
    Role("SACR", False, "sacrum (mid-PSIS)",
         ("SACR", "SACRUM", "SAC", "VSAC", "VSACR", "SACRAL", "S1", "S2", "MPSI", "MIPS", "MPSIS")),
    # thigh, shank
    Role("THI", True, "thigh wand (lateral thigh)", ("THI", "THL", "TH", "THIGH", "THIW")),
    Role("KNE", True, "lateral femoral epicondyle (knee)",
         ("KNE", "KNEE", "KNEL", "KNL", "LKNE", "LEK", "FLE", "LFE", "LFC", "LEPI", "KNEELAT", "LATKNEE",
          "KNEELATERAL", "LATEPI")),
    Role("KNM", True, "medial femoral epicondyle (knee)",
         ("KNM", "KNEM", "MKNE", "KNI", "MEK", "FME", "MFE", "MFC", "MEPI", "KNEEMED", "MEDKNEE", "KNEEMEDIAL",
          "MEDEPI", "KNEIN", "KNEEIN")),
    Role("TRO", True, "greater trochanter", ("TRO", "FTC", "GTR", "TROC", "GT", "TROCH")),
    Role("TIB", True, "tibia wand (lateral shank)", ("TIB", "TIBL", "TBL", "TI", "SHANK", "TIBW", "SHA")),
    Role("ANK", True, "lateral malleolus (ankle)",
         ("ANK", "ANKL", "LMAL", "LM", "FAL", "LMA", "LATMAL", "ANKLELAT", "ANKLAT", "MALL")),
    Role("MED", True, "medial malleolus (ankle)",
         ("MED", "MMAL", "MM", "TAM", "MMA", "MEDMAL", "ANKLEMED", "ANKMED", "ANM", "ANKM", "ANKIN", "ANKLEIN")),
    # foot
    Role("HEE", True, "calcaneus (heel)", ("HEE", "HEEL", "CAL", "FCC", "HEL", "CALC")),
    Role("TOE", True, "2nd metatarsal head (toe)", ("TOE", "MT2", "FM2", "SMH", "TOES", "MET2")),
    Role("MT1", True, "1st metatarsal head", ("MT1", "FM1", "MH1", "FMH", "MET1", "MTH1")),
    Role("MT5", True, "5th metatarsal head", ("MT5", "FM5", "MH5", "VMH", "MET5", "MTH5")),
    # trunk
    Role("C7", False, "7th cervical vertebra", ("C7", "CV7", "VC7")),
    Role("T10", False, "10th (or 8th) thoracic vertebra", ("T10", "TV10", "TH10", "T8", "TV8", "TH8")),
    Role("CLAV", False, "jugular notch (clavicles)", ("CLAV", "IJ", "SJN", "SNJ", "JN", "STER", "MAN", "SUP")),
    Role("STRN", False, "xiphoid process (sternum)", ("STRN", "PX", "SXS", "XIPH", "XP", "XYP")),
    # head
    Role("FHD", True, "front head", ("FHD", "HDF", "FH", "HEADF", "FHEAD")),
    Role("BHD", True, "back head", ("BHD", "HDB", "BH", "HEADB", "BHEAD")),
    # arms
    Role("SHO", True, "acromion (shoulder)", ("SHO", "ACR", "SAJ", "AC", "ACRO", "SAE", "SHOULDER", "CA")),
    Role("ELB", True, "lateral humeral epicondyle (elbow)", ("ELB", "LEL", "ELBL", "HLE", "LHE", "EL", "ELBOW")),
    Role("ELM", True, "medial humeral epicondyle (elbow)", ("ELM", "MEL", "ELBM", "HME", "MHE")),
    Role("WRA", True, "radial styloid (wrist, thumb side)", ("WRA", "RSP", "WRR", "RS", "RAD", "WRI")),
    Role("WRB", True, "ulnar styloid (wrist, little-finger side)", ("WRB", "USP", "WRU", "US", "UHE", "ULN")),
    Role("FIN", True, "2nd metacarpal head (hand)", ("FIN", "HM2", "MH2", "MC2", "MCP2", "HAND")),
    Role("FI5", True, "5th metacarpal head (hand)", ("HM5", "MC5", "MCP5")),
)
#: role name -> :class:`Role`
ROLES: dict[str, Role] = {r.name: r for r in _ROLE_LIST}

#: role -> the segment its marker sits on (sided roles: ``_r`` / ``_l`` appended); what the fit
#: registers each marker on (``solver.io.fit_quality``)
ROLE_SEGMENT: dict[str, str] = {
    "ASI": "pelvis", "PSI": "pelvis", "SACR": "pelvis",
    "THI": "thigh", "KNE": "thigh", "KNM": "thigh", "TRO": "thigh",
    "TIB": "shank", "ANK": "shank", "MED": "shank",
    "HEE": "foot", "TOE": "foot", "MT1": "foot", "MT5": "foot",
    "C7": "thorax", "T10": "thorax", "CLAV": "thorax", "STRN": "thorax",
    "FHD": "head", "BHD": "head", "SHO": "clavicle",
    "ELB": "upper_arm", "ELM": "upper_arm", "WRA": "forearm", "WRB": "forearm", "FIN": "hand", "FI5": "hand",
}

#: lateral role -> its medial partner: two markers of the file under one lateral label (a
#: four-character export: ``RKNE`` twice) are the pair, told apart by their distance from the
#: pelvis' mid-plane
MEDIAL_PARTNER = {"KNE": "KNM", "ANK": "MED", "ELB": "ELM"}
_CENTRAL_SEGMENTS = ("pelvis", "thorax", "head")


def role_segment(key: str) -> str:
    """The segment of a role key (``"LKNE"`` -> ``"thigh_l"``, ``"C7"`` -> ``"thorax"``)."""
    parsed = _parse_key(key)
    if parsed is None:
        raise C3DError(f"unknown role {key!r}")
    role, side = parsed
    base = ROLE_SEGMENT[role]
    return f"{base}_{side.lower()}" if side and base not in _CENTRAL_SEGMENTS else base

#: roles every trial needs (sided ones on both sides); TOE may be MT1 + MT5, PSI may be SACR
REQUIRED = ("ASI", "KNE", "ANK", "HEE")


@dataclass(frozen=True)
class MarkerSet:
    """A marker set the reader knows, by the labels it uses (normalised, ``{s}`` = L/R)."""

    name: str
    reference: str
    labels: tuple[str, ...]


def _sided(*names: str) -> tuple[str, ...]:
    return tuple(n.format(s=s) for n in names for s in "LR")


MARKER_SETS: tuple[MarkerSet, ...] = (
    MarkerSet("Plug-in Gait / Helen Hayes", "Davis et al. 1991; Kadaba et al. 1990 (Vicon Plug-in Gait)",
              _sided("{s}ASI", "{s}PSI", "{s}THI", "{s}KNE", "{s}TIB", "{s}ANK", "{s}HEE", "{s}TOE", "{s}FHD",
                     "{s}BHD", "{s}SHO", "{s}ELB", "{s}WRA", "{s}WRB", "{s}FIN") + ("SACR", "C7", "T10", "CLAV",
                                                                                    "STRN", "RBAK")),
    MarkerSet("CGM 2.x", "Leboeuf et al. 2019 (pyCGM2: Plug-in Gait + medial markers, clusters, foot)",
              _sided("{s}ASI", "{s}PSI", "{s}KNE", "{s}KNM", "{s}ANK", "{s}MED", "{s}HEE", "{s}TOE", "{s}THAP",
                     "{s}THAD", "{s}TIAP", "{s}TIAD", "{s}FMH", "{s}VMH", "{s}SMH", "{s}CUN", "{s}THLD", "{s}PAT",
                     "{s}TIBUP", "{s}TIBLO", "{s}D1M", "{s}D5M")),
    MarkerSet("IOR / ISB anatomical", "Cappozzo et al. 1995; Leardini et al. 2007 (ISB landmark names)",
              _sided("{s}IAS", "{s}IPS", "{s}FTC", "{s}FLE", "{s}FME", "{s}FAX", "{s}TTC", "{s}FAL", "{s}TAM",
                     "{s}FCC", "{s}FM1", "{s}FM2", "{s}FM5", "{s}HDF", "{s}HDB", "{s}SAJ", "{s}HLE", "{s}HME",
                     "{s}RSP", "{s}UHE", "{s}USP", "{s}HM2", "{s}HM5") + ("CV7", "TV8", "TV10", "SJN", "SNJ",
                                                                          "SXS", "PX")),
    MarkerSet("Clusters + anatomical (OpenSim / Stanford)",
              "thigh and shank clusters with femoral condyles and malleoli on both sides (opensim-core's "
              "walking C3D trials)",
              _sided("{s}ASI", "{s}PSI", "{s}LFC", "{s}MFC", "{s}LMAL", "{s}MMAL", "{s}CAL", "{s}MT1", "{s}MT2",
                     "{s}TH1", "{s}TH2", "{s}TH3", "{s}TB1", "{s}TB2", "{s}TB3", "{s}FHD", "{s}BHD")
              + ("C7", "T10", "CLAV", "STRN")),
    MarkerSet("Davis (BTS SMART / Elite)", "Davis et al. 1991 as BTS writes it: wands (bars), lateral markers, "
              "5th metatarsal head; no heel marker",
              _sided("{s}ASI", "{s}ASIS", "{s}THI", "{s}THIGH", "{s}BAR1", "{s}BAR2", "{s}KNE1", "{s}KNE2",
                     "{s}KNEE1", "{s}KNEE2", "{s}MALL", "{s}MET", "{s}SHOULD") + ("SACR", "SACRUM", "C7")),
)

_SEP = re.compile(r"[\s_.\-]+")
_CLUSTER = re.compile(r"^[LR](TH|THI|THIGH|SH|SK|SHK|SHANK|TB|TIB|LEG|FT|FOOT)(CL)?\d$")


def _norm(label: str) -> str:
    return _SEP.sub("", _clean_label(label))


def _readings(label: str) -> list[tuple[str | None, str]]:
    """The ways a label can be read: (side 'L'/'R', core) and (None, the whole name)."""
    up = _clean_label(label)
    n = _SEP.sub("", up)
    out: list[tuple[str | None, str]] = [(None, n)]
    for word, s in (("LEFT", "L"), ("RIGHT", "R")):
        if n.startswith(word) and len(n) > len(word):
            out.append((s, n[len(word):]))
        if n.endswith(word) and len(n) > len(word):
            out.append((s, n[: -len(word)]))
    m = re.match(r"^(.*?)[\s_.\-]+([LR])$", up)
    if m:
        out.append((m.group(2), _SEP.sub("", m.group(1))))
    if len(n) > 1 and n[0] in "LR":
        out.append((n[0], n[1:]))
    return out


def detect_marker_set(labels: Sequence[str]) -> dict:
    """The known marker set whose labels best match ``labels``: {"name", "reference",
    "matched" (labels of the set present), "of"}; name ``"unknown"`` below 6 matches, and
    ``"clusters"`` when technical clusters (e.g. ``LTH1..4``) outnumber every set."""
    present = {_norm(x) for x in labels}
    best: dict[str, Any] = {"name": "unknown", "reference": "", "matched": 0, "of": 0}
    for ms in MARKER_SETS:
        hit = len(present & set(ms.labels))
        if hit > best["matched"]:
            best = {"name": ms.name, "reference": ms.reference, "matched": hit, "of": len(ms.labels)}
    clusters = sum(1 for x in present if _CLUSTER.match(x))
    if clusters >= 6 and clusters > best["matched"]:
        return {"name": "clusters", "reference": "technical marker clusters (e.g. CAST, Cappozzo et al. 1995)",
                "matched": clusters, "of": clusters}
    if best["matched"] < 6:
        best["name"] = "unknown"
    return best


def role_key(role: str, side: str | None) -> str:
    return f"{side or ''}{role}"


def parse_mapping(spec: str | Path | Mapping[str, str] | None) -> dict[str, str]:
    """A user mapping role -> label: a dict, ``"LASI=L_IAS,RASI=R_IAS"``, or a file (JSON object,
    or one ``ROLE=label`` / ``ROLE: label`` per line, ``#`` comments). An empty label means
    "do not use this role"."""
    if spec is None:
        return {}
    if isinstance(spec, Mapping):
        items = list(spec.items())
    else:
        text = str(spec)
        p = Path(text)
        if "=" not in text and p.suffix and not p.is_file():
            raise C3DError(f"marker mapping file not found: {p}")
        if p.is_file():
            text = p.read_text()
            try:
                d = json.loads(text)
            except json.JSONDecodeError:
                d = None
            if isinstance(d, dict):
                items = list(d.items())
            else:
                lines = [ln.split("#", 1)[0].strip() for ln in text.splitlines()]
                items = []
                for ln in lines:
                    if not ln:
                        continue
                    k, sep, v = ln.replace(":", "=", 1).partition("=")
                    if not sep:
                        raise C3DError(f"marker mapping {p}: line {ln!r} is not ROLE=label")
                    items.append((k, v))
        else:
            items = []
            for part in text.split(","):
                if not part.strip():
                    continue
                k, sep, v = part.partition("=")
                if not sep:
                    raise C3DError(f"marker mapping {part!r} is not ROLE=label (e.g. LASI=L_IAS,RASI=R_IAS)")
                items.append((k, v))
    out: dict[str, str] = {}
    for k, v in items:
        key = str(k).strip().upper()
        if _parse_key(key) is None:
            raise C3DError(f"marker mapping: unknown role {k!r}; roles are Plug-in Gait names with a side prefix "
                           f"(e.g. LASI, RKNE) or central ({', '.join(r.name for r in _ROLE_LIST if not r.sided)})"
                           f"; sided roles: {', '.join(r.name for r in _ROLE_LIST if r.sided)}")
        out[key] = str(v).strip()
    return out


def _unique_labels(labels: Sequence[str]) -> tuple[str, ...]:
    """The labels, the second and later uses of one made ``LABEL#2``, ``LABEL#3``, ..."""
    seen: dict[str, int] = {}
    out = []
    for lbl in labels:
        n = seen.get(lbl, 0) + 1
        seen[lbl] = n
        out.append(lbl if n == 1 else f"{lbl}#{n}")
    return tuple(out)


def _parse_key(key: str) -> tuple[str, str | None] | None:
    if key in ROLES and not ROLES[key].sided:
        return key, None
    if len(key) > 1 and key[0] in "LR" and key[1:] in ROLES and ROLES[key[1:]].sided:
        return key[1:], key[0]
    return None


class _Markers:
    """Marker lookup by role; arrays (3, T) in the lab frame, metres."""

    def __init__(self, raw: _Raw, mapping: Mapping[str, str] | None = None) -> None:
        self.name = raw.path.name
        # a label the file uses twice or more: the later markers are LABEL#2, LABEL#3, ...
        self.labels = _unique_labels(raw.labels)
        self._index: dict[str, int] = {lbl: i for i, lbl in enumerate(self.labels)}
        self._pts = raw.points
        self.notes: list[str] = []
        self._auto: dict[tuple[str, str | None], str] = {}
        self._seen = {lbl: bool(np.isfinite(raw.points[:, i]).any()) for lbl, i in self._index.items()}
        self.marker_set = detect_marker_set(raw.labels)
        self.mapping: dict[tuple[str, str | None], str] = {}
        for key, lbl in (mapping or {}).items():
            role_side = _parse_key(key.upper())
            if role_side is None:
                raise C3DError(f"{self.name}: marker mapping: unknown role {key!r}")
            if lbl:
                lbl = _clean_label(lbl)
                if lbl not in self._index:
                    raise C3DError(f"{self.name}: marker mapping {key}={lbl}: no marker {lbl!r} in the file "
                                   f"(labels: {', '.join(self.labels)})")
            self.mapping[role_side] = lbl
        # label readings, once
        self._by_reading: dict[tuple[str | None, str], str] = {}
        for lbl in self.labels:
            for rd in _readings(lbl):
                self._by_reading.setdefault(rd, lbl)
        self._split_duplicates()

    def _split_duplicates(self) -> None:
        """Two markers under one lateral label (``RKNE`` and ``RKNE#2``: exports that cut labels
        to four characters write the medial marker under the lateral one's name) are the lateral
        and medial pair: the one nearer the pelvis' mid-plane (through mid-ASIS, normal along
        RASI -> LASI) is medial."""
        asis = [self.find("ASI", s) for s in ("R", "L")]
        if not all(asis):
            return
        ra, la = (self.get(a) for a in asis if a)
        normal = la - ra
        with np.errstate(invalid="ignore", divide="ignore"):  # frames where an ASIS is not seen: NaN
            normal = normal / np.linalg.norm(normal, axis=0)
        mid = 0.5 * (la + ra)
        for role, partner in MEDIAL_PARTNER.items():
            for side in ("R", "L"):
                if any(k in self.mapping for k in ((role, side), (partner, side))) or self.find(partner, side):
                    continue
                first = self.find(role, side)
                twin = f"{first}#2"
                if first is None or not self._seen.get(twin):
                    continue
                d = [float(np.nanmedian(np.abs(np.sum((self.get(x) - mid) * normal, axis=0))))
                     for x in (first, twin)]
                lateral, medial = (first, twin) if d[0] >= d[1] else (twin, first)
                self._auto[(role, side)], self._auto[(partner, side)] = lateral, medial
                self.notes.append(f"two markers labelled {first}: {lateral} ({max(d) * 1e3:.0f} mm from the pelvis' "
                                  f"mid-plane) taken as {side}{role}, {medial} ({min(d) * 1e3:.0f} mm) as "
                                  f"{side}{partner}")

    def find(self, role: str, side: str | None = None) -> str | None:
        side = side.upper() if side else None
        if (role, side) in self.mapping:
            lbl = self.mapping[(role, side)]
            return lbl if lbl and self._seen.get(lbl) else None
        if (role, side) in self._auto:
            return self._auto[(role, side)]
        r = ROLES[role]
        for core in r.names:
            found = self._by_reading.get((side if r.sided else None, core))
            if found is not None and self._seen.get(found) and found not in self.mapping.values():
                return found
        return None

    def get(self, label: str) -> np.ndarray:
        return self._pts[:, self._index[label]]

    def missing_message(self, missing: list[str]) -> str:
        """The error for missing required roles: what they mark, the names looked for, the labels
        in the file, the detected set and how to pass a mapping."""
        lines = []
        for key in missing:
            role = key[1:] if key[0] in "LR" and key[1:] in ROLES and ROLES[key[1:]].sided else key
            r = ROLES[role]
            side = key[0] if r.sided else ""
            names = ", ".join(f"{side}{n}" for n in r.names[:6])
            lines.append(f"{key} ({'left ' if side == 'L' else 'right ' if side == 'R' else ''}{r.what}; "
                         f"looked for {names}, ...)")
        ms = self.marker_set
        hint = ("technical clusters need the anatomical landmarks of a static calibration trial: add them to the "
                "trial or map them; " if ms["name"] == "clusters" else "")
        return (f"{self.name}: marker set {ms['name']!r}: required landmarks not found: " + "; ".join(lines)
                + f". Labels in the file: {', '.join(self.labels)}. {hint}Pass a mapping from Plug-in Gait roles "
                "to your labels: markers='LASI=<label>,RASI=<label>,...' (CLI: --markers LASI=...,RASI=... or "
                "--markers mapping.txt with one ROLE=label per line); supported marker sets and roles: docs/c3d.md")


def required_markers(mk: _Markers) -> list[str]:
    """Labels of the markers every frame needs (pelvis, knees, ankles, heels, toes); a
    :class:`C3DError` naming everything missing otherwise."""
    out: list[str] = []
    missing: list[str] = []
    for s in ("R", "L"):
        for role in REQUIRED:
            lbl = mk.find(role, s)
            (out.append(lbl) if lbl else missing.append(role_key(role, s)))
        toe = mk.find("TOE", s)
        if toe is None:
            mt = [mk.find("MT1", s), mk.find("MT5", s)]
            if all(mt):
                out += [m for m in mt if m]
            else:
                missing.append(role_key("TOE", s))
        else:
            out.append(toe)
    psi = [mk.find("PSI", s) for s in ("R", "L")]
    if all(psi):
        out += [p for p in psi if p]
    elif mk.find("SACR") is not None:
        out.append(mk.find("SACR"))  # type: ignore[arg-type]
    else:
        missing += [role_key("PSI", s) for s, p in zip("RL", psi) if p is None] + ["SACR"]
    if missing:
        raise C3DError(mk.missing_message(missing))
    return out
