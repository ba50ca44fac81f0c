"""A motion written on an OpenSim model: coordinates, ground reactions, ExternalLoads, the
model, an inverse-dynamics setup, checked by OpenSim's own tools.

A motion made from an OpenSim trial is written on the trial's own model (its context's
``rig``, see :mod:`solver.io.opensim.rig`, holds the model and the trial); a
motion of another source, with ``model="generic"``, on OpenSim's gait2354 model scaled to its
character (:func:`generic_rig`). The folder holds:

* ``<model>.osim``: the model (a 3.x-era file whose sockets name bodies as ``../body`` gets
  those paths rewritten to ``/bodyset/body``, nothing else changed; its ``<gravity>`` set to
  the motion's when that differs);
* ``coordinates.mot``: the model's coordinates (degrees and metres, ``inDegrees=yes``, the
  header of OpenSim's InverseKinematicsTool), ``CYCLES`` repetitions of the gait cycle sampled
  at ``RATE_HZ`` from the motion's own interpolation (the optimizer's C² spline);
* ``grf.mot``: per foot ``ground_force_{r,l}_v{x,y,z}`` (N), ``ground_force_{r,l}_p{x,y,z}``
  (centre of pressure on the floor, m) and ``ground_torque_{r,l}_{x,y,z}`` (the free moment
  about the floor's normal), in the model's ground frame (x forward, y up, z right);
* ``external_loads.xml``: the two forces applied to the model's feet (``calcn_r``, ``calcn_l``),
  force and point expressed in ground;
* ``setup_id.xml``: OpenSim's InverseDynamicsTool on these files over the middle cycle (the
  outer ones keep a filter's edges away from it), muscles excluded, the coordinates not
  filtered by default (``LOWPASS_HZ``: they sample a smooth motion; ``lowpass=6.0`` writes
  OpenSim's examples' 6 Hz);
* ``summary.json`` and ``README.md``: what was written, how, and the residuals OpenSim's
  InverseDynamicsTool reports on exactly these files.

**Coordinates.** The motion drives our segments; the model has its own bodies. At each
captured frame of the cycle the importer's OpenSim evaluation gives every body's pose, and
the capture skeleton's fit gives our segments' poses: the rigid map between a body and its
*anchor* segment (the segment it belongs to when the motion's character has it) is the
*calibration*, a smooth periodic function of the gait phase (:class:`Calibration`). It holds
what our character does not model (subtalar, knee translations, toes…) as the trial had it
at that phase. A motion time ``t`` is at phase ``φ = t / D`` (``D`` the motion's cycle) and
so at capture time ``t_start + φ · period`` (the motion's ``context.cycle``): each body is
placed at the motion's anchor pose composed with the calibration there. Bodies whose segment
the character merged (the torso and arms of a HalfBoy, lumped into its pelvis) stay rigid on
it, in the model's own posture at the cycle's mean coordinates; a torso shared by our
abdomen, thorax and head follows their mass-weighted mean pose. Four body-fixed virtual
markers per body (its centre of mass and 10 cm along each axis) follow those poses;
OpenSim's InverseKinematicsTool fits the model to them (``.trc`` and a copy of the model
carrying the markers in a scratch folder, not in the export) and Gauss–Newton iterations
finish its fit (:func:`_refine`).

**Ground reactions.** The motion's wrenches, linear between the frames and midpoints where
the optimizer's equations hold (frames 1…T−2; frame T−2 and the midpoint after it stand for
frame 0 and the midpoint of [0, 1], whose stored wrench is not constrained), are carried
to the model's ground frame (:func:`export_frame`: a slope's tilted gravity turned down,
a treadmill trial's belt velocity included) and written as force, centre of pressure on the
floor plane and free moment: the same wrench exactly (a foot loaded below 1 % of the body
weight keeps its last centre of pressure and takes the remainder as torque).

**Residual reduction** (``reduce_residuals=True``, the default). The model is not our
character: its joints differ (knee translations, oblique ankle axes), the merged bodies are
where the character held them only on average. OpenSim's InverseDynamicsTool is run on the
written files; its pelvis residuals ``r`` (generalised forces of the six ground-pelvis
coordinates) are the external wrench ``W`` the model still misses, ``r = G W`` where the
rows of ``G`` are the twists each pelvis coordinate imparts to the whole model (computed by
OpenSim at every row). That wrench is added to the feet in contact (in proportion to their
loads) and the ground-reaction file rewritten; the summary reports by how much the forces,
centres of pressure and free moments moved (and flags a large adjustment). Then the
InverseDynamicsTool is run again on the folder as written: those are the residuals reported.

OpenSim runs in a child process (CasADi and OpenSim cannot share one: see
:mod:`solver.io.opensim.worker`); :func:`child_main` is its entry point.
"""

from __future__ import annotations

import io
import json
import math
import os
import re
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from solver.capture import GroundFrame
from solver.character import Character
from solver.export import ExportError
from solver.kinematics import segment_frames
from solver.motion import Motion
from solver.trajectory import ROOT_XY, ROOT_YAW, cycle_turn, sample

#: sampling rate of the written files (Hz)
RATE_HZ = 100.0
#: gait cycles written (the inverse-dynamics setup analyses the middle one)
CYCLES = 3
#: low-pass cut-off of the written coordinates in the inverse-dynamics setup (Hz; None: no filter).
#: They are samples of a smooth motion, not measurements: a filter would take away part of the
#: motion the ground reactions balance (the optimizer's spline has content up to half its frame rate)
LOWPASS_HZ: float | None = None
#: OpenSim's examples' cut-off for measured coordinates: the trial's own check, and the written
#: files' figures reported under it for information
CAPTURE_LOWPASS_HZ = 6.0
#: a plate carrying less vertical force (N) than this is off in the trial's own check
PLATE_MIN_N = 20.0
#: the calibration's harmonics reach this frequency (Hz)
CALIBRATION_CUTOFF_HZ = 6.0
#: virtual markers: this far (m) from a body's centre of mass along each of its axes
MARKER_OFFSET_M = 0.1
#: a foot loaded less than this fraction of the body weight keeps its last centre of pressure
MIN_LOAD_FRACTION = 0.01
#: Hicks et al. 2015, "Is my model good enough?" (J Biomech Eng 137(2)), Table 2: peak
#: residual force ≤ 5 % of the peak net external force; peak residual moment ≤ 1 % of
#: (centre-of-mass height × peak net external force)
HICKS_FORCE_FRACTION = 0.05
HICKS_MOMENT_FRACTION = 0.01
CHILD_TIMEOUT_S = 600.0
#: bodies left without virtual markers: their pose follows from constraints (a patella's coupler)
UNMARKED_BODIES = re.compile(r"patella.*")

COORDINATES_FILE = "coordinates.mot"
GRF_FILE = "grf.mot"
EXTERNAL_LOADS_FILE = "external_loads.xml"
SETUP_FILE = "setup_id.xml"
ID_OUTPUT_FILE = "inverse_dynamics.sto"
SUMMARY_FILE = "summary.json"
README_FILE = "README.md"


class OpenSimExportError(ExportError):
    """A motion cannot be written on an OpenSim model; the message says why."""


# --- what the motion must carry ---------------------------------------------------------------


def exportable(motion: Motion) -> Motion:
    """``motion`` if the OpenSim export can write it (ground reactions, a gait cycle, the captured
    cycle it stands for); refused otherwise."""
    if not isinstance(motion, Motion):
        raise OpenSimExportError(f"expected a solver.motion.Motion, got {type(motion).__name__}")
    if motion.wrenches is None:
        raise OpenSimExportError("the motion has no ground reactions (contact wrenches): the OpenSim export "
                                 "writes them as the model's external loads; export a tutor or a λ optimum, "
                                 "not a capture")
    if not motion.cyclic:
        raise OpenSimExportError("the OpenSim export writes gait cycles: this motion is not a cycle "
                                 "(motion.cyclic is false)")
    cycle = motion.context.cycle
    if cycle is None or cycle.t_start is None or cycle.period_s is None:
        raise OpenSimExportError("the motion does not record the captured gait cycle it stands for "
                                 "(its context's cycle, source.cycle in the motion file, with t_start and period_s)")
    return motion


def _cycle(motion: Motion) -> tuple[float, float]:
    """(t_start, period_s) of the captured cycle an :func:`exportable` motion stands for."""
    cycle = motion.context.cycle
    assert cycle is not None and cycle.t_start is not None and cycle.period_s is not None  # exportable
    return cycle.t_start, cycle.period_s


def source_rig(motion: Motion) -> Mapping[str, Any]:
    """The OpenSim rig a motion carries (``motion.context.rig``), checked; refused otherwise."""
    exportable(motion)
    rig = motion.context.rig
    fmt = (motion.provenance.get("source") or {}).get("format")
    if not isinstance(rig, Mapping) or rig.get("format") != "opensim":
        have = f"its source is {fmt!r}" if fmt else "it records no source"
        raise OpenSimExportError(
            f"the OpenSim export writes a motion on the OpenSim model of the trial it was made from; this motion "
            f"carries no OpenSim model ({have}; its rig is "
            f"{'absent' if rig is None else repr(rig.get('format')) if isinstance(rig, Mapping) else 'not a mapping'})."
            " Make the tutor from an OpenSim trial (.osim + coordinates or markers), or pass model='generic' "
            "(motionx export --generic-model) to write it on the generic gait2354 model scaled to its character")
    missing = [k for k in ("model", "coordinates", "times", "fit", "bodies", "body_segments", "feet", "frame")
               if k not in rig]
    if missing:
        raise OpenSimExportError(f"the motion's OpenSim rig lacks {missing}")
    return rig


# --- sampling the motion ------------------------------------------------------------------------


