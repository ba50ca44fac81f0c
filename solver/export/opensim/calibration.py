"""The model's bodies on the motion: :class:`OpenSimCalibration`, the
:class:`~solver.retargeting.Calibration` of an OpenSim rig (:class:`~solver.io.opensim.rig.OpenSimRig`):
each OpenSim body against the segment of the motion's character it rides on, as a smooth periodic
function of the gait phase (:class:`BodySeries`), fitted on OpenSim's evaluation of the model along
the trial (:meth:`OpenSimCalibration.fit`) and applied to place the bodies along a motion
(:meth:`OpenSimCalibration.pose`); the virtual markers OpenSim's inverse kinematics fits to them
(:func:`virtual_markers`), and the bodies along one cycle for a look at them (:func:`model_bodies`)."""

from __future__ import annotations

import re
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from solver.capture import GroundFrame
from solver.character import Character
from solver.export.opensim.base import OpenSimExportError, _cycle, source_rig
from solver.export.opensim.files import repaired_model_text, with_gravity
from solver.export.opensim.sampling import cycle_samples, cycle_times, export_frame
from solver.io.opensim.rig import OpenSimRig, unpack_model
from solver.kinematics import segment_frames
from solver.motion import Motion
from solver.retargeting import Calibration

#: the calibration's harmonics reach this frequency (Hz)
CALIBRATION_CUTOFF_HZ = 6.0
#: virtual markers: this far (m) from a body's centre of mass along each of its axes
MARKER_OFFSET_M = 0.1
#: bodies left without virtual markers: their pose follows from constraints (a patella's coupler)
UNMARKED_BODIES = re.compile(r"patella.*")
#: a torso body shared between our trunk segments (a model with arms), which it follows together
TRUNK_PARTS = ("abdomen", "thorax", "head")


def trunk_parts(rig: OpenSimRig, character: Character) -> tuple[str | None, list[tuple[str, float]]]:
    """The model body split between trunk segments the motion's character has (the torso of a
    model with arms, for a full-body character) and those segments with their masses; (None,
    []) when the character moves at most one of them."""
    body = next((b for b, sg in rig.body_segments.items() if sg == "torso"), None)
    names = {sg.name: sg for sg in character.segments}
    parts = [(p, float(names[p].mass)) for p in TRUNK_PARTS if p in names]
    return (body, parts) if body is not None and len(parts) > 1 else (None, [])


def _own_segments(rig: OpenSimRig) -> dict[str, str | None]:
    return {b: ("abdomen" if s == "torso" else s) for b, s in rig.body_segments.items()}


def _anchors(rig: OpenSimRig, character: Character, parents: Mapping[str, str],
             override: Mapping[str, str] | None = None) -> dict[str, str]:
    """Each model body -> the segment of the motion's character it rides on (see
    :mod:`solver.export.opensim`); ``override``: body -> its own segment instead of the rig's."""
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

    for b in rig.bodies:
        out[b] = anchor(b)
    return out


def _fit_q(rig: OpenSimRig, character: Character) -> np.ndarray:
    names = list(rig.fit_names)
    qf = rig.fit_q
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
class BodySeries:
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

    def to_dict(self) -> dict[str, Any]:
        """Plain data (every number as computed)."""
        return {"anchors": dict(self.anchors), "mean": self.mean.tolist(), "rot": self.rot.tolist(),
                "pos": self.pos.tolist(), "harmonics": self.harmonics, "fit_rms_deg": self.fit_rms_deg,
                "fit_rms_mm": self.fit_rms_mm, "right": self.right.tolist(), "offset": self.offset.tolist()}

    @staticmethod
    def from_dict(d: Mapping[str, Any]) -> BodySeries:
        def arr(k: str) -> np.ndarray:
            return np.asarray(d[k], dtype=float)

        return BodySeries({str(b): str(a) for b, a in dict(d["anchors"]).items()}, arr("mean"), arr("rot"),
                          arr("pos"), int(d["harmonics"]), float(d["fit_rms_deg"]), float(d["fit_rms_mm"]),
                          arr("right"), arr("offset"))


