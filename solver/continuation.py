"""Extrapolation by continuation in λ ∈ [0, 1] (docs/method.md (M6), Algorithm 3 and beyond).

Types are frozen values; progress is reported through callbacks so the CLI, a worker or
a test can consume it (crocoddyl's CallbackLogger / mujoco's IterLog habit).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from solver import native
from solver.axes import Target, environment_at, guide_at, nlp_at
from solver.axes.terrain import stairs_base, stairs_target
from solver.environment import Environment
from solver.jsonable import jsonable
from solver.motion import GaitReference, Motion
from solver.naturalness import motion_figures
from solver.outputs import progress_csv, step_stem
from solver.spacetime import ProblemData, SolveResult, SolverOptions, SpacetimeProblem, WarmStart, Weights
from solver.stairs import flight_for
from solver.status import Status

__all__ = ["CancelCheck", "ExtrapolationResult", "ProgressCallback", "ProgressRecord", "StepCallback", "StepControl",
           "StepResult", "Target", "environment_at", "extrapolate", "guide_at", "motion_at", "needs_rising", "nlp_at",
           "tutor_heading_change"]


@dataclass(frozen=True)
class StepControl:
    """Step control of the homotopy walk.

    method "thesis" (default): Algorithm 3 (double on success, halve on failure, stop when Δ < ε),
        each solve from the previous optimum's deviation on the new guide (primal only).
    method "adaptive": step from the recent history of accepted steps, secant predictor
        from the last two optima, warm-started multipliers.

    The default is the thesis's controller: with the realistic transcription it was faster on
    the timed targets and reached as far or further on most reach targets
    (docs/continuation.md, "Step control").
    """

    method: str = "thesis"
    delta0: float = 0.05
    predictor: str = "secant"  # adaptive: "secant" (from the last two optima) or "previous"
    growth: float = 4.0  # adaptive: step growth after an easy step (no more iterations than usual)
    #: adaptive: warm-start IPOPT's multipliers too — "small" (only when the step does not
    #: grow: interior-point warm starts pay off when the active set barely changes and cost
    #: iterations after large steps), "always", "never", or "fallback" (a warm attempt with
    #: ``warm_budget`` iterations, then a cold restart at the same λ). Measured: docs/continuation.md
    warm_multipliers: str = "small"
    warm_budget: int = 12  # IPOPT iterations allowed to a warm attempt before the cold restart
    #: adaptive: initial barrier parameter for restarts (monotone strategy); None keeps IPOPT's
    #: adaptive strategy, which measured fewer iterations here
    restart_mu: float | None = None
    max_iter: int = 200  # k: solver iterations allowed per step
    eps: float = 0.005  # smallest step before declaring an impasse
    max_solves: int = 400

    def __post_init__(self) -> None:
        if self.method not in ("adaptive", "thesis"):
            raise ValueError("method must be 'adaptive' or 'thesis'")
        if self.predictor not in ("secant", "previous"):
            raise ValueError("predictor must be 'secant' or 'previous'")
        if self.warm_multipliers not in ("fallback", "always", "never", "small"):
            raise ValueError("warm_multipliers must be 'fallback', 'always', 'never' or 'small'")
        if not (0 < self.eps <= self.delta0 <= 1):
            raise ValueError("need 0 < eps <= delta0 <= 1")
        if self.max_iter < 1 or self.max_solves < 1:
            raise ValueError("max_iter and max_solves must be >= 1")

    def summary(self) -> dict[str, Any]:
        """The settings a summary or a manifest records."""
        return {"method": self.method, "delta0": self.delta0, "eps": self.eps, "max_iter": self.max_iter,
                "max_solves": self.max_solves}


@dataclass(frozen=True)
class ProgressRecord:
    """One solve of the continuation, accepted or not."""

    wall_time: float  # s since the start of the extrapolation
    lam: float  # λ tried
    environment: Mapping[str, float]  # every registered axis's value at that λ (solver.axes)
    iterations: int
    accepted: bool
    status: str  # solver status text
    lam_reached: float


@dataclass(frozen=True)
class StepResult:
    """An accepted λ: a plausible motion of the continuum."""

    step: int  # 0 = the base problem (λ = 0), then 1, 2, ...
    lam: float
    motion: Motion
    stats: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class ExtrapolationResult:
    """A walk in λ: every accepted optimum (``steps``), every solve (``records``) and how it
    ended (``status``: succeeded, impasse, canceled or failed)."""

    status: Status
    lam_reached: float
    steps: tuple[StepResult, ...]
    records: tuple[ProgressRecord, ...]
    solves: int
    wall_time: float
    message: str = ""
    target: Target | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "status", Status(self.status))

    def summary(self) -> dict[str, Any]:
        """What the walk reached, as ``summary.json`` holds it."""
        return {"status": str(self.status), "lambda_reached": round(self.lam_reached, 9), "message": self.message,
                "target": self.target.to_dict() if self.target is not None else None,
                "solves": self.solves, "accepted": len(self.steps), "wall_time_s": round(self.wall_time, 3),
                "motions": [f"{step_stem(s.step, s.lam)}.motion.json" for s in self.steps]}

    def save(self, folder: str | Path) -> Path:
        """Write every optimum as ``step_NNN_lambda_L.motion.json``, ``progress.csv`` and
        ``summary.json`` into ``folder`` (created when missing)."""
        out = Path(folder)
        out.mkdir(parents=True, exist_ok=True)
        for s in self.steps:
            s.motion.save(out / f"{step_stem(s.step, s.lam)}.motion.json")
        (out / "progress.csv").write_text(progress_csv(asdict(r) for r in self.records))
        (out / "summary.json").write_text(json.dumps(self.summary(), indent=2, allow_nan=False))
        return out


ProgressCallback = Callable[[ProgressRecord], None]
StepCallback = Callable[[StepResult], None]
CancelCheck = Callable[[], bool]


# --- homotopy: the problem at λ (solver.axes: environment_at, guide_at, nlp_at) ---------------


@dataclass
class _State:
    lam: float
    res: SolveResult


def _is_tutor(motion: Motion) -> None:
    if motion.wrenches is None or motion.contacts is None:
        raise ValueError("extrapolation needs a tutor: a plausible motion with contact wrenches and a contact schedule "
                         "(run the tutor pipeline first)")


def gait_reference(tutor: Motion) -> GaitReference:
    """What a λ optimum's naturalness is judged against besides the published limits: the
    captured walk's figures (recorded in the tutor) and the tutor's own."""
    ref = tutor.context.gait_reference or GaitReference()
    if tutor.contacts is None or not tutor.character.has_soles:
        return GaitReference(ref.capture, None, ref.fit)
    return GaitReference(ref.capture, jsonable(motion_figures(tutor)), ref.fit)


def _motion(tutor: Motion, lam: float, target: Target, env: Environment, values: Mapping[str, float],
            res: SolveResult, control: StepControl, step: int, fps: float,
            reference: GaitReference | None = None) -> Motion:
    from solver.plausibility import report

    prov = {
        "step": "extrapolate",
        "source": tutor.provenance.get("source"),
        "lambda": float(lam),
        "target": target.to_dict(),
        "continuation": {"method": control.method, "step": step},
        "solver": res.solver_record(time_s=round(res.wall_time, 6), marker_rms_to_guide_mm=1e3 * res.marker_rms),
    }
    ctx = tutor.context.with_(
        environment=env, axis_values=dict(values), heading_change_deg=math.degrees(res.heading_change),
        tutor_heading_change_deg=math.degrees(tutor_heading_change(tutor)),
        heading_change_requested_deg=None,
        gait_reference=reference if reference is not None else gait_reference(tutor))
    m = Motion(tutor.character, fps, res.q, contacts=tutor.contacts, wrenches=res.wrenches, provenance=prov,
               context=ctx, interpolation="cubic-spline", cyclic=True)
    return m.evolve(report=report(m))


def tutor_heading_change(tutor: Motion) -> float:
    """The tutor's heading change over its cycle (rad), as its optimizer imposed it."""
    deg = tutor.context.heading_change_deg
    if deg is not None:
        return math.radians(deg)
    return float(tutor.q[3, -2] - tutor.q[3, 0])