def _rotz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def cycle_samples(motion: Motion, cycles: int, rate: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The motion repeated ``cycles`` times and sampled at ``rate``: times (S,) from 0, q (n, S)
    (the periodic spline; each repetition moved by the cycle's own turn and displacement),
    wrenches (2, 6, S) (linear between the frames and midpoints where the optimizer's
    equations hold, moved alike) and the cycle duration D (s)."""
    N = motion.T - 2  # frames T-2, T-1 repeat 0, 1
    D = N / motion.fps
    S = int(math.floor(cycles * D * rate + 1e-9)) + 1
    t = np.arange(S) / rate
    c = np.minimum(np.floor(t / D + 1e-12).astype(int), cycles - 1)
    tau = t - c * D
    q1 = sample(motion.q, motion.fps, tau, cyclic=True, interpolation=motion.interpolation)
    dpsi = cycle_turn(motion.q)
    R2 = _rotz(dpsi)[:2, :2]
    x0, xN = motion.q[list(ROOT_XY), 0], motion.q[list(ROOT_XY), N]
    b = xN - R2 @ x0  # xy_{k+N} = R xy_k + b
    # the wrenches where the optimizer's equations hold — frames 1..N and the midpoints between
    # them, frame N and the midpoint after it standing for frame 0 and the midpoint of [0, 1]
    # (carried back by the cycle's transform: frame 0's own wrench is not constrained) — and
    # linear between those samples
    W = np.asarray(motion.wrenches, dtype=float)
    R3, b3 = np.eye(3), np.array([b[0], b[1], 0.0])
    R3[:2, :2] = R2

    def back(w: np.ndarray) -> np.ndarray:  # a wrench of cycle 1 expressed in cycle 0
        F = R3.T @ w[:, 3:].T
        M = R3.T @ (w[:, :3].T - np.cross(b3, w[:, 3:]).T)
        return np.concatenate([M, F]).T

    half = np.empty((2, 6, 2 * N + 1))
    half[:, :, 2::2] = W[:, :, 1:N + 1]
    half[:, :, 3::2] = 0.5 * (W[:, :, 1:N] + W[:, :, 2:N + 1])
    half[:, :, 0] = back(W[:, :, N])
    half[:, :, 1] = back(0.5 * (W[:, :, N] + W[:, :, N + 1]))
    s2 = np.clip(2 * tau * motion.fps, 0.0, 2 * N)
    k = np.minimum(np.floor(s2).astype(int), 2 * N - 1)
    u = s2 - k
    w1 = half[:, :, k] * (1 - u) + half[:, :, k + 1] * u  # (2, 6, S)
    q = q1.copy()
    w = w1.copy()
    for j in range(S):
        Rk = np.eye(2)
        bk = np.zeros(2)
        for _ in range(int(c[j])):
            Rk, bk = R2 @ Rk, R2 @ bk + b
        if c[j]:
            q[list(ROOT_XY), j] = Rk @ q1[list(ROOT_XY), j] + bk
            q[ROOT_YAW, j] = q1[ROOT_YAW, j] + c[j] * dpsi
            R3 = np.eye(3)
            R3[:2, :2] = Rk
            b3 = np.array([bk[0], bk[1], 0.0])
            for f in range(2):
                F = R3 @ w1[f, 3:, j]
                w[f, 3:, j] = F
                w[f, :3, j] = R3 @ w1[f, :3, j] + np.cross(b3, F)
    return t, q, w, D


# --- calibration: the model's bodies against our segments at the captured frames ---------------


#: a torso body shared between our trunk segments (a model with arms), which it follows together
TRUNK_PARTS = ("abdomen", "thorax", "head")


def trunk_parts(rig: Mapping[str, Any], character: Character) -> tuple[str | None, list[tuple[str, float]]]:
    """The model body split between trunk segments the motion's character has (the torso of a
    model with arms, for a full-body character) and those segments with their masses; (None,
    []) when the character moves at most one of them."""
    body = next((b for b, sg in dict(rig["body_segments"]).items() if sg == "torso"), None)
    names = {sg.name: sg for sg in character.segments}
    parts = [(p, float(names[p].mass)) for p in TRUNK_PARTS if p in names]
    return (body, parts) if body is not None and len(parts) > 1 else (None, [])


def _own_segments(rig: Mapping[str, Any]) -> dict[str, str | None]:
    return {b: ("abdomen" if s == "torso" else s) for b, s in dict(rig["body_segments"]).items()}


def _anchors(rig: Mapping[str, Any], character: Character, parents: Mapping[str, str],
             override: Mapping[str, str] | None = None) -> dict[str, str]:
    """Each model body -> the segment of the motion's character it rides on (see the module doc);
    ``override``: body -> its own segment instead of the rig's."""
    segs = {s.name for s in character.segments}
    own = {**_own_segments(rig), **dict(override or {})}
    out: dict[str, str] = {}

    def anchor(b: str, seen: tuple[str, ...] = ()) -> str:
        if b in out:
            return out[b]
        s = own.get(b)
        if s in segs:
            return str(s)
        p = parents.get(b)
        if p is None or p == "ground" or p in seen:
            return character.segments[0].name
        return anchor(p, (*seen, b))

    for b in rig["bodies"]:
        out[b] = anchor(b)
    return out


def _fit_q(rig: Mapping[str, Any], character: Character) -> np.ndarray:
    names = list(rig["fit"]["names"])
    qf = np.asarray(rig["fit"]["q"], dtype=float)
    missing = [c for c in character.coordinate_names if c not in names]
    if missing:
        raise OpenSimExportError(f"the motion's character has coordinates the capture fit lacks: {missing}")
    return np.stack([qf[names.index(c)] for c in character.coordinate_names])


def _fourier(phase: np.ndarray, K: int) -> np.ndarray:
    """The periodic basis (len(phase), 2K+1): 1, cos 2πkφ, sin 2πkφ (k = 1..K)."""
    phase = np.asarray(phase, dtype=float)
    cols = [np.ones_like(phase)]
    for k in range(1, K + 1):
        cols += [np.cos(2 * np.pi * k * phase), np.sin(2 * np.pi * k * phase)]
    return np.stack(cols, axis=-1)


@dataclass(frozen=True, eq=False)
class Calibration:
    """Each model body relative to its anchor segment as a smooth periodic function of the gait
    phase: rotation ``mean[b] · exp(Σ rot[b, j] basis_j(φ))`` and origin ``Σ pos[b, j]
    basis_j(φ)`` (anchor frame, metres). A body riding on a segment that is not its own (the
    torso and arms of a HalfBoy, merged into its pelvis) has the constant term only: the
    posture the motion's character holds them in."""

    anchors: Mapping[str, str]
    mean: np.ndarray  # (B, 3, 3)
    rot: np.ndarray  # (B, 2K+1, 3) rotation-vector coefficients
    pos: np.ndarray  # (B, 2K+1, 3)
    harmonics: int
    fit_rms_deg: float  # how far the smooth calibration is from the per-frame one (rotation, RMS)
    fit_rms_mm: float
    right: np.ndarray  # (B, 3, 3) a merged body in its host body (identity for the others)
    offset: np.ndarray  # (B, 3) its origin in the host body (metres, host axes)

    def at(self, phase: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rotations (S, B, 3, 3) and origins (S, B, 3) at gait phases (S,)."""
        basis = _fourier(np.mod(phase, 1.0), self.harmonics)
        rv = np.einsum("sj,bjk->sbk", basis, self.rot)
        H = np.einsum("bij,sbjk->sbik", self.mean, Rotation.from_rotvec(rv.reshape(-1, 3)).as_matrix().reshape(
            rv.shape[:2] + (3, 3)))  # the host's (or the body's own) rotation in the anchor segment
        p = np.einsum("sj,bjk->sbk", basis, self.pos) + np.einsum("sbij,bj->sbi", H, self.offset)
        return H @ self.right, p


def calibration(rig: Mapping[str, Any], character: Character, evaluation: Mapping[str, Any],
                cycle: tuple[float, float], posture: tuple[np.ndarray, np.ndarray],
                cutoff_hz: float = CALIBRATION_CUTOFF_HZ, override: Mapping[str, str] | None = None
                ) -> Calibration:
    """The model's bodies against the motion's character at the captured cycle's frames (our
    world; ``evaluation``: OpenSim's body frames along the trial's coordinates,
    :func:`solver.io.opensim.worker.run_worker`; the capture skeleton's fit in the rig), as a
    periodic function of the phase with harmonics up to ``cutoff_hz`` (the capture's frame
    noise and the cycle's small non-closure do not reach the written motion).

    A body riding on a segment that is not its own (merged into it) is rigid on that segment:
    it is where the model puts it in ``posture`` (the body frames (B, 3, 3), (B, 3) in OpenSim
    ground at the cycle's mean coordinates) relative to the model body that is the segment's
    own (the pelvis), that host taken at its mean calibration — one pose of the model, so the
    model can take it, and the posture in which the character holds the merged segments."""
    bodies = list(evaluation["body_names"])
    if bodies != list(rig["bodies"]):
        raise OpenSimExportError("the motion's OpenSim model does not have the bodies its rig records")
    parents = dict(zip(evaluation["joint_child"], evaluation["joint_parent"]))
    anchors = _anchors(rig, character, parents, override)
    frame = GroundFrame.from_dict(rig["frame"])
    times = np.asarray(rig["times"], dtype=float)
    t_start, period = cycle
    inside = (times >= t_start - 1e-9) & (times < t_start + period - 1e-9)
    if inside.sum() < 8:
        raise OpenSimExportError(f"the captured cycle {t_start:.3f}+{period:.3f} s holds {int(inside.sum())} frames "
                                 "of the trial: too few to calibrate the model against")
    phase = (times[inside] - t_start) / period
    K = max(0, min(int(cutoff_hz * period), (int(inside.sum()) - 1) // 2 - 1))
    basis = _fourier(phase, K)
    Rb = np.asarray(evaluation["R"], dtype=float)[inside]  # (F, B, 3, 3) OpenSim ground
    Pb = np.asarray(evaluation["P"], dtype=float)[inside]
    W = np.einsum("ji,tbjk->tbik", frame.R, Rb)  # ours = R^T osim
    p = frame.point_from_input(Pb, times[inside][:, None])
    Rs, Ps = segment_frames(character, _fit_q(rig, character)[:, inside])  # (S, 3, 3, F), (S, 3, F)
    names = [s.name for s in character.segments]
    own = {**_own_segments(rig), **dict(override or {})}
    B = len(bodies)
    mean = np.empty((B, 3, 3))
    right = np.tile(np.eye(3), (B, 1, 1))  # body in its host body (merged bodies), identity otherwise
    offset = np.zeros((B, 3))
    rot = np.zeros((B, 2 * K + 1, 3))
    pos = np.zeros((B, 2 * K + 1, 3))
    err_r, err_p = [], []
    merged = [b for b in bodies if own.get(b) != anchors[b]]
    for i, b in enumerate(bodies):
        if b in merged:
            continue
        a = names.index(anchors[b])
        Ra = np.moveaxis(Rs[a], -1, 0)  # (F, 3, 3)
        C = np.einsum("tji,tjk->tik", Ra, W[:, i])
        d = np.einsum("tji,tj->ti", Ra, p[:, i] - Ps[a].T)
        m = Rotation.from_matrix(C).mean()
        rv = (m.inv() * Rotation.from_matrix(C)).as_rotvec()  # (F, 3)
        k = 0 if UNMARKED_BODIES.fullmatch(b) else K
        sub = basis[:, :2 * k + 1]
        rot[i, :2 * k + 1] = np.linalg.lstsq(sub, rv, rcond=None)[0]
        pos[i, :2 * k + 1] = np.linalg.lstsq(sub, d, rcond=None)[0]
        mean[i] = m.as_matrix()
        if k:
            err_r.append(rv - sub @ rot[i, :2 * k + 1])
            err_p.append(d - sub @ pos[i, :2 * k + 1])
    R_post, P_post = np.asarray(posture[0], dtype=float), np.asarray(posture[1], dtype=float)
    for b in merged:  # rigid on the anchor segment's own body, in the model's own posture
        i = bodies.index(b)
        host = next(h for h in bodies if own.get(h) == anchors[b] and h not in merged)
        j = bodies.index(host)
        rel_R = R_post[j].T @ R_post[i]  # body in host (OpenSim body axes: frame-independent)
        rel_p = R_post[j].T @ (P_post[i] - P_post[j])
        # the host's mean calibration (constant: rigid on the anchor segment, as the character holds it), then
        # the body where the model's posture puts it in the host
        mean[i] = mean[j]
        pos[i, 0] = pos[j, 0]
        right[i] = rel_R
        offset[i] = rel_p
    er = np.degrees(np.linalg.norm(np.concatenate(err_r), axis=1)) if err_r else np.zeros(1)
    ep = 1e3 * np.linalg.norm(np.concatenate(err_p), axis=1) if err_p else np.zeros(1)
    return Calibration(anchors, mean, rot, pos, K, float(np.sqrt(np.mean(er**2))), float(np.sqrt(np.mean(ep**2))),
                       right, offset)


def body_poses(motion: Motion, q: np.ndarray, t: np.ndarray, D: float, cal: Calibration,
               frame: GroundFrame | None = None,
               blend: Mapping[str, Sequence[tuple[Calibration, float]]] | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
    """The model's bodies (S, B, 3, 3), (S, B, 3) in OpenSim ground, placed on the motion's
    anchors ``q`` (n, S) at times ``t`` (s; ``D`` the motion's cycle) with the calibration at
    the same gait phase; ``frame``: the motion's world → OpenSim ground (default
    :func:`export_frame`). ``blend``: body -> (calibration, weight) pairs whose poses it takes
    the weighted mean of (a torso shared by our abdomen, thorax and head, weighed by mass)."""
    if blend:
        W, P = body_poses(motion, q, t, D, cal, frame)
        bodies = list(cal.anchors)
        for b, cals in blend.items():
            i = bodies.index(b)
            poses = [body_poses(motion, q, t, D, c, frame) for c, _ in cals]
            w = np.array([float(x) for _, x in cals])
            P[:, i] = np.einsum("k,kti->ti", w / w.sum(), np.stack([pp[1][:, i] for pp in poses]))
            for s_ in range(t.size):
                W[s_, i] = Rotation.from_matrix(np.stack([pp[0][s_, i] for pp in poses])).mean(weights=w).as_matrix()
        return W, P
    t_start = _cycle(motion)[0]
    C, d = cal.at(t / D)
    Rs, Ps = segment_frames(motion.character, q)
    names = [s.name for s in motion.character.segments]
    frame = export_frame(motion)[0] if frame is None else frame
    W = np.empty_like(C)
    P = np.empty_like(d)
    for i, b in enumerate(cal.anchors):
        a = names.index(cal.anchors[b])
        Ra = np.moveaxis(Rs[a], -1, 0)
        W[:, i] = np.einsum("ij,tjk->tik", frame.R, Ra @ C[:, i])
        P[:, i] = frame.point_to_input(Ps[a].T + np.einsum("tij,tj->ti", Ra, d[:, i]), t_start + t)
    return W, P


def virtual_markers(bodies: Sequence[str], body_com: np.ndarray, W: np.ndarray, P: np.ndarray
                    ) -> tuple[list[tuple[str, str, list[float]]], np.ndarray]:
    """Four markers per body (its centre of mass, and ``MARKER_OFFSET_M`` along each body axis):
    their definitions (name, body, position in the body) and trajectories (S, M, 3) in ground."""
    defs: list[tuple[str, str, list[float]]] = []
    traj = []
    for i, b in enumerate(bodies):
        if UNMARKED_BODIES.fullmatch(b):
            continue
        c = np.asarray(body_com[i], dtype=float)
        for tag, off in (("c", np.zeros(3)), ("x", np.eye(3)[0]), ("y", np.eye(3)[1]), ("z", np.eye(3)[2])):
            local = c + MARKER_OFFSET_M * off
            defs.append((f"{b}_{tag}", b, local.tolist()))
            traj.append(P[:, i] + np.einsum("tij,j->ti", W[:, i], local))
    return defs, np.stack(traj, axis=1)


# --- ground reactions in the model's frame -----------------------------------------------------


def wrenches_to_input(w: np.ndarray, t_abs: np.ndarray, frame: GroundFrame) -> np.ndarray:
    """Wrenches (2, 6, S) (moment about our origin; force) -> the input's ground frame, the moment
    about its origin (the frame's translation, belt motion included, carried along)."""
    M = np.moveaxis(w[:, :3], 1, -1)
    F = np.moveaxis(w[:, 3:], 1, -1)  # (2, S, 3)
    Fi = frame.vector_to_input(F)
    o = frame.point_to_input(np.zeros((t_abs.size, 3)), t_abs)  # our origin in the input frame
    Mi = frame.vector_to_input(M) + np.cross(o[None], Fi)
    return np.moveaxis(np.concatenate([Mi, Fi], axis=-1), -1, 1)


def grf_columns(w_in: np.ndarray, normal: np.ndarray, origin: np.ndarray, min_load: float) -> np.ndarray:
    """Per foot (2, S, 9): force, point on the ground plane, torque — OpenSim's ground-reaction
    columns — for wrenches ``w_in`` (2, 6, S) about OpenSim's ground origin; the ground is the
    plane through ``origin`` (S, 3) with unit ``normal`` (3,) (the level floor: y up).

    Loaded (force along the normal above ``min_load``): the point is the centre of pressure
    ``o + n × M_o / (n · F)`` (``M_o`` the moment about ``o``), the torque the free moment
    along the normal. Otherwise the foot's nearest loaded centre of pressure is kept and the
    torque is whatever keeps the wrench (zero for an unloaded foot)."""
    n = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    o = np.broadcast_to(np.asarray(origin, dtype=float), (w_in.shape[2], 3))
    out = np.zeros((2, w_in.shape[2], 9))
    for f in range(2):
        M, F = w_in[f, :3].T, w_in[f, 3:].T  # (S, 3)
        fn = F @ n
        loaded = fn > min_load
        Mo = M - np.cross(o, F)
        p = o + np.cross(n, Mo) / np.where(loaded, fn, 1.0)[:, None]
        p[~loaded] = np.nan
        if loaded.any():
            idx = np.where(loaded)[0]
            near = idx[np.abs(np.arange(F.shape[0])[:, None] - idx[None]).argmin(axis=1)]
            p[~loaded] = p[near[~loaded]]
        else:
            p[:] = o
        tq = M - np.cross(p, F)
        tq[loaded] = np.outer(tq[loaded] @ n, n)  # along the normal at the centre of pressure (rounding only)
        out[f] = np.concatenate([F, p, tq], axis=1)
    return out


def export_frame(motion: Motion) -> tuple[GroundFrame, np.ndarray]:
    """The map from the motion's world to the trial's ground for OpenSim, and the gravity there.

    The optimizer models a slope by tilting gravity over a level ground; OpenSim's gravity
    points down its y axis. The motion is first turned (about the origin, its ground and a
    treadmill's belt velocity with it) so that its gravity points down, then mapped by its
    ``GroundFrame``: the written ground is the inclined plane. Returns that frame and the
    gravity vector in OpenSim ground (the motion's own magnitude)."""

    frame = motion.frame
    g = np.asarray(motion.environment.gravity, dtype=float)
    gn = float(np.linalg.norm(g))
    down = np.array([0.0, 0.0, -1.0])
    u = g / gn if gn > 0 else down
    axis = np.cross(u, down)
    angle = math.atan2(float(np.linalg.norm(axis)), float(u @ down))
    Rg = Rotation.from_rotvec(axis / np.linalg.norm(axis) * angle).as_matrix() if angle > 1e-12 else np.eye(3)
    out = GroundFrame(R=frame.R @ Rg, offset=frame.offset, unit_m=frame.unit_m, velocity=frame.velocity,
                      axes=frame.axes)
    return out, out.R @ g


GRF_LABELS = tuple(f"ground_{kind}_{s}_{c}" for s in "rl" for kind, cs in (
    ("force", ("vx", "vy", "vz", "px", "py", "pz")), ("torque", ("x", "y", "z"))) for c in cs)


def _grf_table(cols: np.ndarray) -> np.ndarray:
    """(2, S, 9) -> (S, 18) in GRF_LABELS order."""
    return np.concatenate([cols[0], cols[1]], axis=1)


# --- writing OpenSim's text files ----------------------------------------------------------------


def write_mot(path: str | Path, name: str, labels: Sequence[str], times: np.ndarray, data: np.ndarray, *,
              in_degrees: bool, digits: int = 8) -> None:
    """An OpenSim storage file (version 1 header, tab-separated, ``time`` first)."""
    data = np.asarray(data, dtype=float)
    lines = [name, "version=1", f"nRows={data.shape[0]}", f"nColumns={len(labels) + 1}",
             f"inDegrees={'yes' if in_degrees else 'no'}", "endheader", "\t".join(["time", *labels])]
    fmt = f"%.{digits}f"
    for k in range(data.shape[0]):
        lines.append("\t".join([fmt % times[k], *(fmt % v for v in data[k])]))
    Path(path).write_text("\n".join(lines) + "\n")


def write_trc(path: str | Path, names: Sequence[str], times: np.ndarray, xyz: np.ndarray, rate: float) -> None:
    """Marker trajectories (S, M, 3), metres, as a ``.trc`` (OpenSim's MarkersReference reads it)."""
    S, M = xyz.shape[:2]
    head = [f"PathFileType\t4\t(X/Y/Z)\t{Path(path).name}",
            "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
            f"{rate:g}\t{rate:g}\t{S}\t{M}\tm\t{rate:g}\t1\t{S}",
            "\t".join(["Frame#", "Time", *(f"{n}\t\t" for n in names)]).rstrip("\t"),
            "\t".join(["", "", *(f"X{i + 1}\tY{i + 1}\tZ{i + 1}" for i in range(M))]), ""]
    rows = ["\t".join([str(k + 1), f"{times[k]:.8f}", *(f"{v:.8f}" for v in xyz[k].ravel())]) for k in range(S)]
    Path(path).write_text("\n".join(head + rows) + "\n")


def external_loads_xml(feet: Mapping[str, str], datafile: str,
                       columns: Sequence[tuple[str, str, str, str]] | None = None) -> str:
    """ExternalLoads for the two feet: by default columns ``ground_force_{r,l}_v/p`` and
    ``ground_torque_{r,l}_``; ``columns``: (side, force, point, torque) identifiers instead."""
    cols = columns or [(side, f"ground_force_{s}_v", f"ground_force_{s}_p", f"ground_torque_{s}_")
                       for side, s in (("right", "r"), ("left", "l"))]
    forces = []
    for k, (side, f_id, p_id, t_id) in enumerate(cols):
        forces.append(f"""			<ExternalForce name="{side}_foot_{k + 1}">
				<appliesForce>true</appliesForce>
				<applied_to_body>{feet[side]}</applied_to_body>
				<force_expressed_in_body>ground</force_expressed_in_body>
				<point_expressed_in_body>ground</point_expressed_in_body>
				<force_identifier>{f_id}</force_identifier>
				<point_identifier>{p_id}</point_identifier>
				<torque_identifier>{t_id}</torque_identifier>
			</ExternalForce>""")
    body = "\n".join(forces)
    return f"""<?xml version="1.0" encoding="UTF-8" ?>
<OpenSimDocument Version="40000">
	<ExternalLoads name="externalloads">
		<objects>
{body}
		</objects>
		<groups />
		<datafile>{datafile}</datafile>
	</ExternalLoads>
</OpenSimDocument>
"""


def id_setup_xml(model: str, coordinates: str, external_loads: str, t0: float, t1: float, *,
                 lowpass: float | None = LOWPASS_HZ, output: str = ID_OUTPUT_FILE, results: str = ".") -> str:
    """An InverseDynamicsTool setup (muscles excluded, coordinates low-passed at ``lowpass`` Hz,
    or not filtered: None)."""
    lowpass = -1.0 if lowpass is None else float(lowpass)
    return f"""<?xml version="1.0" encoding="UTF-8" ?>
<OpenSimDocument Version="40000">
	<InverseDynamicsTool name="inverse_dynamics">
		<results_directory>{results}</results_directory>
		<model_file>{model}</model_file>
		<time_range> {t0:.6f} {t1:.6f}</time_range>
		<forces_to_exclude> Muscles</forces_to_exclude>
		<external_loads_file>{external_loads}</external_loads_file>
		<coordinates_file>{coordinates}</coordinates_file>
		<lowpass_cutoff_frequency_for_coordinates>{lowpass:g}</lowpass_cutoff_frequency_for_coordinates>
		<output_gen_force_file>{output}</output_gen_force_file>
	</InverseDynamicsTool>
</OpenSimDocument>
"""


def with_gravity(text: bytes, gravity: np.ndarray) -> tuple[bytes, str | None]:
    """The model with its ``<gravity>`` set to ``gravity`` (OpenSim ground, m/s²) when it differs
    from the model's by more than 1e-6 m/s² (a motion in another gravity, e.g. a λ optimum on
    the gravity axis); returns the text and what was changed (None: unchanged)."""
    m = re.search(rb"<gravity>([^<]*)</gravity>", text)
    old = np.array([0.0, -9.80665, 0.0]) if m is None else np.array([float(v) for v in m.group(1).split()])
    g = np.asarray(gravity, dtype=float)
    if old.shape == (3,) and np.max(np.abs(old - g)) <= 1e-6:
        return text, None
    new = "<gravity>{:.9g} {:.9g} {:.9g}</gravity>".format(*g).encode()
    if m is None:
        raise OpenSimExportError("the motion's OpenSim model has no <gravity> element to set the motion's gravity in")
    changed = f"gravity {old.tolist()} -> {np.round(g, 6).tolist()} m/s² (the motion's environment)"
    return text[:m.start()] + new + text[m.end():], changed


def repaired_model_text(text: bytes) -> tuple[bytes, bool]:
    """A model whose socket paths name bodies as ``../body`` (3.x-era files that OpenSim 4
    cannot connect) with those paths rewritten to ``/bodyset/body`` (``/ground``); every other
    element kept (muscles, markers). Returns the text and whether anything changed."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as e:
        raise OpenSimExportError(f"the motion's OpenSim model is not valid XML ({e})") from None
    model = root.find("Model")
    if model is None:
        raise OpenSimExportError("the motion's OpenSim model has no <Model> element")
    bodies = {b.get("name") for b in model.iter("Body")}
    changed = False
    for el in model.iter():
        if el.tag.startswith("socket_") and el.text:
            m = re.fullmatch(r"(?:\.\./)+(\w+)", el.text.strip())
            if m and (m.group(1) == "ground" or m.group(1) in bodies):
                el.text = "/ground" if m.group(1) == "ground" else "/bodyset/" + m.group(1)
                changed = True
    if not changed:
        return text, False
    return b'<?xml version="1.0" encoding="UTF-8" ?>\n' + ET.tostring(root, encoding="utf-8"), True


# --- the child process ------------------------------------------------------------------------------


def run_child(job: Mapping[str, Any]) -> dict[str, Any]:
    """Run one OpenSim job (:func:`child_main`) in a child process; its JSON answer."""
    from solver.io.opensim.worker import readable  # the worker's message cleaning

    with tempfile.TemporaryDirectory(prefix="motionx-osim-export-") as d:
        out = os.path.join(d, "answer.json")
        root = str(Path(__file__).resolve().parents[2])
        env = dict(os.environ)
        env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        code = "from solver.export.opensim import child_main; child_main()"
        try:
            proc = subprocess.run([sys.executable, "-c", code], input=json.dumps({**job, "answer": out}), text=True,
                                  capture_output=True, env=env, timeout=CHILD_TIMEOUT_S, cwd=d)  # OpenSim's log there
        except subprocess.TimeoutExpired:
            raise OpenSimExportError(f"OpenSim's {job['job']} did not finish within {CHILD_TIMEOUT_S:.0f} s") from None
        if proc.returncode != 0:
            err = Path(out + ".err")
            msg = err.read_text() if err.exists() else (proc.stderr.strip().splitlines() or ["(no message)"])[-1]
            if "No module named 'opensim'" in proc.stderr:
                msg = "the 'opensim' package is not installed (pip install opensim)"
            raise OpenSimExportError(f"OpenSim's {job['job']} failed: {readable(msg)}")
        return dict(json.loads(Path(out).read_text()))


def child_main() -> None:  # pragma: no cover - runs in the child process (exercised by every export test)
    """Child entry: a JSON job on stdin (``ik``, ``id``, ``couple``, ``scale``, ``masses``), its answer as JSON."""
    import opensim as osim  # first heavy import of the process: OpenSim's casadi wins

    osim.Logger.setLevelString("error")
    osim.Logger.removeFileSink()  # no opensim.log in the working directory
    job = json.loads(sys.stdin.read())
    try:
        answer = {"ik": _child_ik, "id": _child_id, "couple": _child_couple, "scale": _child_scale,
                  "masses": _child_masses}[job["job"]](osim, job)
        Path(job["answer"]).write_text(json.dumps(answer))
    except Exception as e:
        Path(job["answer"] + ".err").write_text(str(e))
        sys.exit(3)


def _child_ik(osim, job):  # pragma: no cover - child
    """OpenSim's InverseKinematicsTool on virtual markers added to a scratch copy of the model,
    its solution refined to the optimum of the same weighted marker cost (:func:`_refine`), the
    coordinates file written with the tool's own header."""
    model = osim.Model(job["model"])
    for name, body, local in job["markers"]:
        model.addMarker(osim.Marker(name, model.getBodySet().get(body), osim.Vec3(*local)))
    cs = model.getCoordinateSet()
    for i in range(cs.getSize()):  # the motion's pose, even where it leaves a coordinate's range
        cs.get(i).set_clamped(False)
    model.finalizeConnections()
    scratch = job["scratch"]
    marked = os.path.join(scratch, "model_with_virtual_markers.osim")
    model.printToXML(marked)
    weights = {name: float(job["weights"].get(name, 1.0)) for name, _, _ in job["markers"]}
    tasks = osim.IKTaskSet()
    for name, w in weights.items():
        task = osim.IKMarkerTask()
        task.setName(name)
        task.setApply(True)
        task.setWeight(w)
        tasks.cloneAndAppend(task)
    tool = osim.InverseKinematicsTool()
    tool.set_model_file(marked)
    tool.setMarkerDataFileName(job["trc"])
    tool.set_IKTaskSet(tasks)
    tool.setStartTime(float(job["t0"]))
    tool.setEndTime(float(job["t1"]))
    tool.setOutputMotionFileName(os.path.join(scratch, "ik_tool.mot"))
    tool.setResultsDir(scratch)
    t = time.perf_counter()
    if not tool.run():
        raise RuntimeError("the InverseKinematicsTool did not run")
    tool_s = time.perf_counter() - t
    t = time.perf_counter()
    answer = _refine(osim, marked, os.path.join(scratch, "ik_tool.mot"), job["markers"], weights,
                     np.asarray(job["xyz"], dtype=float), job["out"])
    answer.update({"tool_s": tool_s, "refine_s": time.perf_counter() - t})
    return answer


def _couplers(osim, model, names):  # pragma: no cover - child
    """The model's enforced CoordinateCouplerConstraints: (dependent index, independent indices, function)."""
    out = []
    for i in range(model.getConstraintSet().getSize()):
        ccc = osim.CoordinateCouplerConstraint.safeDownCast(model.getConstraintSet().get(i))
        if ccc is not None and ccc.get_isEnforced():
            ind = ccc.getIndependentCoordinateNames()
            out.append((names.index(ccc.getDependentCoordinateName()),
                        [names.index(ind.get(k)) for k in range(ind.getSize())], ccc.getFunction()))
    return out


def _coupled(osim, couplers, q):  # pragma: no cover - child
    """``q`` (model order, radians/metres) with every coupled coordinate set by its coupler."""
    for d, ind, fn in couplers:
        v = osim.Vector(len(ind), 0.0)
        for k, j in enumerate(ind):
            v.set(k, float(q[j]))
        q[d] = fn.calcValue(v)
    return q


def _child_couple(osim, job):  # pragma: no cover - child
    """A coordinates file with every coupled coordinate set by its CoordinateCouplerConstraint
    (a file whose ``knee_angle_r_beta`` merely repeats ``knee_angle_r`` violates the constraint,
    and the inverse dynamics answers with the constraint's forces in the pelvis residuals)."""
    model = osim.Model(job["model"])
    state = model.initSystem()
    cs = model.getCoordinateSet()
    coords = [cs.get(i) for i in range(cs.getSize())]
    names = [c.getName() for c in coords]
    couplers = _couplers(osim, model, names)
    with open(job["coordinates"]) as f:
        lines = f.read().splitlines()
    end = next(i for i, ln in enumerate(lines) if ln.strip().lower() == "endheader")
    labels = lines[end + 1].split()
    rows = np.array([[float(x) for x in ln.split()] for ln in lines[end + 2:] if ln.strip()])
    deg = any(ln.replace(" ", "").lower() == "indegrees=yes" for ln in lines[:end])
    rot = [c.getMotionType() == osim.Coordinate.Rotational for c in coords]
    changed = []
    for d, ind, _ in couplers:
        if names[d] not in labels or any(names[j] not in labels for j in ind):
            continue
        changed.append(names[d])
        for r in rows:
            q = np.array([c.getDefaultValue() for c in coords])
            for j in [*ind, d]:
                v = r[labels.index(names[j])]
                q[j] = np.radians(v) if deg and rot[j] else v
            v = _coupled(osim, couplers, q)[d]
            r[labels.index(names[d])] = np.degrees(v) if deg and rot[d] else v
    del state
    body = ["\t".join(f"{v:.8f}" for v in row) for row in rows]
    with open(job["out"], "w") as f:
        f.write("\n".join(lines[:end + 2] + body) + "\n")
    return {"coupled": changed}


def _refine(osim, model_path, tool_mot, markers, weights, xyz, out):  # pragma: no cover - child
    """Gauss-Newton on the weighted marker cost from the InverseKinematicsTool's solution, frame by
    frame, OpenSim evaluating the model (its assembler stops up to ~2 mm short of the optimum even
    on markers the model can fit exactly, which shows as ±1° jitter in the coordinates). Coupled
    coordinates follow their CoordinateCouplerConstraint. No coordinate is clamped to its range
    (a clamp is a kink in the motion, i.e. an acceleration spike); those that leave it are
    reported (``outside_range``: the largest excursion, radians or metres)."""
    model = osim.Model(model_path)
    state = model.initSystem()
    cs = model.getCoordinateSet()
    coords = [cs.get(i) for i in range(cs.getSize())]
    names = [c.getName() for c in coords]
    couplers = _couplers(osim, model, names)
    dependent = {d for d, _, _ in couplers}
    free = [i for i, c in enumerate(coords) if not c.getLocked(state) and i not in dependent]
    lo = np.array([c.getRangeMin() for c in coords])
    hi = np.array([c.getRangeMax() for c in coords])
    bodies = [model.getBodySet().get(b) for b in dict.fromkeys(m[1] for m in markers)]
    bidx = {b.getName(): k for k, b in enumerate(bodies)}
    mb = np.array([bidx[m[1]] for m in markers])
    local = np.array([m[2] for m in markers], dtype=float)
    sw = np.sqrt(np.array([weights[m[0]] for m in markers]))[:, None]
    with open(tool_mot) as f:
        lines = f.read().splitlines()
    end = next(i for i, ln in enumerate(lines) if ln.strip().lower() == "endheader")
    labels = lines[end + 1].split("\t")
    rows = np.array([[float(x) for x in ln.split()] for ln in lines[end + 2:] if ln.strip()])
    deg = any(ln.strip().lower() == "indegrees=yes" for ln in lines[:end])
    col = [labels.index(n) for n in names]
    Q = rows[:, col].copy()
    rot = [c.getMotionType() == osim.Coordinate.Rotational for c in coords]
    if deg:
        Q[:, rot] = np.radians(Q[:, rot])

    def place(q):
        _coupled(osim, couplers, q)
        for i, c in enumerate(coords):
            c.setValue(state, float(q[i]), False)
        model.realizePosition(state)
        R = np.empty((len(bodies), 3, 3))
        P = np.empty((len(bodies), 3))
        for k, b in enumerate(bodies):
            tr = b.getTransformInGround(state)
            r = tr.R()
            R[k] = [[r.get(a, c) for c in range(3)] for a in range(3)]
            P[k] = tr.p().to_numpy()
        return P[mb] + np.einsum("mij,mj->mi", R[mb], local)

    h = 1e-7
    errs = np.empty((Q.shape[0], len(markers)))
    iterations, last_steps = [], []
    for k in range(Q.shape[0]):
        q = Q[k].copy()
        base = place(q.copy())
        n_it = 0
        size = np.inf
        for _ in range(4):  # Gauss-Newton, each Jacobian reused for a few steps (the start is close)
            J = np.empty((base.size, len(free)))
            for a, i in enumerate(free):
                qp = q.copy()
                qp[i] += h
                J[:, a] = (sw * (place(qp) - base)).ravel() / h
            pinv = np.linalg.pinv(J)
            done = False
            for _ in range(4):
                step = -pinv @ (sw * (base - xyz[k])).ravel()
                q[free] = q[free] + step
                base = place(q.copy())
                n_it += 1
                size = float(np.max(np.abs(step)))
                if size < 1e-9:
                    done = True
                    break
            if done:
                break
        iterations.append(n_it)
        last_steps.append(size)
        final = place(q)  # couplers applied
        Q[k] = [c.getValue(state) for c in coords]
        errs[k] = np.linalg.norm(final - xyz[k], axis=1)
    out_rows = rows.copy()
    vals = Q.copy()
    if deg:
        vals[:, rot] = np.degrees(vals[:, rot])
    out_rows[:, col] = vals
    body = ["\t".join(f"{v:16.8f}" for v in row) for row in out_rows]
    with open(out, "w") as f:
        f.write("\n".join(lines[:end + 2] + body) + "\n")
    below, above = np.maximum(lo - Q, 0.0), np.maximum(Q - hi, 0.0)
    outside = {names[i]: float(max(below[:, i].max(), above[:, i].max())) for i in range(len(names))
               if below[:, i].max() > 1e-9 or above[:, i].max() > 1e-9}
    return {"outside_range": outside, "refine_iterations_max": int(max(iterations)),
            "refine_last_step_max": float(max(last_steps)),
            "marker_rms_m": np.sqrt(np.mean(errs**2, axis=1)).tolist(), "marker_max_m": errs.max(axis=1).tolist(),
            "per_marker_rms_m": dict(zip((m[0] for m in markers), np.sqrt(np.mean(errs**2, axis=0)).tolist()))}


def _child_scale(osim, job):  # pragma: no cover - child
    """A model scaled body by body (OpenSim's ``Model.scale``: joint locations, muscle paths,
    masses and inertias; the mass distribution kept, the total set to ``mass``), printed to ``out``."""
    model = osim.Model(job["model"])
    state = model.initSystem()
    scales = osim.ScaleSet()
    for body, f in job["factors"].items():
        sc = osim.Scale()
        sc.setSegmentName(body)
        sc.setScaleFactors(osim.Vec3(*f))
        sc.setApply(True)
        scales.cloneAndAppend(sc)
    if not model.scale(state, scales, True, float(job["mass"])):
        raise RuntimeError("OpenSim could not scale the generic model")
    model.setName(job["name"])
    model.printToXML(job["out"])
    return {"mass": model.getTotalMass(model.initSystem())}


def _child_masses(osim, job):  # pragma: no cover - child
    """A model with its bodies' masses, centres of mass and inertias (body frame, about the
    centre of mass) set as given, printed to ``out``."""
    model = osim.Model(job["model"])
    for body, (m, c, inertia) in job["bodies"].items():
        b = model.getBodySet().get(body)
        b.setMass(float(m))
        b.setMassCenter(osim.Vec3(*c))
        i = np.asarray(inertia, dtype=float)
        b.setInertia(osim.Inertia(i[0, 0], i[1, 1], i[2, 2], i[0, 1], i[0, 2], i[1, 2]))
    model.finalizeConnections()
    model.printToXML(job["out"])
    return {"mass": model.getTotalMass(model.initSystem())}


def _labels(sto) -> list[str]:  # pragma: no cover - child
    a = sto.getColumnLabels()
    return [a.get(i) for i in range(a.getSize())]


def _coordinate_rows(osim, model, path):  # pragma: no cover - child
    """The rows of a coordinates file (radians, metres) in the model's coordinate order."""
    sto = osim.Storage(path)
    if sto.isInDegrees():
        model.getSimbodyEngine().convertDegreesToRadians(sto)
    labels = _labels(sto)
    cs = model.getCoordinateSet()
    coords = [cs.get(i) for i in range(cs.getSize())]
    times, rows = [], []
    for k in range(sto.getSize()):
        sv = sto.getStateVector(k)
        data = sv.getData()
        times.append(sv.getTime())
        rows.append({c.getName(): data.get(labels.index(c.getName()) - 1) for c in coords
                     if c.getName() in labels})
    return coords, times, rows


def _child_pelvis_twists(osim, model_path, coordinates):  # pragma: no cover - child
    """Per coordinates row: the twist (ω, v at ground's origin) each coordinate of the model's
    free root joint gives the whole model, and the whole-body centre of mass."""
    model = osim.Model(model_path)
    state = model.initSystem()
    root_joint = next(j for j in (model.getJointSet().get(i) for i in range(model.getJointSet().getSize()))
                      if j.getParentFrame().findBaseFrame().getName() == "ground")
    names = [root_joint.get_coordinates(i).getName() for i in range(root_joint.numCoordinates())]
    body = root_joint.getChildFrame().findBaseFrame()
    coords, times, rows = _coordinate_rows(osim, model, coordinates)
    by_name = {c.getName(): c for c in coords}
    h = 1e-6
    twists, com = [], []

    def pose():
        model.realizePosition(state)
        tr = body.getTransformInGround(state)
        R = np.array([[tr.R().get(i, j) for j in range(3)] for i in range(3)])
        return R, tr.p().to_numpy()

    for row in rows:
        for n, v in row.items():
            by_name[n].setValue(state, v, False)
        model.realizePosition(state)
        com.append(list(model.calcMassCenterPosition(state).to_numpy()))
        G = []
        for n in names:
            c = by_name[n]
            v0 = c.getValue(state)
            c.setValue(state, v0 + h, False)
            Rp, pp = pose()
            c.setValue(state, v0 - h, False)
            Rm, pm = pose()
            c.setValue(state, v0, False)
            Om = ((Rp - Rm) / (2 * h)) @ (0.5 * (Rp + Rm)).T
            w = np.array([Om[2, 1] - Om[1, 2], Om[0, 2] - Om[2, 0], Om[1, 0] - Om[0, 1]]) / 2
            v = (pp - pm) / (2 * h) - np.cross(w, 0.5 * (pp + pm))
            G.append([*w.tolist(), *v.tolist()])
        twists.append(G)
    return {"root_coordinates": names, "twist_times": times, "twists": twists, "com": com,
            "mass": model.getTotalMass(state)}


def _child_id(osim, job):  # pragma: no cover - child
    """OpenSim's InverseDynamicsTool from a setup file, run in its folder: the output table; with
    ``twists``, also :func:`_child_pelvis_twists` along the setup's coordinates."""
    setup = os.path.abspath(job["setup"])
    os.chdir(os.path.dirname(setup))
    tool = osim.InverseDynamicsTool(os.path.basename(setup))
    t = time.perf_counter()
    if not tool.run():
        raise RuntimeError("the InverseDynamicsTool did not run")
    elapsed = time.perf_counter() - t
    out = os.path.join(tool.getResultsDir(), tool.getOutputGenForceFileName())
    sto = osim.Storage(out)
    labels = _labels(sto)[1:]
    times, data = [], []
    for k in range(sto.getSize()):
        sv = sto.getStateVector(k)
        times.append(sv.getTime())
        data.append([sv.getData().get(i) for i in range(sv.getSize())])
    answer = {"labels": labels, "times": times, "data": data, "time_s": elapsed, "output": os.path.abspath(out)}
    if job.get("twists"):
        answer.update(_child_pelvis_twists(osim, tool.getModelFileName(), tool.getCoordinatesFileName()))
    return answer


# --- residuals ------------------------------------------------------------------------------------


def _setup_fields(setup: Path) -> dict[str, str]:
    root = ET.parse(setup).getroot()
    tool = root.find("InverseDynamicsTool")
    if tool is None:
        raise OpenSimExportError(f"{setup}: not an InverseDynamicsTool setup")
    return {el.tag: (el.text or "").strip() for el in tool}


def _grf_in_range(folder: Path, fields: Mapping[str, str], t0: float, t1: float) -> tuple[np.ndarray, np.ndarray]:
    """The ground reactions an ExternalLoads file applies (net force (S, 3) and the foot
    forces' rows) over [t0, t1]."""
    from solver.io.opensim.external_loads import external_loads
    from solver.io.opensim.storage import read_mot

    xml = folder / fields["external_loads_file"]
    specs = external_loads(xml)
    datafile = (ET.parse(xml).getroot().findtext(".//datafile") or "").strip()
    sto = read_mot(xml.parent / datafile)
    keep = (sto.time >= t0 - 1e-9) & (sto.time <= t1 + 1e-9)
    F = np.zeros((int(keep.sum()), 3))
    for s in specs:
        F += np.stack([sto.column(s.force + c)[keep] for c in "xyz"], axis=1)
    return sto.time[keep], F


def residual_figures(labels: Sequence[str], data: np.ndarray, root_coordinates: Sequence[str],
                     net_force: np.ndarray, com_height: float) -> dict[str, Any]:
    """Hicks et al. (2015) figures from an inverse-dynamics table: peak and RMS of every root
    coordinate's generalised force, against 5 % of the peak net external force (forces) and
    1 % of centre-of-mass height × that force (moments)."""
    peak_ext = float(np.max(np.linalg.norm(net_force, axis=1))) if net_force.size else 0.0
    f_lim = HICKS_FORCE_FRACTION * peak_ext
    m_lim = HICKS_MOMENT_FRACTION * com_height * peak_ext
    forces, moments = {}, {}
    fvec = []
    for c in root_coordinates:
        lab_f, lab_m = f"{c}_force", f"{c}_moment"
        if lab_f in labels:
            col = data[:, list(labels).index(lab_f)]
            forces[c] = {"peak_N": float(np.max(np.abs(col))), "rms_N": float(np.sqrt(np.mean(col**2)))}
            fvec.append(col)
        elif lab_m in labels:
            col = data[:, list(labels).index(lab_m)]
            moments[c] = {"peak_Nm": float(np.max(np.abs(col))), "rms_Nm": float(np.sqrt(np.mean(col**2)))}
    peak_f = max((v["peak_N"] for v in forces.values()), default=float("nan"))
    peak_fvec = float(np.max(np.linalg.norm(np.stack(fvec, axis=1), axis=1))) if fvec else float("nan")
    peak_m = max((v["peak_Nm"] for v in moments.values()), default=float("nan"))
    return {
        "forces": forces, "moments": moments,
        "peak_net_external_force_N": peak_ext, "com_height_m": com_height,
        "peak_residual_force_N": peak_f, "peak_residual_force_vector_N": peak_fvec,
        "peak_residual_moment_Nm": peak_m,
        "force_limit_N": f_lim, "moment_limit_Nm": m_lim,
        "force_percent_of_peak_external": 100.0 * peak_fvec / peak_ext if peak_ext else float("nan"),
        "moment_percent_of_com_height_x_peak_external": 100.0 * peak_m / (com_height * peak_ext)
        if peak_ext and com_height else float("nan"),
        "meets_hicks_2015": bool(peak_fvec <= f_lim and peak_m <= m_lim),
        "criteria": "Hicks et al. 2015 (J Biomech Eng 137(2):020905), Table 2: peak residual force <= 5 % of the "
                    "peak net external force (here the largest magnitude of the pelvis residual force vector); "
                    "peak residual moment <= 1 % of centre-of-mass height x peak net external force (each "
                    "rotational pelvis coordinate's generalised force)",
    }


def run_inverse_dynamics(folder: str | Path, setup: str = SETUP_FILE) -> dict[str, Any]:
    """OpenSim's InverseDynamicsTool on a folder's setup (child process): the generalised forces
    (``labels``, ``times``, ``data``), and at every row of the coordinates file the twists of the
    model's free root joint's coordinates (``twists`` (rows, 6, 6): ω, v at ground's origin),
    the whole-body centre of mass (``com``) and the model's mass."""
    setup_path = Path(folder).resolve() / setup
    if not setup_path.is_file():
        raise OpenSimExportError(f"no inverse-dynamics setup {setup_path}")
    ans = run_child({"job": "id", "setup": str(setup_path), "twists": True})
    ans["fields"] = _setup_fields(setup_path)
    return ans


def figures_of(folder: str | Path, ans: Mapping[str, Any]) -> dict[str, Any]:
    """:func:`residual_figures` of an inverse-dynamics run (:func:`run_inverse_dynamics`) on a
    folder: net external force from its ExternalLoads over the analysed rows, centre-of-mass
    height = its mean over those rows above the floor (the ground reactions' point height)."""
    folder = Path(folder).resolve()
    fields = ans["fields"]
    times = np.asarray(ans["times"], dtype=float)
    data = np.asarray(ans["data"], dtype=float)
    _, F = _grf_in_range(folder, fields, float(times[0]), float(times[-1]))
    tc = np.asarray(ans["twist_times"], dtype=float)
    keep = (tc >= times[0] - 1e-9) & (tc <= times[-1] + 1e-9)
    com_h = float(np.mean(np.asarray(ans["com"], dtype=float)[keep, 1]) - _floor_height(folder, fields))
    out = residual_figures(ans["labels"], data, ans["root_coordinates"], F, com_h)
    out.update({"time_range_s": [float(times[0]), float(times[-1])], "rows": int(times.size),
                "id_time_s": round(float(ans["time_s"]), 3), "model_mass_kg": float(ans["mass"]),
                "lowpass_hz": float(fields.get("lowpass_cutoff_frequency_for_coordinates") or -1)})
    return out


def opensim_residuals(folder: str | Path, setup: str = SETUP_FILE) -> dict[str, Any]:
    """OpenSim's InverseDynamicsTool run on a folder's setup as written (in a child process),
    and the residuals of the model's free root joint (the pelvis) against Hicks et al. (2015)
    (:func:`residual_figures`, :func:`figures_of`)."""
    return figures_of(folder, run_inverse_dynamics(folder, setup))


def _floor_height(folder: Path, fields: Mapping[str, str]) -> float:
    from solver.io.opensim.external_loads import external_loads
    from solver.io.opensim.storage import read_mot

    xml = folder / fields["external_loads_file"]
    specs = external_loads(xml)
    sto = read_mot(xml.parent / (ET.parse(xml).getroot().findtext(".//datafile") or "").strip())
    ys, ws = [], []
    for s in specs:
        fy = sto.column(s.force + "y")
        on = fy > 100.0
        ys.append(sto.column(s.point + "y")[on])
        ws.append(fy[on])
    y, w = np.concatenate(ys), np.concatenate(ws)
    return float(np.sum(y * w) / np.sum(w)) if w.size else 0.0


def capture_residuals(model: str | Path, coordinates: str | Path, grf: str | Path,
                      external_loads: str | Path | None = None, *, t0: float, t1: float,
                      lowpass: float = CAPTURE_LOWPASS_HZ, feet: Mapping[str, str] | None = None
                      ) -> dict[str, Any]:
    """The residuals of a trial's own inverse dynamics — its coordinates file and force plates on
    its model — by OpenSim's InverseDynamicsTool over [t0, t1] (s), coordinates low-passed at
    ``lowpass`` Hz as OpenSim's examples do (:func:`residual_figures`). Without an
    ExternalLoads file the GRF columns are told by their names (``ground_force_r_vx``…) and
    applied to ``feet`` (default ``calcn_r``, ``calcn_l``). The files are copied to a scratch
    folder (a 3.x model's socket paths repaired as for an export; coupled coordinates set by
    their CoordinateCouplerConstraint, :func:`_child_couple`); a plate carrying less than
    ``PLATE_MIN_N`` vertically is zeroed there (force, point, torque), as force-plate
    thresholds do: its centre of pressure is meaningless (33 km away in the loaded-walking
    trial's file) and would turn a few newtons of noise into kilonewton-metres."""
    from solver.io.opensim.base import OpenSimError
    from solver.io.opensim.external_loads import external_loads as read_loads
    from solver.io.opensim.external_loads import guess_force_specs
    from solver.io.opensim.storage import read_mot

    feet = dict(feet or {"right": "calcn_r", "left": "calcn_l"})
    try:
        sto = read_mot(grf)
        specs = read_loads(external_loads) if external_loads is not None else guess_force_specs(sto)
        cols = []
        for sp in specs:
            t_id = next((c for c in (sp.torque + "_", sp.torque) if sp.torque and all(
                c + a in sto.labels for a in "xyz")), "")
            cols.append((sp.side, sp.force, sp.point, t_id))
        with tempfile.TemporaryDirectory(prefix="motionx-osim-capture-") as d:
            folder = Path(d)
            text, _ = repaired_model_text(Path(model).read_bytes())
            (folder / "model.osim").write_bytes(text)
            coupled = run_child({"job": "couple", "model": str(folder / "model.osim"),
                                 "coordinates": str(Path(coordinates).resolve()),
                                 "out": str(folder / "coordinates.mot")})["coupled"]
            data = np.array(sto.data, copy=True)
            for _, f_id, p_id, t_id in cols:  # a plate under no load: its point is meaningless (far away)
                idx = [sto.labels.index(f_id + a) for a in "xyz"] + [sto.labels.index(p_id + a) for a in "xyz"]
                idx += [sto.labels.index(t_id + a) for a in "xyz"] if t_id else []
                off = sto.column(f_id + "y") < PLATE_MIN_N
                data[np.ix_(np.flatnonzero(off), np.asarray(idx, dtype=int))] = 0.0
            write_mot(folder / "grf.mot", "grf", sto.labels, sto.time, data, in_degrees=False)
            (folder / EXTERNAL_LOADS_FILE).write_text(external_loads_xml(feet, "grf.mot", cols))
            (folder / SETUP_FILE).write_text(id_setup_xml("model.osim", "coordinates.mot", EXTERNAL_LOADS_FILE,
                                                          t0, t1, lowpass=lowpass))
            out = opensim_residuals(folder)
            out["coupled_coordinates_recomputed"] = coupled
            out["plates_below_N_zeroed"] = PLATE_MIN_N
            return out
    except OpenSimError as e:
        raise OpenSimExportError(str(e)) from None


def _capture_reference(rig: Mapping[str, Any], model_path: Path, cycle: tuple[float, float],
                       rotational: Mapping[str, bool]) -> dict[str, Any]:
    """The trial's own residuals over the captured cycle where the plates are complete, when the
    trial's GRF file is still where it was imported from; otherwise why not (``rotational``:
    coordinate name -> whether OpenSim says it is a rotation)."""
    plates = rig.get("plates") or {}
    grf = plates.get("grf")
    if not grf or not Path(grf).is_file():
        return {"available": False, "why": "the trial's force-plate file is not available" if grf else
                "the trial has no force plates"}
    xml = plates.get("external_loads")
    if xml and not Path(xml).is_file():
        return {"available": False, "why": "the trial's ExternalLoads file is not available"}
    t0, t1 = cycle[0], cycle[0] + cycle[1]
    span = plates.get("complete_s")
    if span:
        t0, t1 = max(t0, float(span[0])), min(t1, float(span[1]))
    if t1 - t0 < 0.2:
        return {"available": False, "why": "the plates do not cover the captured cycle"}
    with tempfile.TemporaryDirectory(prefix="motionx-osim-capture-") as d:
        names = list(rig["coordinates"]["names"])
        values = np.asarray(rig["coordinates"]["values"], dtype=float).copy()
        rot = np.array([bool(rotational[n]) for n in names], dtype=bool)
        values[:, rot] = np.degrees(values[:, rot])
        mot = Path(d) / "capture_coordinates.mot"
        write_mot(mot, "Coordinates", names, np.asarray(rig["times"], dtype=float), values, in_degrees=True)
        out = capture_residuals(model_path, mot, grf, xml, t0=t0, t1=t1, feet=rig["feet"])
    out["available"] = True
    out["what"] = ("the trial's own coordinates and force plates on its model, OpenSim's InverseDynamicsTool, "
                   f"coordinates low-passed at {out['lowpass_hz']:g} Hz, over the captured cycle where every loaded "
                   "foot is on a plate")
    return out


#: the generic model for motions of other sources: the OpenSim gait2354 model as scaled for the
#: example subject01 (1.80 m, 72.6 kg; opensim-core, Apache-2.0; see models/README.md),
#: scaled again to the motion's character at export
GENERIC_MODEL = Path(__file__).with_name("models") / "gait2354_subject01.osim"
#: frames of the generic model's calibration "trial" (its default pose, repeated over the cycle)
_GENERIC_FRAMES = 10


def generic_rig(motion: Motion, scratch: str | Path) -> dict[str, Any]:
    """An OpenSim rig for a motion of another source (BVH, C3D, DeepMimic…): the generic model
    (:data:`GENERIC_MODEL`) scaled to the motion's character — pelvis by the hip width, each
    femur, tibia and foot by our thigh, shank and foot lengths, the torso by the legs' mean —
    and given the character's mass distribution (pelvis, thighs, shanks, feet, toes on the
    corresponding bodies, every other segment on the torso; a HalfBoy's pelvis carries its
    upper body, so its torso is left nearly massless); calibrated in the default
    standing pose (the model's coordinates at their defaults, ours at zero: both stand with the
    segments aligned), the model's hip mid-point on ours. The rig has the keys of an imported
    one (:mod:`solver.io.opensim.rig`); the motion is then written in OpenSim's own axes."""
    from solver.capture import GroundFrame as Frame
    from solver.io.opensim.base import C_OSIM
    from solver.io.opensim.model import _body_segments
    from solver.io.opensim.rig import pack_model
    from solver.io.opensim.worker import run_worker

    ch = motion.character
    names = [sg.name for sg in ch.segments]
    need = ["pelvis", "thigh_r", "thigh_l", "shank_r", "shank_l", "foot_r", "foot_l"]
    if [n for n in need if n not in names]:
        raise OpenSimExportError(f"the generic OpenSim model needs a character with a pelvis, thighs, shanks and feet; "
                                 f"{ch.name!r} has {names}")
    R0, P0 = segment_frames(ch, np.zeros(ch.n))
    ours = {n: P0[names.index(n)] for n in need}
    heel_toe = {side: ch.sole(side).length if ch.has_soles else None for side in ("right", "left")}
    # the generic model's own default geometry (OpenSim ground)
    base = run_worker(str(GENERIC_MODEL), ["pelvis_ty"], np.array([[0.0]]), False)
    jc = {c: np.asarray(base["JC"])[0, k] for k, c in enumerate(base["joint_child"])}
    bc = {b: np.asarray(base["body_com"])[k] for k, b in enumerate(base["body_names"])}
    Pm = {b: np.asarray(base["P"])[0, k] for k, b in enumerate(base["body_names"])}

    def ratio(a: float, b: float) -> float:
        return float(a / b) if b > 1e-6 else 1.0

    factors: dict[str, list[float]] = {}
    hip = ratio(float(np.linalg.norm(ours["thigh_r"] - ours["thigh_l"])),
                float(np.linalg.norm(jc["femur_r"] - jc["femur_l"])))
    factors["pelvis"] = [hip] * 3
    legs = []
    for s, side in (("r", "right"), ("l", "left")):
        thigh = ratio(float(np.linalg.norm(ours[f"shank_{s}"] - ours[f"thigh_{s}"])),
                      float(np.linalg.norm(jc[f"tibia_{s}"] - jc[f"femur_{s}"])))
        shank = ratio(float(np.linalg.norm(ours[f"foot_{s}"] - ours[f"shank_{s}"])),
                      float(np.linalg.norm(jc[f"talus_{s}"] - jc[f"tibia_{s}"])))
        tip = Pm[f"toes_{s}"] + np.array([2.0 * bc[f"toes_{s}"][0], 0.0, 0.0])
        length = heel_toe[side]
        foot = ratio(length, float(np.linalg.norm((tip - Pm[f"calcn_{s}"])[[0, 2]]))) if length else shank
        factors[f"femur_{s}"] = [thigh] * 3
        factors[f"tibia_{s}"] = [shank] * 3
        for b in (f"talus_{s}", f"calcn_{s}", f"toes_{s}"):
            factors[b] = [foot] * 3
        legs += [thigh, shank]
    factors["torso"] = [float(np.mean(legs))] * 3
    scaled = Path(scratch) / "generic_scaled.osim"
    run_child({"job": "scale", "model": str(GENERIC_MODEL), "factors": factors, "mass": ch.total_mass,
               "name": f"gait2354_scaled_{ch.name}".replace("-", "_"), "out": str(scaled)})
    res = run_worker(str(scaled), ["pelvis_ty"], np.array([[0.0]]), False)
    coords = list(res["coord_names"])
    default = np.array(res["coord_default"], dtype=float)
    default[coords.index("pelvis_ty")] = 0.0
    jc = {c: np.asarray(res["JC"])[0, k] for k, c in enumerate(res["joint_child"])}
    # the model's hip mid-point on ours (OpenSim ground = C_OSIM^T ours)
    target = C_OSIM.T @ (0.5 * (ours["thigh_r"] + ours["thigh_l"]))
    delta = target - 0.5 * (jc["femur_r"] + jc["femur_l"])
    for k, c in enumerate(("pelvis_tx", "pelvis_ty", "pelvis_tz")):
        default[coords.index(c)] += delta[k]
    seg_of, _, _ = _body_segments(res, str(scaled))
    # the character's mass distribution on the model's bodies (default pose, hip mid-points together):
    # pelvis <- our pelvis; femur, tibia, calcn, toes <- thigh, shank, foot, toes; torso <- every other
    # segment of ours (none for a HalfBoy, whose pelvis carries the upper body); talus (and an empty
    # torso) a negligible mass
    R_b = {b: C_OSIM @ np.asarray(res["R"])[0, k] for k, b in enumerate(res["body_names"])}
    p_b = {b: C_OSIM @ (np.asarray(res["P"])[0, k] + delta) for k, b in enumerate(res["body_names"])}
    groups: dict[str, list[str]] = {"pelvis": ["pelvis"], "torso": []}
    for s, _ in (("r", 0), ("l", 1)):
        groups.update({f"femur_{s}": [f"thigh_{s}"], f"tibia_{s}": [f"shank_{s}"], f"calcn_{s}": [f"foot_{s}"],
                       f"toes_{s}": [f"toes_{s}"] if f"toes_{s}" in names else [], f"talus_{s}": []})
    used = {x for v in groups.values() for x in v}
    groups["torso"] = [n for n in names if n not in used]
    eps = 1e-3
    props: dict[str, tuple[float, list[float], list[list[float]]]] = {}
    for body, segs in groups.items():
        if body not in R_b:
            continue
        m, mc = 0.0, np.zeros(3)
        parts = []
        for sname in segs:
            sg = ch.segments[names.index(sname)]
            i_s = names.index(sname)
            c_w = P0[i_s] + R0[i_s] @ np.asarray(sg.com)
            parts.append((sg.mass, c_w, R0[i_s] @ np.asarray(sg.inertia) @ R0[i_s].T))
            m += sg.mass
            mc += sg.mass * c_w
        if m <= eps:
            props[body] = (eps, [0.0, 0.0, 0.0], (1e-6 * np.eye(3)).tolist())
            continue
        com = mc / m
        inertia = sum(ii + mi * (float((c - com) @ (c - com)) * np.eye(3) - np.outer(c - com, c - com))
                      for mi, c, ii in parts)
        Rb = R_b[body]
        props[body] = (m, (Rb.T @ (com - p_b[body])).tolist(), (Rb.T @ inertia @ Rb).tolist())
    massed = Path(scratch) / "generic_massed.osim"
    run_child({"job": "masses", "model": str(scaled), "bodies": props, "out": str(massed)})
    scaled = massed
    t_start, period = _cycle(motion)
    times = t_start + period * np.arange(_GENERIC_FRAMES) / _GENERIC_FRAMES
    return {
        "format": "opensim",
        "generic": {"model": GENERIC_MODEL.name, "scale_factors": {b: round(f[0], 4) for b, f in factors.items()},
                    "mass_kg": ch.total_mass},
        "model": {"file": f"gait2354_scaled_{ch.name}.osim", "name": f"gait2354 scaled to {ch.name}",
                  "sha256": None, "osim_xz_b64": pack_model(scaled.read_bytes())},
        "model_coordinates": coords,
        "coordinates": {"names": coords, "values": np.tile(default, (_GENERIC_FRAMES, 1)).tolist()},
        "times": times.tolist(),
        "fit": {"names": list(ch.coordinate_names), "q": np.zeros((ch.n, _GENERIC_FRAMES)).tolist()},
        "bodies": list(res["body_names"]),
        "body_segments": dict(seg_of),
        "feet": {"right": "calcn_r", "left": "calcn_l"},
        "frame": Frame(R=C_OSIM.T, axes="OpenSim ground: x forward, y up, z right").to_dict(),
    }


# --- the export ---------------------------------------------------------------------------------------


def reduce_residuals_on_feet(w_in: np.ndarray, ans: Mapping[str, Any], t: np.ndarray, min_load: float
                             ) -> tuple[np.ndarray, np.ndarray]:
    """The feet's wrenches (2, 6, S) (OpenSim ground, moment about its origin) with the external
    wrench an inverse-dynamics run (:func:`run_inverse_dynamics`) still needed added, shared by
    the loaded feet in proportion to their vertical forces (see the module doc). Returns the
    new wrenches and the wrench added per row (S, 6) (zero where no row was analysed)."""
    labels = list(ans["labels"])
    roots = list(ans["root_coordinates"])
    cols = [labels.index(f"{c}_moment") if f"{c}_moment" in labels else labels.index(f"{c}_force") for c in roots]
    r = np.asarray(ans["data"], dtype=float)[:, cols]  # (rows, 6)
    t_id = np.asarray(ans["times"], dtype=float)
    tw_t = np.asarray(ans["twist_times"], dtype=float)
    G = np.asarray(ans["twists"], dtype=float)  # (rows, 6 coords, 6)
    out = np.array(w_in, copy=True)
    added = np.zeros((t.size, 6))
    for k, tk in enumerate(t_id):
        j = int(np.argmin(np.abs(t - tk)))
        g = int(np.argmin(np.abs(tw_t - tk)))
        if abs(t[j] - tk) > 1e-6 or abs(tw_t[g] - tk) > 1e-6:
            continue
        dW = np.linalg.solve(G[g], r[k])  # r = G W: the wrench (M about the origin, F) still missing
        fy = np.maximum(out[:, 4, j], 0.0)
        on = fy > min_load
        if not on.any():
            continue
        share = np.where(on, fy, 0.0) / fy[on].sum()
        out[:, :, j] += share[:, None] * dW[None, :]
        added[j] = dW
    return out, added


#: an adjustment moving a foot's centre of pressure further than this (mm) is flagged as large
LARGE_COP_SHIFT_MM = 50.0
#: half-width (m) of a foot's footprint around its heel-to-toe line
FOOT_HALF_WIDTH_M = 0.05


def footprints(bodies: Sequence[str], body_com: np.ndarray, W: np.ndarray, P: np.ndarray,
               feet: Mapping[str, str]) -> np.ndarray:
    """Per foot (right, left) and row, its heel-to-toe line on the floor (2, S, 2, 2): (x, z) of
    the foot body's origin (the heel of a gait model's calcn) and of the toe tip (the toes
    body's origin moved forward by twice its centre of mass, as the importer places it)."""
    out = np.empty((2, W.shape[0], 2, 2))
    for f, (side, s) in enumerate((("right", "r"), ("left", "l"))):
        heel = P[:, list(bodies).index(feet[side])]
        ti = list(bodies).index(f"toes_{s}") if f"toes_{s}" in bodies else list(bodies).index(feet[side])
        tip = P[:, ti] + 2.0 * np.einsum("tij,j->ti", W[:, ti], np.array([body_com[ti][0], 0.0, 0.0]))
        out[f, :, 0], out[f, :, 1] = heel[:, [0, 2]], tip[:, [0, 2]]
    return out


def cop_outside_feet(cols: np.ndarray, prints: np.ndarray, rows: np.ndarray, min_load: float) -> list[float]:
    """Per foot, how far (m) its centre of pressure leaves its footprint (the heel-to-toe line
    widened by ``FOOT_HALF_WIDTH_M``) at worst over ``rows`` where it is loaded."""
    out = []
    for f in range(2):
        loaded = rows & (cols[f, :, 1] > min_load)
        if not loaded.any():
            out.append(0.0)
            continue
        c = cols[f, loaded][:, [3, 5]]
        a, b = prints[f, loaded, 0], prints[f, loaded, 1]
        ab = b - a
        u = np.clip(np.einsum("ti,ti->t", c - a, ab) / np.maximum(np.einsum("ti,ti->t", ab, ab), 1e-9), 0.0, 1.0)
        d = np.linalg.norm(c - (a + u[:, None] * ab), axis=1)
        out.append(float(np.maximum(d - FOOT_HALF_WIDTH_M, 0.0).max()))
    return out


def _adjustment_figures(before: np.ndarray, after: np.ndarray, t: np.ndarray, window: tuple[float, float],
                        min_load: float) -> dict[str, Any]:
    """How much the ground reactions moved (per foot, over the analysed window): force change,
    centre-of-pressure shift on the floor while loaded, free-moment change."""
    keep = (t >= window[0] - 1e-9) & (t <= window[1] + 1e-9)
    out: dict[str, Any] = {}
    for f, side in enumerate(("right", "left")):
        b, a = before[f, keep], after[f, keep]
        dF = np.linalg.norm(a[:, :3] - b[:, :3], axis=1)
        loaded = (b[:, 1] > min_load) & (a[:, 1] > min_load)
        dp = np.linalg.norm(a[loaded, 3:6] - b[loaded, 3:6], axis=1)
        dm = np.abs(a[:, 7] - b[:, 7])
        out[side] = {"force_change_N": {"max": float(dF.max(initial=0.0)), "rms": float(np.sqrt(np.mean(dF**2)))},
                     "cop_shift_mm": {"max": 1e3 * float(dp.max(initial=0.0)),
                                      "rms": 1e3 * float(np.sqrt(np.mean(dp**2))) if dp.size else 0.0},
                     "free_moment_change_Nm": {"max": float(dm.max(initial=0.0))},
                     "free_moment_Nm": {"max_before": float(np.abs(b[:, 7]).max(initial=0.0)),
                                        "max_after": float(np.abs(a[:, 7]).max(initial=0.0))}}
    return out


def _calibrated(motion: Motion, rig: Mapping[str, Any], model_path: Path
                ) -> tuple[dict[str, Any], tuple[np.ndarray, np.ndarray], Calibration, Any]:
    """OpenSim's evaluation of the model along the captured trial (``model_path``: the model as
    written), its posture at the cycle's mean coordinates, the calibration of its bodies against
    the motion's character and the trunk's blend (:func:`calibration`, :func:`trunk_parts`)."""
    from solver.io.opensim.worker import run_worker

    names = list(rig["coordinates"]["names"])
    values = np.asarray(rig["coordinates"]["values"], dtype=float)
    t_start, period = _cycle(motion)
    times = np.asarray(rig["times"], dtype=float)
    in_cycle = (times >= t_start - 1e-9) & (times < t_start + period)
    mean_row = values[in_cycle].mean(axis=0) if in_cycle.any() else values.mean(axis=0)
    ev = run_worker(str(model_path), names, np.vstack([values, mean_row]), False)
    posture = (np.asarray(ev["R"])[-1], np.asarray(ev["P"])[-1])
    ev = {**ev, "R": np.asarray(ev["R"])[:-1], "P": np.asarray(ev["P"])[:-1]}
    cyc = (t_start, period)
    cal = calibration(rig, motion.character, ev, cyc, posture)
    torso, parts = trunk_parts(rig, motion.character)
    blend = None
    if torso is not None:
        blend = {torso: [(cal if k == 0 else calibration(rig, motion.character, ev, cyc, posture,
                                                          override={torso: seg}), m)
                         for k, (seg, m) in enumerate(parts)]}
    return ev, posture, cal, blend


def model_bodies(motion: Motion, rate: float = 30.0) -> dict[str, Any]:
    """The motion on its OpenSim trial's model, for a look at it (the web page's preview): one
    gait cycle at ``rate`` of every body's frame in the model's ground (where gravity points down),
    placed as :func:`write_opensim` places them for OpenSim's inverse kinematics (no IK run); a
    capture (no cycle, no ground reactions): the trial itself, the model along its own coordinates. Keys:
    ``bodies``, ``parents`` (body -> parent body, ``ground`` for the root), ``times``, ``R`` (S, B,
    3, 3), ``P`` (S, B, 3), ``posture`` (R, P at the cycle's mean coordinates), ``com`` (B, 3:
    each body's centre of mass in its frame) and ``frame`` (the ground frame without the slope's
    turn: the model's ground in the world where gravity points down)."""
    from solver.io.opensim.base import OpenSimError
    from solver.io.opensim.rig import unpack_model
    from solver.io.opensim.worker import run_worker

    rig = motion.context.rig
    trial = not (motion.cyclic and motion.wrenches is not None)  # a capture: the trial as the model moved
    if trial:
        if not isinstance(rig, Mapping) or rig.get("format") != "opensim":
            raise OpenSimExportError("the motion was not made from an OpenSim trial: it has no OpenSim model")
    else:
        rig = source_rig(motion)
    text, _ = repaired_model_text(unpack_model(rig["model"]["osim_xz_b64"]))
    frame, gravity = export_frame(motion)
    text, _ = with_gravity(text, gravity)
    try:
        with tempfile.TemporaryDirectory(prefix="motionx-osim-bodies-") as scratch:
            path = Path(scratch) / "model.osim"
            path.write_bytes(text)
            if trial:
                times = np.asarray(rig["times"], dtype=float)
                ev = run_worker(str(path), list(rig["coordinates"]["names"]),
                                np.asarray(rig["coordinates"]["values"], dtype=float), False)
            else:
                ev, posture, cal, blend = _calibrated(motion, rig, path)
    except OpenSimError as e:
        raise OpenSimExportError(str(e)) from None
    if trial:
        t_abs = times
        t = times - times[0]
        W, P = np.asarray(ev["R"], dtype=float), np.asarray(ev["P"], dtype=float)
        posture = (W[0], P[0])
    else:
        t, q, _, D = cycle_samples(motion, 1, float(rate))
        t_abs = _cycle(motion)[0] + t
        W, P = body_poses(motion, q, t, D, cal, frame, blend)
    # a treadmill trial's model walks on its belt: moved on with it, it walks along its ground
    P = P + (frame.R @ frame.velocity / frame.unit_m)[None, None, :] * t_abs[:, None, None]
    return {"bodies": list(rig["bodies"]), "parents": dict(zip(ev["joint_child"], ev["joint_parent"])),
            "times": t, "R": W, "P": P, "posture": posture, "com": np.asarray(ev["body_com"], dtype=float),
            "frame": motion.frame}


def write_opensim(motion: Motion, folder: str | Path, *, cycles: int = CYCLES, rate: float = RATE_HZ,
                  lowpass: float | None = LOWPASS_HZ, reduce_residuals: bool = True,
                  model: str = "source") -> dict[str, Any]:
    """Write ``motion`` on its source OpenSim model into ``folder`` (created; see the module doc
    for every file) and return the summary (also ``summary.json``): files, sampling, the
    inverse-kinematics fit, the residuals of OpenSim's InverseDynamicsTool on the files as
    written (and, with ``reduce_residuals``, before the ground reactions were adjusted, with
    the adjustment's size)."""
    from solver.io.opensim.base import OpenSimError
    from solver.io.opensim.rig import unpack_model

    t_begin = time.perf_counter()
    if model not in ("source", "generic"):
        raise OpenSimExportError(f"model must be 'source' (the trial's own OpenSim model) or 'generic' (gait2354 "
                                 f"scaled to the motion's character), got {model!r}")
    if model == "generic":
        from solver.io.opensim.base import OpenSimError as _OpenSimError

        exportable(motion)
        try:
            with tempfile.TemporaryDirectory(prefix="motionx-osim-generic-") as scratch:
                generic = generic_rig(motion, scratch)
        except _OpenSimError as e:
            raise OpenSimExportError(str(e)) from None
        # written in OpenSim's own axes: the source's ground frame (BVH's y up, centimetres…) is not the model's
        motion = motion.evolve(context=motion.context.with_(rig=generic, frame=GroundFrame.from_dict(generic["frame"])))
    rig = source_rig(motion)
    if not (isinstance(cycles, int) and not isinstance(cycles, bool) and 1 <= cycles <= 10):
        raise OpenSimExportError(f"cycles must be an integer from 1 to 10, got {cycles!r}")
    if not (isinstance(rate, (int, float)) and math.isfinite(rate) and 10.0 <= rate <= 1000.0):
        raise OpenSimExportError(f"rate must be 10-1000 Hz, got {rate!r}")
    if lowpass is not None and not (isinstance(lowpass, (int, float)) and not isinstance(lowpass, bool)
                                    and math.isfinite(lowpass) and 0.0 < lowpass <= 0.5 * rate):
        raise OpenSimExportError(f"lowpass must be None (no filter) or a cut-off in (0, rate/2] Hz, got {lowpass!r}")
    if not isinstance(reduce_residuals, bool):
        raise OpenSimExportError(f"reduce_residuals must be true or false, got {reduce_residuals!r}")
    folder = Path(folder).resolve()
    folder.mkdir(parents=True, exist_ok=True)
    model_info = rig["model"]
    text, repaired = repaired_model_text(unpack_model(model_info["osim_xz_b64"]))
    model_file = Path(str(model_info.get("file") or "model.osim")).name
    if not model_file.endswith(".osim"):
        model_file += ".osim"
    frame, gravity = export_frame(motion)
    text, model_gravity = with_gravity(text, gravity)
    (folder / model_file).write_bytes(text)
    timing: dict[str, float] = {}
    try:
        # the model's bodies along the captured trial, then against our segments
        tk = time.perf_counter()
        ev, posture, cal, blend = _calibrated(motion, rig, folder / model_file)
        timing["evaluate_capture_s"] = time.perf_counter() - tk
        cyc = motion.context.cycle
        assert cyc is not None and cyc.t_start is not None  # exportable
        torso, parts = trunk_parts(rig, motion.character)
        t, q, w, D = cycle_samples(motion, cycles, float(rate))
        W, P = body_poses(motion, q, t, D, cal, frame, blend)
        defs, xyz = virtual_markers(list(rig["bodies"]), np.asarray(ev["body_com"], dtype=float), W, P)
        with tempfile.TemporaryDirectory(prefix="motionx-osim-ik-") as scratch:
            trc = Path(scratch) / "virtual_markers.trc"
            write_trc(trc, [m[0] for m in defs], t, xyz, float(rate))
            tk = time.perf_counter()
            ik = run_child({"job": "ik", "model": str(folder / model_file), "markers": defs, "xyz": xyz.tolist(),
                            "weights": {},  # every virtual marker weighs 1 (OpenSim's default)
                            "trc": str(trc), "t0": float(t[0]), "t1": float(t[-1]),
                            "out": str((folder / COORDINATES_FILE).resolve()), "scratch": scratch})
            timing["inverse_kinematics_s"] = time.perf_counter() - tk
        # ground reactions in the model's ground frame, on the motion's ground plane there
        t_abs = cyc.t_start + t
        # the motion stands its contact points on z = 0, the capture's soles were that much lower:
        # the floor (the trial's plates) is z = -shift in the motion's world
        m_frame, c_frame = motion.frame, GroundFrame.from_dict(rig["frame"])
        shift = float((m_frame.R.T @ (m_frame.offset - c_frame.offset))[2]) * m_frame.unit_m
        normal = frame.R @ np.array([0.0, 0.0, 1.0])
        origin = frame.point_to_input(np.tile([0.0, 0.0, -shift], (t.size, 1)), t_abs)
        min_load = MIN_LOAD_FRACTION * float(np.linalg.norm(gravity)) * motion.character.total_mass
        w_in = wrenches_to_input(w, t_abs, frame)
        naive = grf_columns(w_in, normal, origin, min_load)
        write_mot(folder / GRF_FILE, "grf", GRF_LABELS, t, _grf_table(naive), in_degrees=False)
        (folder / EXTERNAL_LOADS_FILE).write_text(external_loads_xml(rig["feet"], GRF_FILE))
        window = (D, 2 * D) if cycles >= 3 else (float(t[0]), float(t[-1]))
        (folder / SETUP_FILE).write_text(id_setup_xml(model_file, COORDINATES_FILE, EXTERNAL_LOADS_FILE, *window,
                                                      lowpass=lowpass))
        residuals: dict[str, Any] = {}
        adjustment: dict[str, Any] | None = None
        cols = naive
        if reduce_residuals:
            # OpenSim's ID over every row (the naive loads), then the wrench it still needs, on the feet
            full = "setup_id_all_rows.xml"
            (folder / full).write_text(id_setup_xml(model_file, COORDINATES_FILE, EXTERNAL_LOADS_FILE,
                                                    float(t[0]), float(t[-1]), lowpass=lowpass,
                                                    output="inverse_dynamics_all.sto"))
            tk = time.perf_counter()
            ans = run_inverse_dynamics(folder, full)
            timing["inverse_dynamics_naive_s"] = time.perf_counter() - tk
            for name in (full, "inverse_dynamics_all.sto"):
                (folder / name).unlink(missing_ok=True)
            keep = (np.asarray(ans["times"]) >= window[0] - 1e-9) & (np.asarray(ans["times"]) <= window[1] + 1e-9)
            residuals["before_reduction"] = figures_of(folder, {**ans, "times": np.asarray(ans["times"])[keep],
                                                                "data": np.asarray(ans["data"])[keep]})
            w_new, added = reduce_residuals_on_feet(w_in, ans, t, min_load)
            cols = grf_columns(w_new, normal, origin, min_load)
            write_mot(folder / GRF_FILE, "grf", GRF_LABELS, t, _grf_table(cols), in_degrees=False)
            inside = (t >= window[0] - 1e-9) & (t <= window[1] + 1e-9)
            prints = footprints(list(rig["bodies"]), np.asarray(ev["body_com"], dtype=float), W, P, rig["feet"])
            out_before = cop_outside_feet(naive, prints, inside, min_load)
            out_after = cop_outside_feet(cols, prints, inside, min_load)
            per_foot = _adjustment_figures(naive, cols, t, window, min_load)
            weight = float(np.linalg.norm(gravity)) * motion.character.total_mass
            large = [side for side, v in per_foot.items()
                     if v["cop_shift_mm"]["max"] > LARGE_COP_SHIFT_MM or v["force_change_N"]["max"] > 0.1 * weight]
            adjustment = {"per_foot": per_foot,
                          "large": bool(large),
                          "note": (f"the ground reaction of the {' and '.join(large)} foot moved by more than "
                                   f"{LARGE_COP_SHIFT_MM:g} mm or 10 % of the body weight: this model cannot follow "
                                   "the motion's character closely (its joints, or trunk segments the character "
                                   "moves and the model holds rigid); the files balance on the model but the "
                                   "adjusted ground reactions are not the motion's") if large else None,
                          "cop_outside_footprint_mm": {
                              side: {"before": 1e3 * out_before[f], "after": 1e3 * out_after[f]}
                              for f, side in enumerate(("right", "left"))},
                          "footprint": f"heel-to-toe line widened by {1e3 * FOOT_HALF_WIDTH_M:g} mm each side",
                          "added_force_N": {"max": float(np.linalg.norm(added[inside, 3:], axis=1).max()),
                                            "rms": float(np.sqrt(np.mean(np.sum(added[inside, 3:]**2, axis=1))))}}
        tk = time.perf_counter()
        residuals["as_written"] = opensim_residuals(folder)
        timing["inverse_dynamics_s"] = time.perf_counter() - tk
        other = CAPTURE_LOWPASS_HZ if lowpass is None else None  # the same files under the other filter choice
        extra = "setup_id_other_filter.xml"
        (folder / extra).write_text(id_setup_xml(model_file, COORDINATES_FILE, EXTERNAL_LOADS_FILE, *window,
                                                 lowpass=other, output="inverse_dynamics_other_filter.sto"))
        try:
            residuals["as_written_other_filter"] = opensim_residuals(folder, extra)
        finally:
            for name in (extra, "inverse_dynamics_other_filter.sto"):
                (folder / name).unlink(missing_ok=True)
        for name in (ID_OUTPUT_FILE, "opensim.log"):  # outputs of running the setup, not part of the export
            (folder / name).unlink(missing_ok=True)
        tk = time.perf_counter()
        reference = _capture_reference(rig, folder / model_file, _cycle(motion),
                                       dict(zip(ev["coord_names"], (bool(r) for r in ev["coord_rotational"]))))
        timing["capture_inverse_dynamics_s"] = time.perf_counter() - tk
    except OpenSimError as e:
        raise OpenSimExportError(str(e)) from None
    timing["total_s"] = time.perf_counter() - t_begin
    translational = {n for n, r in zip(ev["coord_names"], ev["coord_rotational"]) if not r}
    ik_rms = np.asarray(ik["marker_rms_m"], dtype=float)
    ik_max = np.asarray(ik["marker_max_m"], dtype=float)
    summary = {
        "format": "motionx.opensim-export",
        "version": 1,
        "motion": {"step": motion.provenance.get("step"), "lambda": motion.provenance.get("lambda"),
                   "character": motion.character.name, "fps": motion.fps, "frames": motion.T,
                   "cycle_s": D, "source_cycle": cyc.to_dict()},
        "model": {"file": model_file, "name": model_info.get("name"), "sha256_source": model_info.get("sha256"),
                  "socket_paths_repaired": repaired, "gravity_changed": model_gravity,
                  "generic": rig.get("generic")},
        "files": {"model": model_file, "coordinates": COORDINATES_FILE, "ground_reactions": GRF_FILE,
                  "external_loads": EXTERNAL_LOADS_FILE, "inverse_dynamics_setup": SETUP_FILE},
        "sampling": {"rate_hz": float(rate), "cycles": cycles, "rows": int(t.size),
                     "time_s": [float(t[0]), float(t[-1])], "analysed_cycle_s": list(window),
                     "interpolation": motion.interpolation},
        "ground_frame": {"axes": "OpenSim ground: x forward, y up, z right",
                         "ground_normal": normal.round(9).tolist(), "ground_point_m": origin[0].round(6).tolist(),
                         "contact_plane_shift_m": shift, "gravity_m_s2": gravity.round(6).tolist(),
                         "belt_velocity_m_s": frame.vector_to_input(frame.velocity).tolist(),
                         "feet": dict(rig["feet"])},
        "inverse_kinematics": {"tool": "OpenSim InverseKinematicsTool", "virtual_markers": len(defs),
                               "bodies_marked": sorted({m[1] for m in defs}),
                               "anchors": {**dict(cal.anchors), **({torso: "+".join(p for p, _ in parts)}
                                                                    if torso is not None else {})},
                               "calibration": {"harmonics": cal.harmonics,
                                               "smoothing_rms_deg": cal.fit_rms_deg,
                                               "smoothing_rms_mm": cal.fit_rms_mm},
                               "marker_rms_mm": {"mean": 1e3 * float(ik_rms.mean()), "max": 1e3 * float(ik_rms.max())},
                               "marker_max_mm": 1e3 * float(ik_max.max()),
                               "refinement_iterations_max": ik.get("refine_iterations_max"),
                               "refinement_last_step_max": ik.get("refine_last_step_max"),
                               "coordinates_outside_model_range_deg_or_m": {
                                   n: round(float(np.degrees(v)) if n not in translational else float(v), 4)
                                   for n, v in ik["outside_range"].items()},
                               "worst_markers_rms_mm": {n: round(1e3 * v, 2) for n, v in sorted(
                                   ik["per_marker_rms_m"].items(), key=lambda kv: -kv[1])[:5]}},
        "residual_reduction": adjustment,
        "residuals": residuals,
        "capture_residuals": reference,
        "opensim_version": _opensim_version(),
        "timing_s": {k: round(v, 3) for k, v in timing.items()},
    }
    (folder / SUMMARY_FILE).write_text(json.dumps(summary, indent=1, default=float) + "\n")
    (folder / README_FILE).write_text(readme(summary))
    return summary


def _opensim_version() -> str | None:
    try:
        from importlib.metadata import version

        return version("opensim")
    except Exception:
        return None


def readme(summary: Mapping[str, Any]) -> str:
    """The folder's README: what the files are and what OpenSim's inverse dynamics says of them."""
    res = summary["residuals"]["as_written"]
    before = summary["residuals"].get("before_reduction")
    f = summary["files"]
    repaired = " (3.x socket paths rewritten to /bodyset/...)" if summary["model"]["socket_paths_repaired"] else ""
    filt = ("coordinates not filtered (samples of a smooth motion)" if res["lowpass_hz"] <= 0 else
            f"coordinates low-passed at {res['lowpass_hz']:g} Hz")
    lines = [
        "# A motionx motion on your OpenSim model", "",
        f"Motion: {summary['motion']['step']} (λ = {summary['motion']['lambda']}), character "
        f"{summary['motion']['character']}, gait cycle {summary['motion']['cycle_s']:.3f} s; model "
        f"`{f['model']}`.", "",
        "| file | content |", "|---|---|",
        f"| `{f['model']}` | the trial's model{repaired} |",
        f"| `{f['coordinates']}` | the model's coordinates (degrees, metres), {summary['sampling']['cycles']} gait "
        f"cycles at {summary['sampling']['rate_hz']:g} Hz, by OpenSim's InverseKinematicsTool (refined) |",
        f"| `{f['ground_reactions']}` | ground reactions per foot: force (N), centre of pressure on the floor (m), "
        "free moment (N·m), OpenSim ground (x forward, y up, z right) |",
        f"| `{f['external_loads']}` | the forces applied to {', '.join(summary['ground_frame']['feet'].values())} |",
        f"| `{f['inverse_dynamics_setup']}` | OpenSim's InverseDynamicsTool on these files, {filt}, over the middle "
        f"cycle {res['time_range_s'][0]:.3f}-{res['time_range_s'][1]:.3f} s |",
        "| `summary.json` | everything below, and more |", "",
        "Run the inverse dynamics yourself: `opensim-cmd run-tool setup_id.xml` (in this folder), or",
        "`opensim.InverseDynamicsTool('setup_id.xml').run()` from Python.", "",
        "## Residuals (OpenSim's InverseDynamicsTool on these files)", "",
        "Hicks et al. 2015: peak residual force <= 5 % of the peak net external force, peak residual moment",
        "<= 1 % of centre-of-mass height x peak net external force.", "",
        "| | peak residual force (N) | limit (N) | peak residual moment (N·m) | limit (N·m) | meets |",
        "|---|---|---|---|---|---|",
    ]
    other = summary["residuals"].get("as_written_other_filter")
    rows: list[tuple[str, Mapping[str, Any]]] = [("before ground-reaction adjustment", before)] if before else []
    rows.append(("as written", res))
    if other:
        rows.append(("as written, " + ("not filtered" if other["lowpass_hz"] <= 0 else
                                       f"coordinates low-passed at {other['lowpass_hz']:g} Hz"), other))
    cap = summary.get("capture_residuals") or {}
    if cap.get("available"):
        rows.append((f"the trial's own IK and plates ({cap['time_range_s'][0]:.2f}-{cap['time_range_s'][1]:.2f} s, "
                     f"{cap['lowpass_hz']:g} Hz)", cap))
    for name, r in rows:
        lines.append(f"| {name} | {r['peak_residual_force_vector_N']:.2f} | {r['force_limit_N']:.1f} | "
                     f"{r['peak_residual_moment_Nm']:.2f} | {r['moment_limit_Nm']:.2f} | "
                     f"{'yes' if r['meets_hicks_2015'] else 'no'} |")
    adj = summary.get("residual_reduction")
    if adj:
        lines += ["", "The ground reactions were adjusted by the external wrench OpenSim's inverse dynamics still",
                  "needed on this model (its arms, trunk and joints are not those of the motion's character);",
                  "by at most: " + "; ".join(
                      f"{side} foot {v['force_change_N']['max']:.1f} N, centre of pressure "
                      f"{v['cop_shift_mm']['max']:.1f} mm, free moment {v['free_moment_change_Nm']['max']:.2f} N·m"
                      for side, v in adj["per_foot"].items()) + "."]
        if adj.get("note"):
            lines += ["", "**Large adjustment**: " + adj["note"] + "."]
    return "\n".join(lines) + "\n"


def to_opensim(motion: Motion, *, cycles: int = CYCLES, rate: float = RATE_HZ, lowpass: float | None = LOWPASS_HZ,
               reduce_residuals: bool = True, model: str = "source") -> bytes:
    """The folder :func:`write_opensim` writes, as a zip archive (``export_motion(motion,
    "opensim")``; with ``path=DIR`` it is unpacked into DIR)."""
    with tempfile.TemporaryDirectory(prefix="motionx-osim-export-") as d:
        write_opensim(motion, d, cycles=cycles, rate=rate, lowpass=lowpass, reduce_residuals=reduce_residuals,
                      model=model)
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
            for p in sorted(Path(d).iterdir()):
                if p.is_file():
                    z.write(p, p.name)
        return buf.getvalue()