def _series(rig: OpenSimRig, character: Character, evaluation: Mapping[str, Any],
            cycle: tuple[float, float], posture: tuple[np.ndarray, np.ndarray],
            cutoff_hz: float = CALIBRATION_CUTOFF_HZ, override: Mapping[str, str] | None = None
            ) -> BodySeries:
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
    if bodies != list(rig.bodies):
        raise OpenSimExportError("the motion's OpenSim model does not have the bodies its rig records")
    parents = dict(zip(evaluation["joint_child"], evaluation["joint_parent"]))
    anchors = _anchors(rig, character, parents, override)
    frame = rig.frame
    times = rig.times
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
    return BodySeries(anchors, mean, rot, pos, K, float(np.sqrt(np.mean(er**2))), float(np.sqrt(np.mean(ep**2))),
                      right, offset)


def _body_poses(motion: Motion, q: np.ndarray, t: np.ndarray, D: float, cal: BodySeries, frame: GroundFrame,
                blend: Mapping[str, Sequence[tuple[BodySeries, float]]] | None = None
                ) -> tuple[np.ndarray, np.ndarray]:
    """The model's bodies (S, B, 3, 3), (S, B, 3) in OpenSim ground, placed on the motion's anchors
    ``q`` (n, S) at times ``t`` (s; ``D`` the motion's cycle) with the calibration at the same gait
    phase; ``frame``: the motion's world → OpenSim ground
    (:func:`~solver.export.opensim.sampling.export_frame`). ``blend``: body -> (series, weight)
    pairs whose poses it takes the weighted mean of (a torso shared by our abdomen, thorax and
    head, weighed by mass)."""
    if blend:
        W, P = _body_poses(motion, q, t, D, cal, frame)
        bodies = list(cal.anchors)
        for b, cals in blend.items():
            i = bodies.index(b)
            poses = [_body_poses(motion, q, t, D, c, frame) for c, _ in cals]
            w = np.array([float(x) for _, x in cals])
            P[:, i] = np.einsum("k,kti->ti", w / w.sum(), np.stack([pp[1][:, i] for pp in poses]))
            for s_ in range(t.size):
                W[s_, i] = Rotation.from_matrix(np.stack([pp[0][s_, i] for pp in poses])).mean(weights=w).as_matrix()
        return W, P
    t_start = _cycle(motion)[0]
    C, d = cal.at(t / D)
    Rs, Ps = segment_frames(motion.character, q)
    names = [s.name for s in motion.character.segments]
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


@dataclass(frozen=True, eq=False)
class EvaluatedModel:
    """The model as OpenSim evaluated it for a calibration: each body's parent (``ground`` for the
    root), centre of mass (B, 3) in its frame, each coordinate (rotational or not), and the
    bodies' frames (B, 3, 3), (B, 3) in OpenSim ground at the cycle's mean coordinates
    (``posture``)."""

    parents: Mapping[str, str]
    body_com: np.ndarray
    coordinates: Mapping[str, bool]
    posture: tuple[np.ndarray, np.ndarray]

    def to_dict(self) -> dict[str, Any]:
        return {"parents": dict(self.parents), "body_com": self.body_com.tolist(),
                "coordinates": dict(self.coordinates), "posture": [self.posture[0].tolist(), self.posture[1].tolist()]}

    @staticmethod
    def from_dict(d: Mapping[str, Any]) -> EvaluatedModel:
        return EvaluatedModel({str(b): str(p) for b, p in dict(d["parents"]).items()},
                              np.asarray(d["body_com"], dtype=float),
                              {str(c): bool(r) for c, r in dict(d["coordinates"]).items()},
                              (np.asarray(d["posture"][0], dtype=float), np.asarray(d["posture"][1], dtype=float)))