def _predict(history: list[_State], lam_try: float, secant: bool,
             guide: Callable[[float], np.ndarray]) -> WarmStart:
    """Initial motion at λ_try: the new guide plus the previous optimum's deviation from its
    own guide (the guide carries the bend and tilt of the homotopy; the deviation carries what
    the physics added), extrapolated along the secant of the last two deviations."""
    b = history[-1]
    dev_b = b.res.q - guide(b.lam)
    if not secant or len(history) < 2:
        return WarmStart(guide(lam_try) + dev_b, b.res.wrenches)
    a = history[-2]
    s = (lam_try - b.lam) / (b.lam - a.lam)
    dev_a = a.res.q - guide(a.lam)
    wa, wb = a.res.wrenches, b.res.wrenches
    return WarmStart(guide(lam_try) + dev_b + s * (dev_b - dev_a),
                     wb if wa is None or wb is None else wb + s * (wb - wa))


class _Walk:
    """One walk along the homotopy; holds the records, the accepted steps and the counters."""

    def __init__(self, tutor: Motion, target: Target, control: StepControl, prob: SpacetimeProblem,
                 on_progress: ProgressCallback | None, on_step: StepCallback | None,
                 should_cancel: CancelCheck | None, weights: Weights = Weights()) -> None:
        self.tutor, self.target, self.control, self.prob = tutor, target, control, prob
        self.weights = weights
        self.on_progress, self.on_step, self.should_cancel = on_progress, on_step, should_cancel
        self.env0 = tutor.environment
        if target.step_height_m:  # the going starts from the walker's own step
            self.env0 = stairs_base(self.env0, tutor.q, tutor.foot_contact())
        self.t0 = time.perf_counter()
        self.records: list[ProgressRecord] = []
        self.steps: list[StepResult] = []
        self.solves = 0
        self.dpsi0 = tutor_heading_change(tutor)
        self._guides: dict[float, np.ndarray] = {}
        self.reference = gait_reference(tutor)

    def guide(self, lam: float) -> np.ndarray:
        g = self._guides.get(lam)
        if g is None:
            if len(self._guides) > 8:
                self._guides.pop(next(iter(self._guides)))
            g = self._guides[lam] = guide_at(self.tutor.q, self.target, lam, self.env0)
        return g

    def record(self, lam: float, values: Mapping[str, float], res: SolveResult | None, accepted: bool, status: str,
               reached: float) -> None:
        rec = ProgressRecord(time.perf_counter() - self.t0, float(lam), dict(values),
                             -1 if res is None else res.iterations, accepted, status, float(reached))
        self.records.append(rec)
        if self.on_progress:
            self.on_progress(rec)

    def nlp(self, lam: float) -> dict[str, float]:
        return nlp_at(self.target, lam, self.env0)

    def fps(self, lam: float) -> float:
        """The frame rate at λ: the frame count is fixed, the frame interval follows the axes."""
        return self.tutor.fps / self.nlp(lam)["frame_interval"]

    def accept(self, lam: float, env: Environment, values: Mapping[str, float], res: SolveResult) -> str:
        """"" when the optimum is kept (plausible and natural), else why not ("implausible",
        "unnatural: CHECK, …")."""
        m = _motion(self.tutor, lam, self.target, env, values, res, self.control, len(self.steps), self.fps(lam),
                    self.reference)
        if m.report is None or not m.report["plausible"]:
            return "implausible"
        if m.report.get("natural") is False:
            return "unnatural: " + ", ".join((m.report.get("naturalness") or {}).get("failed") or [])
        sr = StepResult(len(self.steps), float(lam), m, {"iterations": res.iterations, "solve_s": res.wall_time,
                                                          "status": res.status, "marker_rms_mm": 1e3 * res.marker_rms})
        self.steps.append(sr)
        if self.on_step:
            self.on_step(sr)
        return ""

    def finish(self, status: str, lam: float, message: str = "") -> ExtrapolationResult:
        return ExtrapolationResult(Status(status), float(lam), tuple(self.steps), tuple(self.records), self.solves,
                                   time.perf_counter() - self.t0, message, self.target)

    def solve(self, lam: float, start: WarmStart, max_iter: int, guide: np.ndarray | None = None,
              restart_mu: float | None = None) -> tuple[SolveResult | None, bool, str, Environment, dict]:
        env, values = environment_at(self.env0, self.target, lam)
        if guide is None:
            guide = self.guide(lam)
        if env.step_height_m:  # the flight stands under the start iterate's stance feet
            flight = flight_for(self.tutor.character, start.q, self.tutor.foot_contact(), env.with_(stairs_at=None))
            env = env.with_(stairs_at=flight.at if flight is not None else None)
        opts: dict[str, Any] = {}
        if restart_mu is not None:  # mu_init only acts with the monotone barrier strategy
            opts = {"ipopt.mu_strategy": "monotone", "ipopt.mu_init": restart_mu}
            if not start.warm:
                opts.update({"ipopt.bound_push": 1e-6, "ipopt.bound_frac": 1e-6})
        try:
            eff = self.nlp(lam)
            dpsi = self.dpsi0 + math.radians(eff["heading_change_deg"])
            data = ProblemData(guide, env=env, weights=self.weights, heading_change=dpsi,
                               frame_interval=self.prob.dt * eff["frame_interval"])
            res = self.prob.solve(data, start, SolverOptions(max_iter, opts, self.should_cancel))
        except RuntimeError as e:  # a numerical failure inside the solver is a status, not a crash
            self.solves += 1
            return None, False, f"error: {e}", env, values
        self.solves += 1
        ok = res.success and bool(np.all(np.isfinite(res.q)))
        return res, ok, res.status, env, values

    def base(self) -> _State | None:
        """The base problem (λ = 0): guide = tutor. A tutor made by this transcription (a cyclic
        cubic-spline motion whose report says plausible) is its own optimum up to the weak
        priors and is taken as it is; an older tutor is re-solved from itself."""
        tut = self.tutor
        if (tut.interpolation == "cubic-spline" and tut.cyclic and tut.report is not None
                and tut.report.get("plausible")):
            env, values = environment_at(self.env0, self.target, 0.0)
            res = SolveResult(True, "tutor", 0, 0.0, tut.q, tut.wrenches, math.nan, 0.0, None, None, 0.0,
                              heading_change=self.dpsi0)
            why = self.accept(0.0, env, values, res)
            self.record(0.0, values, res, not why, "tutor" if not why else f"tutor {why}", 0.0)
            if not why:
                return _State(0.0, res)
        solved, ok, status, env, values = self.solve(0.0, WarmStart(tut.q, tut.wrenches),
                                                     max(self.control.max_iter, 500), guide=tut.q)
        why = "" if not ok or solved is None else self.accept(0.0, env, values, solved)
        ok = ok and solved is not None and not why
        self.record(0.0, values, solved, ok, why or status, 0.0)
        return _State(0.0, solved) if ok and solved is not None else None

    def run(self, history: list[_State], lam_end: float) -> ExtrapolationResult:
        c = self.control
        adaptive = c.method == "adaptive"
        lam, delta = history[-1].lam, c.delta0
        cap = math.inf  # adaptive: stay below recently failed step sizes
        last_step = 0.0  # size of the last accepted step
        iters: list[int] = []  # adaptive: iterations of accepted steps (the difficulty history)
        while lam < lam_end - 1e-12:
            if self.should_cancel is not None and self.should_cancel():
                return self.finish("canceled", lam, "canceled")
            if self.solves >= c.max_solves:
                return self.finish("impasse", lam, f"solve budget exhausted ({c.max_solves} solves)")
            delta = min(delta, lam_end - lam)
            lam_try = lam_end if lam_end - (lam + delta) < 1e-9 else lam + delta
            init = _predict(history, lam_try, adaptive and c.predictor == "secant", self.guide)
            # the thesis's baseline restarts from the previous optimum (primal only);
            # the adaptive controller may also warm-start the multipliers
            growing = delta > last_step * (1 + 1e-9)
            mode = c.warm_multipliers if adaptive else "never"
            if mode == "fallback":
                res, ok, status, env, values = self.solve(lam_try, init.with_multipliers(history[-1].res),
                                                          min(c.warm_budget, c.max_iter), restart_mu=c.restart_mu)
                if not ok:  # cold restart at the same λ (the warm attempt is recorded as rejected)
                    self.record(lam_try, values, res, False, f"warm attempt: {status}", lam)
                    res, ok, status, env, values = self.solve(lam_try, init, c.max_iter, restart_mu=c.restart_mu)
            else:
                use_warm = mode == "always" or (mode == "small" and not growing)
                start = init.with_multipliers(history[-1].res) if use_warm else init
                res, ok, status, env, values = self.solve(lam_try, start, c.max_iter,
                                                          restart_mu=c.restart_mu if adaptive else None)
            why = self.accept(lam_try, env, values, res) if ok else ""  # type: ignore[arg-type]
            if ok and not why:
                self.record(lam_try, values, res, True, status, lam_try)
                step = lam_try - lam
                last_step = step
                lam = lam_try
                history = (history + [_State(lam, res)])[-3:]  # type: ignore[arg-type]
                if adaptive:
                    it = max(res.iterations, 1)  # type: ignore[union-attr]
                    ref = float(np.median(iters)) if iters else it
                    iters.append(it)
                    # easy step (no harder than usual): quadruple; harder: grow less or shrink
                    factor = (c.growth if it <= 1.25 * ref else 2.0 if it <= 2 * ref
                              else 1.0 if it <= 3 * ref else 0.5)
                    delta = min(step * factor, cap)
                    cap *= 1.5  # forget old failures gradually
                else:
                    delta = 2.0 * delta
            else:
                self.record(lam_try, values, res, False, why or status, lam)
                if adaptive:
                    cap = 0.9 * delta  # do not retry this size right after success (the thesis does)
                delta /= 2.0
                if delta < c.eps:
                    if self.should_cancel is not None and self.should_cancel():  # a solve stopped by a cancel
                        return self.finish("canceled", lam, "canceled")
                    return self.finish("impasse", lam,
                                       f"impasse: no step of at least ε = {c.eps} converges from λ = {lam:.4f}")
        return self.finish("succeeded", lam)


