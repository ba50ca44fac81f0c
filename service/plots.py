"""Plots as PNG bytes (matplotlib, Agg canvas): the continuation's progress curve, the
ground reaction forces per foot, the root residual of the equations of motion, and the
filmstrip of a cycle (side, rear and top views with soles and ground forces).

Presentation only: the numbers come from ``solver``/``mjcf`` (``solver.export.ground_reactions``,
``solver.plausibility.root_residual``, ``mjcf.validate.mujoco_residual``). Used by the API
(``service/routes/plots.py``) and the command line (``motionx plot``, ``motionx extrapolate``).

matplotlib is imported inside the functions, so importing this module stays cheap; figures
are built on their own ``FigureCanvasAgg`` (no pyplot, no global state), so rendering from
several threads of the API at once is safe.
"""

from __future__ import annotations

import io
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from solver import axes as registry

DPI = 110
_COLOURS = {"slope_deg": "tab:orange", "curve_deg": "tab:green", "gravity": "tab:purple", "friction": "tab:brown",
            "speed_scale": "tab:blue"}
_PALETTE = ("tab:olive", "tab:cyan", "tab:pink", "tab:gray", "tab:red")
#: environment values a target can change (the homotopy axes, solver.axes): key, axis label, colour
ENVIRONMENT = tuple(
    (ax.name, f"{ax.label} ({ax.unit})" if ax.unit else ax.label, _COLOURS.get(ax.name, _PALETTE[i % len(_PALETTE)]))
    for i, ax in enumerate(registry.axes()))
TARGET_KEYS = tuple(k for k, _, _ in ENVIRONMENT)
#: the display floor of the log-scale residual plot (a residual of exactly 0 is drawn there)
RESIDUAL_FLOOR = 1e-18


class PlotError(ValueError):
    """The input cannot be plotted; the message says why (HTTP 422, CLI exit 2)."""


# --- matplotlib plumbing ---------------------------------------------------------------------


def _figure(width: float, height: float):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=DPI)
    FigureCanvasAgg(fig)
    return fig


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI)
    return buf.getvalue()


# --- progress curve ------------------------------------------------------------------------