def _evaluated(rig: OpenSimRig, reference: Motion) -> tuple[dict[str, Any], tuple[np.ndarray, np.ndarray]]:
    """OpenSim's evaluation of the rig's model along the captured trial (the model as the export
    writes it for ``reference``, its gravity included) and its posture at the cycle's mean coordinates."""
    from solver.io.opensim.worker import run_worker  # lazy: OpenSim's child process, only for an export

    text, _ = repaired_model_text(unpack_model(rig.model["osim_xz_b64"]))
    text, _ = with_gravity(text, export_frame(reference)[1])
    t_start, period = _cycle(reference)
    in_cycle = (rig.times >= t_start - 1e-9) & (rig.times < t_start + period)
    values = rig.coordinates
    mean_row = values[in_cycle].mean(axis=0) if in_cycle.any() else values.mean(axis=0)
    with tempfile.TemporaryDirectory(prefix="motionx-osim-calibration-") as scratch:
        path = Path(scratch) / "model.osim"
        path.write_bytes(text)
        ev = run_worker(str(path), list(rig.coordinate_names), np.vstack([values, mean_row]), False)
    posture = (np.asarray(ev["R"])[-1], np.asarray(ev["P"])[-1])
    return {**ev, "R": np.asarray(ev["R"])[:-1], "P": np.asarray(ev["P"])[:-1]}, posture


@dataclass(frozen=True, eq=False)
class OpenSimCalibration(Calibration[OpenSimRig, tuple[np.ndarray, np.ndarray]]):
    """An OpenSim rig's calibration (:class:`~solver.retargeting.Calibration`): the model's
    ``bodies`` against the motion's character (:class:`BodySeries`), a torso shared by several of
    its trunk segments as the mass-weighted ``blend`` of one series per segment (body ->
    (series, weight) pairs), and the ``model`` as OpenSim evaluated it."""

    bodies: BodySeries
    blend: Mapping[str, tuple[tuple[BodySeries, float], ...]] = field(default_factory=dict)
    model: EvaluatedModel | None = None

    @classmethod
    def fit(cls, rig: OpenSimRig, reference: Motion) -> OpenSimCalibration:
        """The model's bodies against ``reference``'s character at the captured cycle's frames
        (``reference``: the motion to write, a gait cycle recording its captured cycle; the
        capture skeleton's fit of the trial, in the rig, places the character there), OpenSim
        evaluating the model along the trial (in a child process). Runs OpenSim: an
        :class:`~solver.io.opensim.base.OpenSimError` when it cannot."""
        cycle = reference.context.cycle
        if cycle is None or cycle.t_start is None or cycle.period_s is None:
            raise OpenSimExportError("the motion does not record the captured gait cycle it stands for")
        ev, posture = _evaluated(rig, reference)
        cyc = (cycle.t_start, cycle.period_s)
        ch = reference.character
        series = _series(rig, ch, ev, cyc, posture)
        torso, parts = trunk_parts(rig, ch)
        blend = {}
        if torso is not None:
            blend = {torso: tuple((series if k == 0 else _series(rig, ch, ev, cyc, posture, override={torso: seg}), m)
                                  for k, (seg, m) in enumerate(parts))}
        model = EvaluatedModel(dict(zip(ev["joint_child"], ev["joint_parent"])),
                               np.asarray(ev["body_com"], dtype=float),
                               dict(zip(ev["coord_names"], (bool(r) for r in ev["coord_rotational"]))), posture)
        return cls(series, blend, model)

    def pose(self, motion: Motion, rig: OpenSimRig, times: np.ndarray, q: np.ndarray,
             duration: float) -> tuple[np.ndarray, np.ndarray]:
        """The model's bodies (S, B, 3, 3), (S, B, 3) in OpenSim ground (the motion's world through
        :func:`~solver.export.opensim.sampling.export_frame`), each placed on its anchor segment
        with its series at the same gait phase."""
        return _body_poses(motion, q, times, duration, self.bodies, export_frame(motion)[0], self.blend)

    def to_dict(self) -> dict[str, Any]:
        return {"bodies": self.bodies.to_dict(),
                "blend": {b: [[c.to_dict(), w] for c, w in parts] for b, parts in self.blend.items()},
                "model": None if self.model is None else self.model.to_dict()}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> OpenSimCalibration:
        return cls(BodySeries.from_dict(d["bodies"]),
                   {str(b): tuple((BodySeries.from_dict(c), float(w)) for c, w in parts)
                    for b, parts in dict(d.get("blend") or {}).items()},
                   None if d.get("model") is None else EvaluatedModel.from_dict(d["model"]))


