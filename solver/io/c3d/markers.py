"""Marker names: roles and the labels other marker sets use for them."""

from __future__ import annotations

import numpy as np

from solver.io.c3d.reader import C3DError, _Raw

# ----------------------------------------------------------------------------------------
# marker access, gap filling


#: Landmark markers and the names other marker sets use for them ({s}: side letter L/R).
ALIASES: dict[str, tuple[str, ...]] = {
    "ASI": ("{s}ASI", "{s}ASIS", "{s}_ASIS", "{s}_ASI", "{s}IAS", "{s}.ASIS"),
    "PSI": ("{s}PSI", "{s}PSIS", "{s}_PSIS", "{s}_PSI", "{s}IPS", "{s}.PSIS"),
    "THI": ("{s}THI", "{s}_THI", "{s}THL", "{s}TH"),
    "KNE": ("{s}KNE", "{s}_KNE", "{s}KNEL", "{s}LKNE", "{s}LEK", "{s}FLE", "{s}_KNEE_LAT", "{s}LFC"),
    "KNM": ("{s}KNM", "{s}MKNE", "{s}KNEM", "{s}_KNM", "{s}MEK", "{s}FME", "{s}_KNEE_MED", "{s}MFC"),
    "TIB": ("{s}TIB", "{s}_TIB", "{s}TBL", "{s}TI"),
    "ANK": ("{s}ANK", "{s}_ANK", "{s}LMAL", "{s}LM", "{s}FAL", "{s}_ANKLE_LAT", "{s}LAT_MAL"),
    "MED": ("{s}MED", "{s}MMAL", "{s}MM", "{s}TAM", "{s}_ANKLE_MED", "{s}ANM", "{s}MED_MAL"),
    "HEE": ("{s}HEE", "{s}_HEE", "{s}HEEL", "{s}CAL", "{s}FCC", "{s}_HEEL"),
    "TOE": ("{s}TOE", "{s}_TOE", "{s}MT2", "{s}FM2", "{s}_TOE"),
    "MT1": ("{s}MT1", "{s}FM1", "{s}MH1"),
    "MT5": ("{s}MT5", "{s}FM5", "{s}MH5"),
    "SHO": ("{s}SHO", "{s}_SHO", "{s}ACR", "{s}SHOULDER", "{s}CA"),
    "ELB": ("{s}ELB", "{s}_ELB", "{s}LEL", "{s}ELBL", "{s}EL"),
    "WRA": ("{s}WRA", "{s}_WRA", "{s}RSP", "{s}WRR"),
    "WRB": ("{s}WRB", "{s}_WRB", "{s}USP", "{s}WRU"),
    "FIN": ("{s}FIN", "{s}_FIN", "{s}MH2", "{s}HAND"),
    "FHD": ("{s}FHD", "{s}_FHD", "{s}FH"),
    "BHD": ("{s}BHD", "{s}_BHD", "{s}BH"),
}
CENTRAL_ALIASES: dict[str, tuple[str, ...]] = {
    "SACR": ("SACR", "SACRUM", "S1", "MPSI"),
    "C7": ("C7", "CV7"),
    "T10": ("T10", "TV10", "T8"),
    "CLAV": ("CLAV", "IJ", "SJN", "STER", "MAN"),
    "STRN": ("STRN", "PX", "SXS", "XIPH"),
}


class _Markers:
    """Marker lookup by role, with aliases; arrays (3, T) in the lab frame, metres."""

    def __init__(self, raw: _Raw) -> None:
        self._index: dict[str, int] = {}
        for i, name in enumerate(raw.labels):
            self._index.setdefault(name, i)
        self._pts = raw.points
        self.used: dict[str, str] = {}  # role -> label found

    def find(self, role: str, side: str | None = None) -> str | None:
        if side is None:
            cands = CENTRAL_ALIASES.get(role, (role,))
        else:
            cands = tuple(a.format(s=side.upper()) for a in ALIASES[role])
        for c in cands:
            if c in self._index and np.isfinite(self._pts[:, self._index[c]]).any():
                return c
        return None

    def get(self, label: str) -> np.ndarray:
        return self._pts[:, self._index[label]]



def _alias_names(role: str, side: str | None) -> list[str]:
    if side is None:
        return list(CENTRAL_ALIASES.get(role, (role,)))
    return [a.format(s=side.upper()) for a in ALIASES[role]]



def _required_lower(mk: _Markers, name: str) -> list[str]:
    out = []
    for s in ("R", "L"):
        for role in ("ASI", "KNE", "ANK", "HEE"):
            lbl = mk.find(role, s)
            if lbl is None:
                raise C3DError(f"{name}: required marker {s}{role} not found (looked for "
                               f"{', '.join(_alias_names(role, s))})")
            out.append(lbl)
        toe = mk.find("TOE", s)
        if toe is None:
            mt = [mk.find("MT1", s), mk.find("MT5", s)]
            if not all(mt):
                raise C3DError(f"{name}: required marker {s}TOE not found (looked for "
                               f"{', '.join(_alias_names('TOE', s))}, or {s}MT1 and {s}MT5)")
            out += [m for m in mt if m]
        else:
            out.append(toe)
    psi = [mk.find("PSI", s) for s in ("R", "L")]
    if all(psi):
        out += [p for p in psi if p]
    elif mk.find("SACR") is not None:
        out.append(mk.find("SACR"))  # type: ignore[arg-type]
    else:
        raise C3DError(f"{name}: required markers RPSI and LPSI (or SACR) not found")
    return out