def _number(v: Any, where: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise PlotError(f"{where} must be a number, got {v!r}")
    if not math.isfinite(v):
        raise PlotError(f"{where} must be finite, got {v!r}")
    return float(v)


def _records(progress: Any) -> list[dict]:
    """Checks the progress records (the API's ``progress`` points, or the CLI's
    ``ProgressRecord`` as dicts) and returns them as plain dicts."""
    if isinstance(progress, (str, bytes)) or not isinstance(progress, Sequence):
        raise PlotError(f"progress must be a list of records, got {type(progress).__name__}")
    out = []
    for i, r in enumerate(progress):
        if not isinstance(r, Mapping):
            raise PlotError(f"progress[{i}] must be a record (mapping), got {type(r).__name__}")
        missing = [k for k in ("wall_time", "lam", "lam_reached", "accepted") if k not in r]
        if missing:
            raise PlotError(f"progress[{i}] lacks {missing}")
        phase = r.get("phase", "extrapolate")
        if phase not in ("tutor", "extrapolate"):
            raise PlotError(f"progress[{i}].phase must be 'tutor' or 'extrapolate', got {phase!r}")
        if not isinstance(r["accepted"], bool):
            raise PlotError(f"progress[{i}].accepted must be true or false, got {r['accepted']!r}")
        env = r.get("environment") or {}
        if not isinstance(env, Mapping):
            raise PlotError(f"progress[{i}].environment must be a mapping, got {type(env).__name__}")
        rec = {
            "phase": phase,
            "wall_time": _number(r["wall_time"], f"progress[{i}].wall_time"),
            "lam": _number(r["lam"], f"progress[{i}].lam"),
            "lam_reached": _number(r["lam_reached"], f"progress[{i}].lam_reached"),
            "accepted": r["accepted"],
            "iterations": int(_number(r.get("iterations", 0), f"progress[{i}].iterations")),
            "status": str(r.get("status") or ""),
            "environment": {k: _number(env[k], f"progress[{i}].environment.{k}")
                            for k in TARGET_KEYS if env.get(k) is not None},
        }
        out.append(rec)
    return out


def _target(target: Any) -> dict[str, float | None]:
    if target is None:
        return {}
    if not isinstance(target, Mapping):
        raise PlotError(f"target must be a mapping (slope_deg, curve_deg, friction, gravity), "
                        f"got {type(target).__name__}")
    unknown = sorted(set(target) - set(TARGET_KEYS))
    if unknown:
        raise PlotError(f"unknown target keys {unknown}; known: {list(TARGET_KEYS)}")
    return {k: (None if target.get(k) is None else _number(target[k], f"target.{k}")) for k in TARGET_KEYS}


def changed_parameters(target: Mapping[str, float | None]) -> list[str]:
    """The environment keys a target changes, in display order."""
    out = []
    for k in TARGET_KEYS:
        v = target.get(k)
        if registry.axis(k).changes(v):
            out.append(k)
    return out


def number_text(v: float, decimals: int = 4) -> str:
    """A value with the decimals it needs, up to ``decimals``: -11.25, 90, 0.7, 1.62 (never
    -11.2 for -11.25, nor 90.0000)."""
    text = f"{float(v):.{decimals}f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


_WORDS = {ax.name: ax.words for ax in registry.axes()}


def environment_text(values: Mapping[str, float]) -> str:
    """'slope -11.25°, curve 90°': environment values in words, in display order."""
    return ", ".join(_WORDS[k].format(number_text(values[k])) for k in TARGET_KEYS if values.get(k) is not None)


def describe_target(target: Mapping[str, float | None] | None) -> str:
    """'slope -11.25°, μ=0.7' — the target in words (also used in titles)."""
    t = _target(target)
    return environment_text({k: t[k] for k in changed_parameters(t)}) or "the base problem"


#: line styles of the environment panels (distinct from each other and from λ's)
_STYLES = (("--", "s"), ("-.", "D"), ("--", "v"), (":", "^"), (":", "o"), ("-.", "P"))
_ENV_STYLE = {ax.name: _STYLES[i % len(_STYLES)] for i, ax in enumerate(registry.axes())}


def progress_figure(progress: list[dict], target: dict | None):
    """The figure of :func:`progress_png` (a matplotlib ``Figure``)."""
    recs = _records(progress)
    tgt = _target(target)
    tutor = [r for r in recs if r["phase"] == "tutor"]
    ext = [r for r in recs if r["phase"] == "extrapolate"]
    keys = changed_parameters(tgt) if target is not None else [
        k for k in TARGET_KEYS if len({r["environment"].get(k) for r in ext if r["accepted"]} - {None}) > 1]
    acc = [r for r in ext if r["accepted"]]
    keys = [k for k in keys if any(k in r["environment"] for r in acc)]
    fig = _figure(7.0, 3.2 + 1.7 * len(keys))
    axes = fig.subplots(1 + len(keys), 1, sharex=True, squeeze=False,
                        gridspec_kw={"height_ratios": [2.0] + [1.0] * len(keys)})[:, 0]
    ax = axes[0]
    title = f"continuation toward {describe_target(tgt)}" if target is not None else "continuation"
    if tutor:
        t = tutor[-1]
        if t["status"].startswith("tutor made by job"):  # another job made it (service.jobs)
            title += f"\n(tutor made by another job, taken from the store after {t['wall_time']:.1f} s)"
        else:
            title += f"\n(tutor made first: {t['wall_time']:.1f} s, {t['iterations']} iterations)"
    fig.suptitle(title, fontsize=10)
    axes[-1].set_xlabel("wall time of the extrapolation (s)")
    ax.set_ylabel("λ")
    ax.set_ylim(-0.02, 1.05)
    for a in axes:
        a.grid(alpha=0.3)
    if not ext:
        ax.set_xlim(0, 1)
        ax.text(0.5, 0.5, "no progress yet", ha="center", va="center", transform=ax.transAxes, fontsize=12,
                color="0.4")
        fig.tight_layout()
        return fig
    t = [r["wall_time"] for r in ext]
    rej = [r for r in ext if not r["accepted"]]
    ax.step([0.0, *t], [0.0] + [r["lam_reached"] for r in ext], where="post", color="tab:blue", lw=1.8,
            label="λ reached")
    ax.plot([r["wall_time"] for r in acc], [r["lam"] for r in acc], "o", color="tab:blue", ms=4,
            label=f"accepted λ ({len(acc)})")
    if rej:
        ax.plot([r["wall_time"] for r in rej], [r["lam"] for r in rej], "x", color="tab:red", ms=6,
                label=f"rejected λ ({len(rej)})")
    ax.legend(loc="lower right", fontsize=8)
    labels = {k: (lab, col) for k, lab, col in ENVIRONMENT}
    for a, k in zip(axes[1:], keys):
        pts = [(0.0, acc[0]["environment"][k])] if acc and k in acc[0]["environment"] else []
        pts += [(r["wall_time"], r["environment"][k]) for r in acc if k in r["environment"]]
        lab, col = labels[k]
        ls, marker = _ENV_STYLE[k]
        a.step(*zip(*pts), where="post", color=col, ls=ls, lw=1.5, label=f"{lab.split(' (')[0]} reached")
        a.plot(*zip(*pts[1:]), marker, color=col, ms=3.5, ls="none")
        goal = tgt.get(k)
        if goal is not None:
            a.axhline(goal, color=col, ls=":", lw=1.0, alpha=0.7, label=f"target {number_text(goal)}")
        a.set_ylabel(lab, color=col)
        a.tick_params(axis="y", colors=col)
        a.legend(loc="best", fontsize=8)
    ax.set_xlim(0.0, max(t) * 1.03)
    fig.tight_layout()
    return fig


def progress_png(progress: list[dict], target: dict | None) -> bytes:
    """The continuation's progress curve as PNG: on top λ tried (accepted ●, rejected ✕) and λ
    reached against wall time; below it one panel per environment value reached (slope,
    curve, gravity, friction — those the target changes, with the target as a dotted line;
    without a target, those that vary), each on its own axis and in its own style.

    ``progress`` are records with ``wall_time`` (s since the start of the extrapolation),
    ``lam``, ``lam_reached``, ``accepted``, ``environment`` and optionally ``phase``
    ('tutor' or 'extrapolate') and ``iterations``: the API's job ``progress`` points, or
    ``dataclasses.asdict(solver.continuation.ProgressRecord)``. Records of the tutor phase
    are summed up in the title (their time origin is the job's start). An empty list gives
    a "no progress yet" figure.
    """
    return _png(progress_figure(progress, target))


# --- motions -------------------------------------------------------------------------------


def _motion_with_wrenches(motion: Any):
    from solver.motion import Motion

    if not isinstance(motion, Motion):
        raise PlotError(f"expected a motion (solver.motion.Motion), got {type(motion).__name__}")
    if motion.wrenches is None:
        raise PlotError("motion has no contact wrenches (a raw capture: make its tutor first)")
    return motion


def body_weight(motion) -> float:
    """Body weight (N) in the motion's own environment (its gravity), as the plausibility
    report counts it."""
    from solver.environment import body_weight as weight

    return weight(motion)


def motion_caption(motion) -> str:
    """The second title line of a motion's plots: 'halfboy, 21 frames at 15 fps, λ = 1,
    slope -11.25°' (values with the decimals they need)."""
    prov = motion.provenance or {}
    parts = [f"{motion.character.name}, {motion.T} frames at {motion.fps:g} fps"]
    if prov.get("lambda") is not None:
        parts.append(f"λ = {number_text(prov['lambda'])}")
    env = motion.context.axis_values
    for k in TARGET_KEYS:
        ax = registry.axis(k)
        if ax.default is not None and env.get(k) is not None and ax.changes(env[k]):
            parts.append(ax.words.format(number_text(env[k])))
    return ", ".join(parts)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) frame of each run of True."""
    out, start = [], None
    for i, v in enumerate(mask):
        if v and start is None:
            start = i
        if not v and start is not None:
            out.append((start, i - 1))
            start = None
    if start is not None:
        out.append((start, len(mask) - 1))
    return out


def grf_png(motion) -> bytes:
    """Ground reaction forces per foot as PNG: fx, fy, fz (N, world frame, Z up) against
    time, the foot's contact phases shaded, the body weight for scale.

    The forces are those of ``solver.export.ground_reactions`` (the motion's foot
    wrenches). A motion without contact wrenches raises :class:`PlotError`.
    """
    from solver.export import ExportError, ground_reactions
    from solver.motion import FEET

    motion = _motion_with_wrenches(motion)
    try:
        gr = ground_reactions(motion)
    except ExportError as e:
        raise PlotError(str(e)) from None
    contact = motion.foot_contact() if motion.contacts is not None else gr.loaded
    t = motion.times
    weight = body_weight(motion)
    fig = _figure(7.5, 5.2)
    axes = fig.subplots(2, 1, sharex=True)
    fmin = min(0.0, float(gr.force.min()))
    fmax = max(weight, float(gr.force.max()))
    pad = 0.06 * (fmax - fmin)
    for k, (ax, side) in enumerate(zip(axes, FEET)):
        for i, (a, b) in enumerate(_runs(contact[k])):
            ax.axvspan(t[a] - 0.5 * motion.dt, t[b] + 0.5 * motion.dt, color="0.85", lw=0,
                       label=None if i else "contact")
        for j, (name, col) in enumerate(zip(("fx", "fy", "fz"), ("tab:red", "tab:green", "tab:blue"))):
            ax.plot(t, gr.force[k, :, j], "-o", ms=2.5, color=col, label=name)
        ax.axhline(weight, color="0.3", ls=":", lw=1, label=f"body weight ({weight:.0f} N)")
        ax.axhline(0.0, color="0.5", lw=0.6)
        ax.set_ylim(fmin - pad, fmax + pad)
        ax.set_ylabel(f"{side} foot force (N)")
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=7, ncol=5)
    axes[-1].set_xlabel("time (s)")
    axes[-1].set_xlim(t[0] - 0.5 * motion.dt, t[-1] + 0.5 * motion.dt)
    fig.suptitle(f"ground reaction forces (world frame, Z up)\n{motion_caption(motion)}", fontsize=10)
    fig.tight_layout()
    return _png(fig)


@dataclass(frozen=True, eq=False)
class ResidualSeries:
    """At the motion's dynamics samples (frames and midpoints of its spline, or interior frames
    by central differences: ``solver.trajectory``), the root residual of the equations of
    motion: h0(q, q̇, q̈, g) − Σ contact wrenches, moment about the root position.

    ``ours`` from our RNEA (``solver.plausibility.root_residual``), ``mujoco`` from MuJoCo's
    ``mj_inverse`` replay (``mjcf.validate.mujoco_residual``), both (6, S) as (moment; force).
    ``*_force_rel`` is the largest force component / body weight per frame, ``*_moment_rel``
    the largest moment component / (body weight × leg length): their maxima over the
    frames are the plausibility report's ``max_force_rel_weight`` and
    ``max_moment_rel_weight_leg``.
    """

    time: np.ndarray  # (S,) s
    ours: np.ndarray
    mujoco: np.ndarray
    weight_N: float
    leg_m: float

    @property
    def ours_force_rel(self) -> np.ndarray:
        return np.abs(self.ours[3:]).max(axis=0) / self.weight_N

    @property
    def ours_moment_rel(self) -> np.ndarray:
        return np.abs(self.ours[:3]).max(axis=0) / (self.weight_N * self.leg_m)

    @property
    def mujoco_force_rel(self) -> np.ndarray:
        return np.abs(self.mujoco[3:]).max(axis=0) / self.weight_N

    @property
    def mujoco_moment_rel(self) -> np.ndarray:
        return np.abs(self.mujoco[:3]).max(axis=0) / (self.weight_N * self.leg_m)


def residual_series(motion) -> ResidualSeries:
    """The per-frame root residuals that :func:`residuals_png` draws (ours and MuJoCo's)."""
    from mjcf.validate import mujoco_residual
    from solver.kinematics import standing_leg_length
    from solver.plausibility import root_residual

    motion = _motion_with_wrenches(motion)
    ours = root_residual(motion, motion.environment.gravity)
    mj = mujoco_residual(motion)
    from solver.trajectory import dynamics_samples

    return ResidualSeries(time=dynamics_samples(motion).time, ours=ours, mujoco=mj, weight_N=body_weight(motion),
                          leg_m=standing_leg_length(motion.character))


def residuals_png(motion, tolerance: float = 1e-6) -> bytes:
    """The root residual per frame as PNG (log scale): force / body weight and moment /
    (body weight × leg length), ours and MuJoCo's replay, with the plausibility tolerance.
    A motion without contact wrenches raises :class:`PlotError`."""
    tol = _number(tolerance, "tolerance")
    if tol <= 0:
        raise PlotError(f"tolerance must be positive, got {tolerance!r}")
    s = residual_series(motion)
    fig = _figure(7.5, 5.2)
    axes = fig.subplots(2, 1, sharex=True)
    rows = [
        (s.ours_force_rel, s.mujoco_force_rel, "force / body weight", "N", s.weight_N),
        (s.ours_moment_rel, s.mujoco_moment_rel, "moment / (weight × leg)", "N·m", s.weight_N * s.leg_m),
    ]
    top = max(10 * tol, 10 * float(max(s.ours_force_rel.max(), s.mujoco_force_rel.max(), s.ours_moment_rel.max(),
                                       s.mujoco_moment_rel.max())))
    for ax, (ours, mj, label, unit, scale) in zip(axes, rows):
        ax.semilogy(s.time, np.maximum(ours, RESIDUAL_FLOOR), "o-", ms=3, color="tab:blue", label="ours (RNEA)")
        ax.semilogy(s.time, np.maximum(mj, RESIDUAL_FLOOR), "s--", ms=3, color="tab:orange",
                    label="MuJoCo replay (mj_inverse)")
        ax.axhline(tol, color="tab:red", ls=":", lw=1.2, label=f"plausibility tolerance {tol:g}")
        ax.set_ylim(top=top)
        ax.set_title(f"max: ours {ours.max() * scale:.2g} {unit}, MuJoCo {mj.max() * scale:.2g} {unit}",
                     fontsize=8, loc="left")
        ax.set_ylabel(f"root {label}", fontsize=9)
        ax.grid(alpha=0.3, which="major")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=3, fontsize=8, frameon=False)
    axes[-1].set_xlabel("time (s), frames and midpoints" if motion.interpolation == "cubic-spline"
                        else "time (s), interior frames")
    fig.suptitle(f"root residual of the equations of motion: h0 − Σ contact wrenches\n{motion_caption(motion)}",
                 fontsize=10)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    return _png(fig)


