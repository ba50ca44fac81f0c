"""OpenSim ground reactions: a GRF ``.mot`` and its ExternalLoads ``.xml``, per foot.

An ExternalLoads file lists ``ExternalForce`` objects, each naming the body it is applied
to and the columns of its force, point and torque. OpenSim applies every one of them to its
body, so a foot may receive several (an overground trial with plates left, right, left: two
forces on ``calcn_l``). :func:`grf_arrays` sums them per foot (side = the body's ``_r`` /
``_l`` suffix) into one equivalent wrench: the sum of the forces, applied at the combined
centre of pressure on the plates' surface, with the vertical free moment that keeps the
total moment:

    F = Σ F_i,  M = Σ (p_i × F_i + τ_i ŷ)                  (OpenSim ground, y up)
    h = Σ F_iy p_iy / Σ F_iy                                (the surface height)
    p = ((M_z + h F_x) / F_y,  h,  (h F_z − M_x) / F_y),    τ = M_y − (p_z F_x − p_x F_z)

over the plates carrying more than ``PLATE_ON_N`` (a plate's point is meaningless under no
load). With one loaded plate this is that plate's point and free moment exactly. As for a
single plate, the horizontal components of the torque columns are not used (the free
moment of a plate is vertical; they are logged when large).
"""

from __future__ import annotations

import logging
import re
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from solver.capture import GroundFrame, MeasuredGRF
from solver.gait import lowpass
from solver.io.opensim.base import C_OSIM, OpenSimError
from solver.io.opensim.storage import Storage, read_mot

log = logging.getLogger(__name__)

SIDES = ("right", "left")
#: a plate carrying less vertical force (N) than this does not place the combined point
PLATE_ON_N = 1.0


@dataclass(frozen=True)
class ForceSpec:
    """One ``ExternalForce``: the foot it loads and its column prefixes."""

    name: str
    side: str  # "right" | "left"
    force: str  # column prefix, e.g. "ground_force_v" -> ..._vx/_vy/_vz
    point: str
    torque: str  # "" when the force has no torque columns


def external_loads(xml: str | Path) -> list[ForceSpec]:
    """The applied ``ExternalForce`` objects of an ExternalLoads file (any number per foot)."""
    p = Path(xml)
    if not p.is_file():
        raise OpenSimError(f"ExternalLoads file not found: {p}")
    try:
        root = ET.parse(p).getroot()
    except ET.ParseError:
        raise OpenSimError(f"{p.name}: not valid XML") from None
    specs = []
    for k, ef in enumerate(root.iter("ExternalForce")):
        def txt(tag: str, default: str = "", ef=ef) -> str:
            el = ef.find(tag)
            return (el.text or "").strip() if el is not None and el.text else default

        if txt("appliesForce", "true").lower() == "false" or txt("isDisabled", "false").lower() == "true":
            continue
        name = ef.get("name") or f"ExternalForce #{k + 1}"
        body = txt("applied_to_body")
        m = re.search(r"_([rl])$", body)
        if not m:
            raise OpenSimError(f"{p}: ExternalForce {name!r} is applied to {body!r}; "
                               "cannot tell the side (expected a body name ending in _r or _l)")
        for tag in ("force_expressed_in_body", "point_expressed_in_body"):
            if txt(tag, "ground") != "ground":
                raise OpenSimError(f"{p}: ExternalForce {name!r}: {tag} = {txt(tag)!r}; "
                                   "only forces and points expressed in ground are supported")
        if not txt("force_identifier") or not txt("point_identifier"):
            raise OpenSimError(f"{p}: ExternalForce {name!r} lacks its force_identifier or point_identifier")
        specs.append(ForceSpec(name, "right" if m.group(1) == "r" else "left", txt("force_identifier"),
                               txt("point_identifier"), txt("torque_identifier")))
    if not specs:
        raise OpenSimError(f"{p}: no applied ExternalForce")
    return specs


def guess_force_specs(sto: Storage) -> list[ForceSpec]:
    """Column naming without an ExternalLoads file: ``ground_force_r_vx`` / ``ground_force_l_vx``."""
    specs = []
    for side, tag in (("right", "r"), ("left", "l")):
        f = next((lab[:-1] for lab in sto.labels if re.fullmatch(rf"(.*_)?force_{tag}_vx", lab)), None)
        if f is None:
            f = next((lab[:-1] for lab in sto.labels if re.fullmatch(rf"{tag}_(.*_)?force_vx", lab)), None)
        if f is None:
            raise OpenSimError(
                f"{sto.path}: cannot tell which columns belong to the {side} foot (expected e.g. "
                f"'ground_force_{tag}_vx'); pass the ExternalLoads .xml (grf_xml=...)"
            )
        p = f[:-1] + "p"
        t = f.replace("force", "torque")[:-2] if f.endswith("_v") else f.replace("force", "torque")
        specs.append(ForceSpec(f"{side} (column names)", side, f, p, t))
    return specs