def needs_rising(target: Target) -> bool:
    """Stairs: root z gains a rise over the cycle, a problem of its own structure
    (``SpacetimeProblem(..., rising=True)``). One rule for whoever builds the problem."""
    return bool(target.step_height_m)


def extrapolate(
    tutor: Motion,
    target: Target,
    control: StepControl = StepControl(),
    *,
    on_progress: ProgressCallback | None = None,
    on_step: StepCallback | None = None,
    should_cancel: CancelCheck | None = None,
    problem: SpacetimeProblem | None = None,
    lam_end: float = 1.0,
    start: tuple[float, Motion] | None = None,
    weights: Weights = Weights(),
) -> ExtrapolationResult:
    """Walk the homotopy from the base problem (λ = 0, solved by the tutor) to the target.

    Every accepted λ is a plausible motion (``on_step``); every solve, accepted or not, is a
    progress record (``on_progress``). An impasse (Δ < ε) and a cancellation are results.
    ``start=(λ0, optimum)`` continues the same homotopy from a stored optimum instead of
    solving the base problem; ``lam_end`` stops the walk early; ``weights``: the NLP's cost
    weights (those the tutor was made with, by default the same defaults).
    """
    from solver.pipeline import problem_for

    native.ensure()
    _is_tutor(tutor)
    target = stairs_target(target)  # stairs: the default going when the target gives none
    if not 0.0 < lam_end <= 1.0:
        raise ValueError("lam_end must be in (0, 1]")
    rising = needs_rising(target)
    if problem is not None and problem.rising != rising:
        raise ValueError(f"the problem given was built with rising={problem.rising}, the target needs "
                         f"rising={rising} (continuation.needs_rising)")
    prob = problem or problem_for(tutor.character, tutor.T, tutor.fps, tutor.contacts, rising=rising)
    walk = _Walk(tutor, target, control, prob, on_progress, on_step, should_cancel, weights)
    if start is not None:
        lam0, m0 = start
        if not 0.0 <= lam0 < lam_end:
            raise ValueError("the start λ must lie in [0, lam_end)")
        stored = SolveResult(True, "stored", 0, 0.0, m0.q, m0.wrenches, math.nan, math.nan,
                             None, None, 0.0)
        return walk.run([_State(lam0, stored)], lam_end)
    base = walk.base()
    if base is None:
        if should_cancel is not None and should_cancel():
            return walk.finish("canceled", 0.0, "canceled")
        return walk.finish("failed", 0.0, "the base problem did not converge to a plausible motion")
    return walk.run([base], lam_end)


def motion_at(
    tutor: Motion,
    target: Target,
    lam: float,
    steps: Sequence[StepResult],
    control: StepControl = StepControl(),
    *,
    exact: bool = False,
) -> Motion:
    """A motion for any λ in [0, λ_reached]: the nearest stored optimum, or (``exact``) the
    optimum at λ itself, walked on the same homotopy from the stored optimum just below."""
    if not steps:
        raise ValueError("no stored optimum")
    reached = max(s.lam for s in steps)
    if not 0.0 <= lam <= reached + 1e-12:
        raise ValueError(f"λ = {lam} is outside [0, {reached}] (the range reached)")
    nearest = min(steps, key=lambda s: abs(s.lam - lam))
    if not exact or abs(nearest.lam - lam) < 1e-12:
        return nearest.motion
    below = max((s for s in steps if s.lam <= lam), key=lambda s: s.lam)
    res = extrapolate(tutor, target, control, start=(below.lam, below.motion), lam_end=lam)
    if res.status != "succeeded":
        raise RuntimeError(f"could not reach λ = {lam} from the stored λ = {below.lam}: {res.message}")
    return res.steps[-1].motion