# --- filmstrip -----------------------------------------------------------------------------------


def _stick_lines(character, q: np.ndarray) -> np.ndarray:
    """(S, 2, 3, T) each segment with a length as a line from its origin to its tip."""
    from solver.kinematics import segment_frames

    rots, poss = segment_frames(character, q)
    segs = [i for i, s in enumerate(character.segments) if s.length > 0]
    tips = np.stack([poss[i] + np.einsum("ijt,j->it", rots[i], character.segments[i].direction
                                         * character.segments[i].length) for i in segs])
    return np.stack([poss[segs], tips], axis=1)


#: the most frames whose heading and soles the filmstrip's top view draws (a cycle has fewer)
TOP_FRAMES = 240


def filmstrip_figure(motion, *, title: str | None = None, max_frames: int = 16):
    """Side, rear and top views of a motion's cycle. Side and rear: one stick figure per frame,
    side by side (each frame centred on its pelvis), with each foot's sole as the exports draw
    it (filled while the foot is in contact), the ground under it, and each loaded foot's ground
    reaction force as an arrow at its centre of pressure (1 BW = the standing leg length). The
    views are turned so that gravity points down: a slope shows as an inclined ground. Top: the
    cycle in the ground plane — the pelvis path and heading, and the soles of the stance feet."""
    from solver.environment import ground_of
    from solver.kinematics import sole_corners, standing_leg_length
    from solver.motion import FEET, Motion
    from solver.naturalness import path_heading
    from solver.stairs import flight_of

    if not isinstance(motion, Motion):
        raise PlotError(f"expected a motion (solver.motion.Motion), got {type(motion).__name__}")
    ch, q, T = motion.character, motion.q, motion.T
    N = T - 2 if motion.cyclic else T
    frames = np.arange(N) if max_frames >= N else np.unique(np.linspace(0, N - 1, max_frames).round().astype(int))
    env = motion.environment
    g = np.asarray(env.gravity, dtype=float)
    up = -g / max(float(np.linalg.norm(g)), 1e-12)
    path = path_heading(q, N) if motion.cyclic else np.full(T, float(q[3, 0]))

    def display(t: int) -> np.ndarray:
        """World -> display at frame t: x along the direction of travel (⊥ gravity), y to the
        walker's left, z against gravity — each frame seen from the walker's own side."""
        fwd = np.array([math.cos(path[t]), math.sin(path[t]), 0.0])
        ex = fwd - up * (up @ fwd)
        ex /= np.linalg.norm(ex)
        return np.stack([ex, np.cross(up, ex), up])

    Ds = np.stack([display(t) for t in range(T)])  # (T, 3, 3)
    lines = np.einsum("tij,sejt->seit", Ds, _stick_lines(ch, q))
    has_soles = ch.has_soles
    world_soles = sole_corners(ch, q) if has_soles else np.zeros((2, 4, 3, T))  # (2, 4, 3, T)
    soles = np.einsum("tij,kcjt->kcit", Ds, world_soles)
    root = np.einsum("tij,jt->it", Ds, q[:3])
    B = motion.foot_contact() if motion.contacts is not None else np.zeros((2, T), bool)
    W = body_weight(motion)
    leg = standing_leg_length(ch)
    G = ground_of(motion)
    flight = flight_of(motion)  # stairs: the treads and risers the optimizer and the checks used
    arrows = None
    if motion.wrenches is not None:
        from solver.export import ground_reactions

        gr = ground_reactions(motion)
        cop = np.nan_to_num(gr.cop, nan=0.0)
        cop[..., 2] = G
        arrows = (np.einsum("tij,ktj->kti", Ds, cop), np.einsum("tij,ktj->kti", Ds, gr.force) / W * leg, gr.loaded)
    slot = 0.75 * leg
    strip_w = 8.6  # inches
    strip_h = max(0.8, strip_w * 1.4 * leg / (len(frames) * slot + 0.3))
    fig = _figure(strip_w + 3.6, 2 * strip_h + 1.9)
    gs = fig.add_gridspec(2, 3, height_ratios=[1.0, 1.0], width_ratios=[1.0, 1.0, 0.8])
    side, rear, top = fig.add_subplot(gs[0, :2]), fig.add_subplot(gs[1, :2]), fig.add_subplot(gs[:, 2])
    cols = {"right": "tab:red", "left": "tab:blue"}
    names = [s.name for s in ch.segments if s.length > 0]
    def ground_line(ax, t, u, h_off, v_off):
        """The ground under frame t's feet (world z = its height), through the point below the
        pelvis: inclined along the walk in the side view (a slope), level across it (the rear view)."""
        D = Ds[t]
        if flight is not None and u == 0:  # stairs: the treads and risers along the flight, around the pelvis
            s0 = float(flight.along(q[:2, t]))
            lo, hi = s0 - 0.6 * slot, s0 + 0.6 * slot
            pts = []
            for k in range(math.floor(lo / flight.going), math.floor(hi / flight.going) + 1):
                a, b = max(k * flight.going, lo), min((k + 1) * flight.going, hi)
                pts += [(a, k * flight.rise), (b, k * flight.rise)]
            o, dirn = np.asarray(flight.origin), flight.direction
            disp = np.array([D @ np.r_[o + s_ * dirn, z_] for s_, z_ in pts])
            ax.plot(disp[:, 0] + h_off, disp[:, 2] + v_off, color="0.45", lw=0.8)
            return
        tang = D @ np.array([math.cos(path[t]), math.sin(path[t]), 0.0])  # the ground along the walk
        for h in np.unique(np.round(G[:, t], 6)):
            o = D @ np.array([q[0, t], q[1, t], h])
            if u == 0:
                s_ = np.array([-0.6, 0.6]) * slot / tang[0]
                ax.plot(o[0] + s_ * tang[0] + h_off, o[2] + s_ * tang[2] + v_off, color="0.45", lw=0.8)
            else:  # the ground seen along the walk: at the height of the stance feet's soles
                z = soles[B[:, t], :, 2, t].mean() if B[:, t].any() and has_soles else o[2]
                ax.plot(np.array([-0.4, 0.4]) * slot - o[1] + h_off, [z + v_off] * 2, color="0.45", lw=0.8)

    def draw(ax, u, t, h_off, v_off):
        sg = -1.0 if u == 1 else 1.0  # the rear view is seen from behind: the walker's left on the left
        for si, nm in enumerate(names):
            c = "tab:red" if nm.endswith("_r") else "tab:blue" if nm.endswith("_l") else "0.15"
            ax.plot(sg * lines[si, :, u, t] + h_off, lines[si, :, 2, t] + v_off, color=c,
                    lw=2.2 if c == "0.15" else 1.5)
        for k, s in enumerate(FEET):
            c = soles[k][[0, 2, 3, 1, 0]][:, [u, 2], t]
            if B[k, t] and has_soles:
                ax.fill(sg * c[:, 0] + h_off, c[:, 1] + v_off, color=cols[s], alpha=0.45, lw=0)
            if has_soles:
                ax.plot(sg * c[:, 0] + h_off, c[:, 1] + v_off, color=cols[s], lw=0.9)
            if arrows is not None and arrows[2][k, t]:
                p, f = arrows[0][k, t], arrows[1][k, t]
                ax.annotate("", xy=(sg * (p[u] + f[u]) + h_off, p[2] + f[2] + v_off),
                            xytext=(sg * p[u] + h_off, p[2] + v_off),
                            arrowprops={"arrowstyle": "->", "color": cols[s], "lw": 1.1})

    for i, t in enumerate(frames):
        # each frame centred on its pelvis, the ground below the pelvis at height 0
        stance = G[B[:, t], t] if B[:, t].any() else G[:, t]
        v_off = -float((Ds[t] @ np.array([q[0, t], q[1, t], stance.min()]))[2])
        for ax, u in ((side, 0), (rear, 1)):
            h_off = i * slot - (-root[u, t] if u == 1 else root[u, t])
            ground_line(ax, t, u, h_off, v_off)
            draw(ax, u, t, h_off, v_off)
            ax.text(i * slot, -0.12 * leg, f"{t}", ha="center", va="top", fontsize=7, color="0.3")
    # top: pelvis path and heading, soles (stance filled), in the ground plane (world x, y)
    top.plot(q[0, :N + 1], q[1, :N + 1], "-", color="0.15", lw=1.2)
    if flight is not None:  # stairs: each riser's line across the flight
        s_all = flight.along(q[:2, :N + 1])
        o, dirn = np.asarray(flight.origin), flight.direction
        across = np.array([-dirn[1], dirn[0]]) * 0.3
        k0, k1 = (math.floor((v + 0.3 * sg) / flight.going) for v, sg in ((s_all.min(), -1), (s_all.max(), 1)))
        for k in range(k0, k1 + 2):
            c = o + k * flight.going * dirn
            top.plot([c[0] - across[0], c[0] + across[0]], [c[1] - across[1], c[1] + across[1]], color="0.6", lw=0.7)
    sw = world_soles
    # headings and soles: every frame of a cycle, at most TOP_FRAMES of a long motion (each is a matplotlib
    # artist: a 29,000-frame capture drew for minutes)
    top_frames = range(N) if N <= TOP_FRAMES else np.unique(np.linspace(0, N - 1, TOP_FRAMES).round().astype(int))
    for t in top_frames:
        top.annotate("", xy=(q[0, t] + 0.12 * leg * math.cos(q[3, t]), q[1, t] + 0.12 * leg * math.sin(q[3, t])),
                     xytext=(q[0, t], q[1, t]), arrowprops={"arrowstyle": "->", "color": "0.3", "lw": 0.8})
        for k, s in enumerate(FEET if has_soles else ()):
            c = sw[k][[0, 2, 3, 1, 0]][:, :2, t]
            if B[k, t]:
                top.fill(c[:, 0], c[:, 1], color=cols[s], alpha=0.25, lw=0)
            else:
                top.plot(c[:, 0], c[:, 1], color=cols[s], lw=0.5, alpha=0.5)
    side.set_title("side: frames side by side, each seen across its direction of travel, gravity down; stance "
                   "soles filled; arrows: ground force (1 BW = leg length)", fontsize=8, loc="left")
    rear.set_title("rear: from behind the walker (left foot blue, on the left)", fontsize=8, loc="left")
    top.set_title("top: pelvis path and heading,\nstance soles filled", fontsize=8, loc="left")
    for ax in (side, rear):
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.2)
    top.set_aspect("equal")
    top.tick_params(labelsize=7)
    top.grid(alpha=0.2)
    fig.suptitle((title + "\n" if title else "") + motion_caption(motion), fontsize=10)
    fig.tight_layout()
    return fig


def filmstrip_png(motion, *, title: str | None = None) -> bytes:
    """:func:`filmstrip_figure` as PNG bytes."""
    return _png(filmstrip_figure(motion, title=title))


#: the motion plots by kind (``motionx plot --kind``, ``GET /motions/{id}/plots/{kind}.png``)
MOTION_PLOTS = {"grf": grf_png, "residuals": residuals_png, "filmstrip": filmstrip_png}