def _columns(sto: Storage, prefix: str, suffixes: Sequence[str], what: str) -> np.ndarray:
    labs = [prefix + s for s in suffixes]
    missing = [lab for lab in labs if lab not in sto.labels]
    if missing:
        raise OpenSimError(f"{sto.path}: missing {what} columns {missing}")
    return np.stack([sto.column(lab) for lab in labs], axis=1)


def _torque(sto: Storage, s: ForceSpec) -> np.ndarray:
    if not s.torque:
        return np.zeros((len(sto.time), 3))
    for c in (s.torque + "_", s.torque):
        if all(c + a in sto.labels for a in "xyz"):
            return _columns(sto, c, ("x", "y", "z"), f"{s.name} torque")
    raise OpenSimError(f"{sto.path}: missing the torque columns {s.torque}_x/_y/_z of {s.name!r}")


def combine(F: np.ndarray, P: np.ndarray, TQ: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Several plates' (k, N, 3) forces, points, torques on one foot -> one wrench (N, 3) each
    (OpenSim ground, y up; see the module doc). One plate is returned as it is."""
    if F.shape[0] == 1:
        return F[0], P[0], TQ[0]
    fy = F[:, :, 1]
    on = fy > PLATE_ON_N
    w = np.where(on, fy, 0.0)
    wsum = w.sum(axis=0)
    any_on = wsum > 0
    safe = np.where(any_on, wsum, 1.0)
    Fl = np.where(on[:, :, None], F, 0.0).sum(axis=0)  # the loaded plates' force
    Pl = np.where(on[:, :, None], P, 0.0)
    tau = np.where(on, TQ[:, :, 1], 0.0)
    M = np.cross(Pl, np.where(on[:, :, None], F, 0.0)).sum(axis=0)
    M[:, 1] += tau.sum(axis=0)
    h = (w * P[:, :, 1]).sum(axis=0) / safe
    fyl = np.where(any_on, Fl[:, 1], 1.0)
    p = np.stack([(M[:, 2] + h * Fl[:, 0]) / fyl, h, (h * Fl[:, 2] - M[:, 0]) / fyl], axis=1)
    free = M[:, 1] - (p[:, 2] * Fl[:, 0] - p[:, 0] * Fl[:, 2])
    # no plate loaded: the most loaded plate's (meaningless) point, the sum of the free moments
    top = np.argmax(fy, axis=0)
    p = np.where(any_on[:, None], p, P[top, np.arange(P.shape[1])])
    free = np.where(any_on, free, TQ[:, :, 1].sum(axis=0))
    tq = np.zeros_like(p)
    tq[:, 1] = free
    return F.sum(axis=0), p, tq


def grf_arrays(mot: str | Path, xml: str | Path | None):
    """(storage, F, P, TQ): per foot (right, left) force, point and torque on the file's
    samples, (2, N, 3) in OpenSim ground, every ExternalForce of a foot summed (:func:`combine`)."""
    sto = read_mot(mot)
    specs = external_loads(xml) if xml is not None else guess_force_specs(sto)
    F, P, TQ = [], [], []
    N = len(sto.time)
    for side in SIDES:
        mine = [s for s in specs if s.side == side]
        if not mine:
            log.warning("%s: no external force on the %s foot: its ground reaction reads 0", xml or mot, side)
            F.append(np.zeros((N, 3)))
            P.append(np.full((N, 3), np.nan))
            TQ.append(np.zeros((N, 3)))
            continue
        f = np.stack([_columns(sto, s.force, ("x", "y", "z"), f"{s.name} force") for s in mine])
        p = np.stack([_columns(sto, s.point, ("x", "y", "z"), f"{s.name} point") for s in mine])
        tq = np.stack([_torque(sto, s) for s in mine])
        if len(mine) > 1:
            log.info("%s: %d external forces on the %s foot (%s): summed", xml or mot, len(mine), side,
                     ", ".join(s.name for s in mine))
        fs, ps, ts = combine(f, p, tq)
        F.append(fs)
        P.append(ps)
        TQ.append(ts)
    return sto, np.stack(F), np.stack(P), np.stack(TQ)


def floor_from_grf(mot: str | Path, xml: str | Path | None, threshold: float = 100.0) -> float | None:
    """Floor height in OpenSim ground = median COP height while a foot is loaded."""
    _, F, P, _ = grf_arrays(mot, xml)
    loaded = F[:, :, 1] > threshold
    if not np.any(loaded):
        return None
    return float(np.median(P[:, :, 1][loaded]))


def read_opensim_grf(
    mot: str | Path,
    xml: str | Path | None = None,
    *,
    times: np.ndarray,
    frame: GroundFrame | None = None,
    contacts: np.ndarray | None = None,
    threshold: float = 20.0,
) -> MeasuredGRF:
    """Measured ground reactions of an OpenSim GRF .mot, per foot, on ``times``, in OUR frame.

    Side assignment from the ExternalLoads ``xml`` (``applied_to_body`` ``*_r`` / ``*_l``),
    or without it from column names ``*_force_r_*`` / ``*_force_l_*``. Forces are low-passed
    (zero-phase Butterworth, 0.4 × the target rate) before being sampled at ``times`` when the
    file's rate is over 2.5 times higher; the centre of pressure is interpolated as is and is
    NaN where that foot's vertical force is below ``threshold`` N (it is meaningless there).
    ``free_moment`` is the vertical component of the torque columns.

    ``valid`` marks frames inside the GRF record where the measured reaction is complete:
    with ``contacts`` (4, T) (heel_r, toe_r, heel_l, toe_l, e.g. from kinematics), every foot
    in contact must carry more than ``threshold`` N; without it, every frame of the record is
    taken as complete (true for a treadmill or when every stance is on a plate).
    """
    frame = frame or GroundFrame(R=C_OSIM.T)
    times = np.asarray(times, dtype=float)
    if times.ndim != 1 or times.size == 0:
        raise OpenSimError("read_opensim_grf: times must be a non-empty 1-D array")
    sto, F, P, TQ = grf_arrays(mot, xml)
    t = sto.time
    inside = (times >= t[0] - 1e-9) & (times <= t[-1] + 1e-9)
    if not np.any(inside):
        raise OpenSimError(f"{mot}: GRF record {t[0]:.3f}-{t[-1]:.3f} s does not overlap the kinematics "
                           f"{times[0]:.3f}-{times[-1]:.3f} s")
    fs = 1.0 / float(np.median(np.diff(t)))
    fk = 1.0 / float(np.median(np.diff(times))) if times.size > 1 else fs
    Ff, TQf = F, TQ
    if fs > 2.5 * fk and len(t) > 30:
        cut = 0.4 * fk
        Ff = np.stack([lowpass(F[k].T, fs, cut).T for k in range(2)])
        TQf = np.stack([lowpass(TQ[k].T, fs, cut).T for k in range(2)])
    tc = np.clip(times, t[0], t[-1])

    def interp(a: np.ndarray) -> np.ndarray:  # (N, 3) -> (3, T)
        return np.stack([np.interp(tc, t, a[:, i]) for i in range(a.shape[1])])

    force = np.zeros((2, 3, times.size))
    cop = np.full((2, 3, times.size), np.nan)
    free = np.zeros((2, times.size))
    raw_fy = np.zeros((2, times.size))
    for k in range(2):
        f_os = interp(Ff[k])  # OpenSim axes
        force[k] = frame.vector_from_input(f_os.T).T
        raw_fy[k] = np.interp(tc, t, F[k][:, 1])
        p_os = interp(P[k])
        p = frame.point_from_input(p_os.T, times).T
        loaded = raw_fy[k] > threshold
        cop[k][:, loaded] = p[:, loaded]
        tq = frame.vector_from_input(interp(TQf[k]).T).T
        free[k] = tq[2]
    force[:, :, ~inside] = 0.0
    free[:, ~inside] = 0.0
    cop[:, :, ~inside] = np.nan
    valid = inside.copy()
    if contacts is not None:
        c = np.asarray(contacts, dtype=bool)
        if c.shape != (4, times.size):
            raise OpenSimError(f"contacts must be (4, T={times.size}), got {c.shape}")
        for k in range(2):
            on = c[2 * k] | c[2 * k + 1]
            valid &= ~on | (raw_fy[k] > threshold)
    horiz = float(np.max(np.abs(TQ[:, :, [0, 2]]))) if TQ.size else 0.0
    if horiz > 1.0:
        log.info("%s: torque columns have horizontal components up to %.1f N·m (kept: vertical free moment only)",
                 mot, horiz)
    return MeasuredGRF(force=force, cop=cop, free_moment=free, valid=valid,
                       source=f"opensim:{Path(mot).name}" + (f"+{Path(xml).name}" if xml else ""))