#: frames per second of :func:`model_bodies`' cycle (the OpenSim model's GLB)
PREVIEW_RATE = 30.0


def _capture_rig(motion: Motion) -> OpenSimRig | None:
    """A capture's (no cycle, no ground reactions) OpenSim trial, None for a cyclic motion; an error for a
    capture from anything else."""
    if motion.cyclic and motion.wrenches is not None:
        return None
    rig = motion.context.rig
    if not isinstance(rig, OpenSimRig):
        raise OpenSimExportError("the motion was not made from an OpenSim trial: it has no OpenSim model")
    return rig


def preview_times(motion: Motion, rate: float = PREVIEW_RATE) -> np.ndarray:
    """The times (from 0) at which :func:`model_bodies` poses the model: one gait cycle at ``rate``; a
    capture (no cycle, no ground reactions): the trial's own frames."""
    rig = _capture_rig(motion)
    if rig is not None:
        return np.asarray(rig.times, dtype=float) - float(rig.times[0])
    return cycle_times(motion, 1, float(rate))[0]


def model_bodies(motion: Motion, rate: float = PREVIEW_RATE) -> dict[str, Any]:
    """The motion on its OpenSim trial's model, for a look at it (the web page's preview): one gait
    cycle at ``rate`` of every body's frame in the model's ground (where gravity points down),
    placed as :func:`~solver.export.opensim.folder.write_opensim` places them for OpenSim's inverse
    kinematics (no IK run); a capture (no cycle, no ground reactions): the trial itself, the model
    along its own coordinates. Keys: ``bodies``, ``parents`` (body -> parent body, ``ground`` for
    the root), ``times``, ``R`` (S, B, 3, 3), ``P`` (S, B, 3), ``posture`` (R, P at the cycle's
    mean coordinates), ``com`` (B, 3: each body's centre of mass in its frame) and ``frame`` (the
    ground frame without the slope's turn: the model's ground in the world where gravity points
    down)."""
    from solver.io.opensim.base import OpenSimError
    from solver.io.opensim.worker import run_worker  # lazy: OpenSim's child process

    capture = _capture_rig(motion)
    frame, gravity = export_frame(motion)
    try:
        if capture is not None:  # a capture: the trial as the model moved
            rig = capture
            text, _ = repaired_model_text(unpack_model(rig.model["osim_xz_b64"]))
            text, _ = with_gravity(text, gravity)
            with tempfile.TemporaryDirectory(prefix="motionx-osim-bodies-") as scratch:
                path = Path(scratch) / "model.osim"
                path.write_bytes(text)
                ev = run_worker(str(path), list(rig.coordinate_names), rig.coordinates, False)
            t_abs = rig.times
            t = preview_times(motion)
            W, P = np.asarray(ev["R"], dtype=float), np.asarray(ev["P"], dtype=float)
            parents = dict(zip(ev["joint_child"], ev["joint_parent"]))
            posture, com = (W[0], P[0]), np.asarray(ev["body_com"], dtype=float)
        else:
            rig = source_rig(motion)
            cal = rig.calibrated(motion).calibration
            assert isinstance(cal, OpenSimCalibration) and cal.model is not None  # the format's calibration
            t, q, _, D = cycle_samples(motion, 1, float(rate))
            t_abs = _cycle(motion)[0] + t
            W, P = cal.pose(motion, rig, t, q, D)
            parents, posture, com = dict(cal.model.parents), cal.model.posture, cal.model.body_com
    except OpenSimError as e:
        raise OpenSimExportError(str(e)) from None
    # a treadmill trial's model walks on its belt: moved on with it, it walks along its ground
    P = P + (frame.R @ frame.velocity / frame.unit_m)[None, None, :] * t_abs[:, None, None]
    return {"bodies": list(rig.bodies), "parents": parents, "times": t, "R": W, "P": P, "posture": posture,
            "com": com, "frame": motion.frame}
