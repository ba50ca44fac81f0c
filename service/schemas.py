"""Request and response models (pydantic v2). Floats must be finite everywhere."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, computed_field, create_model, model_validator

from service.limits import MAX_TUTOR_FPS, MAX_TUTOR_FRAMES, MAX_TUTOR_S, MIN_TUTOR_FPS
from service.simulation import DEFAULT_CYCLES as DEFAULT_SIM_CYCLES
from service.simulation import MAX_CYCLES as MAX_SIM_CYCLES
from service.simulation import MIN_CYCLES as MIN_SIM_CYCLES
from solver import axes as registry
from solver.continuation import StepControl
from solver.status import Status

_SC = StepControl()

MotionKind = Literal["capture", "motion", "tutor", "step"]


class Strict(BaseModel):
    """Request bodies: unknown fields refused, numbers finite and strict (``true`` or ``"5"`` is not a number)."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=True)


def _bounds(ax: registry.Axis) -> dict[str, float]:
    """pydantic bounds of an axis (the registry's, solver.axes)."""
    return {"gt" if ax.lo_open else "ge": ax.lo, "lt" if ax.hi_open else "le": ax.hi}


def _changes_something(schema: dict) -> None:
    schema["anyOf"] = [
        {"required": [ax.name], "properties": {ax.name: {"type": "number"} if ax.default is None
                                               else {"not": {"const": ax.default}}}}
        for ax in registry.axes()
    ]


class _TargetBase(Strict):
    """The target environment reached at λ = 1; fields combine (at least one must change).
    One field per homotopy axis of the solver's registry (solver.axes)."""

    model_config = ConfigDict(json_schema_extra=_changes_something)

    @model_validator(mode="after")
    def _not_identity(self) -> _TargetBase:
        if not any(ax.changes(getattr(self, ax.name)) for ax in registry.axes()):
            raise ValueError("the target changes nothing: give " + ", ".join(registry.names()))
        return self


def _target_field(ax: registry.Axis) -> tuple[Any, Any]:
    if ax.default is None:
        return (float | None, Field(None, description=ax.doc, **_bounds(ax)))
    return (float, Field(float(ax.default), description=ax.doc, **_bounds(ax)))


TargetIn = create_model("TargetIn", __base__=_TargetBase, __doc__=_TargetBase.__doc__,  # type: ignore[call-overload]
                        **{ax.name: _target_field(ax) for ax in registry.axes()})


class StepControlIn(Strict):
    """Step control of the continuation (docs/method.md (M6))."""

    method: Literal["adaptive", "thesis"] = _SC.method  # type: ignore[assignment]
    delta0: float = Field(_SC.delta0, gt=0.0, le=1.0, description="first λ step Δ0")
    max_iter: int = Field(_SC.max_iter, ge=1, le=100_000, description="solver iterations allowed per step (k)")
    eps: float = Field(_SC.eps, gt=0.0, le=1.0, description="smallest step before an impasse (ε)")
    max_solves: int = Field(_SC.max_solves, ge=1, le=100_000)

    @model_validator(mode="after")
    def _eps(self) -> StepControlIn:
        if self.eps > self.delta0:
            raise ValueError("eps must not exceed delta0")
        return self


class TutorIn(Strict):
    """How the tutor is made when the source motion is a raw capture."""

    character: Literal["fullbody", "halfboy"] | None = Field(
        None, description="synthesis character (default: the service's, the full body unless its "
                          "MOTIONX_DEFAULT_CHARACTER says otherwise): fullbody keeps the subject's gait, halfboy is "
                          "the thesis's (legs, with the trunk, head and arms welded to the pelvis), faster")
    fps: float | None = Field(None, ge=MIN_TUTOR_FPS, le=MAX_TUTOR_FPS,
                              description="frame rate of the tutor (one gait cycle of at most "
                                          f"{MAX_TUTOR_FRAMES} frames and {MAX_TUTOR_S:g} s; default: 30 for the full "
                                          "body, 15 for HalfBoy), adjusted so that the cycle's frames span the "
                                          "subject's own period")


class ExtrapolateIn(Strict):
    target: TargetIn
    control: StepControlIn = Field(default_factory=StepControlIn)
    tutor: TutorIn = Field(default_factory=TutorIn)
    simulate_cycles: int = Field(0, ge=0, le=MAX_SIM_CYCLES,
                                 description="after the job, simulate its final motion in MuJoCo for this many gait "
                                             "cycles (0: no simulation); the job's links then name the simulation")


class SimulationIn(Strict):
    cycles: int = Field(DEFAULT_SIM_CYCLES, ge=MIN_SIM_CYCLES, le=MAX_SIM_CYCLES,
                        description="gait cycles to simulate (the simulation stops early when the character falls)")


class SimulationOut(BaseModel):
    id: str
    motion_id: str
    job_id: str
    cycles: int
    status: Literal["queued", "running", "succeeded", "failed", "canceled"]
    terminal: bool
    message: str
    report: dict[str, Any] | None = Field(
        None, description="when succeeded: report.json (cycles_walked, fell, fall, joint_tracking_rms_deg, "
                          "foot_force_rms_bw, peak_torque_ratio_max, drift_per_cycle, realtime_factor, start, "
                          "agreement; resync: each cycle from the reference state with a penalized root residual: "
                          "cycles, completed, residual_root_wrench_rms_bw, ...)")
    files: dict[str, int] = Field(default_factory=dict, description="stored files and their sizes (bytes)")
    created_at: str
    started_at: str | None
    finished_at: str | None
    links: dict[str, str]


class MotionOut(BaseModel):
    id: str
    kind: MotionKind
    name: str
    character: str
    coordinates: int
    frames: int
    fps: float
    duration_s: float
    has_wrenches: bool
    job_id: str | None = None
    step: int | None = None
    lam: float | None = None
    parent_id: str | None = None
    plausible: bool | None = None
    created_at: str
    links: dict[str, str]
    input: dict[str, Any] | None = Field(
        None, description="uploaded trials only: what the input looks like (solver.io.summary.describe) — mass, "
                          "the mass the force plates imply and a warning when they disagree, fit errors, stance "
                          "intervals per foot")


class ExportChoices(BaseModel):
    """What a motion can be downloaded as (solver.export.export_choices): one entry per distinct file."""

    formats: list[str] = Field(description="the formats of GET /motions/{id}?format= that write this motion (glb, "
                                           "the same file as gltf, left out; deepmimic only for a motion made from a "
                                           "DeepMimic clip, opensim only for one made from an OpenSim trial — any "
                                           "other motion with model=generic)")
    on_rig: list[str] = Field(description="the formats that write it on the input's own skeleton (rig=source)")
    rig: str | None = Field(description="the format of the input's own skeleton the motion carries, or null")
    source: str | None = Field(description="the format of the trial the motion was made from, or null")


class ProgressPoint(BaseModel):
    seq: int
    phase: Literal["tutor", "extrapolate"]
    wall_time: float
    lam: float
    lam_reached: float
    environment: dict[str, Any]
    iterations: int
    accepted: bool
    status: str


class _Finished(BaseModel):
    """A job's or a library's answer: its status, and whether it is final."""

    status: Status

    @computed_field(description="the status will not change any more (succeeded, impasse, canceled or failed)")
    @property
    def terminal(self) -> bool:
        return self.status.terminal


class JobOut(_Finished):
    id: str
    status: Status
    motion_id: str
    tutor_motion_id: str | None
    target: dict[str, Any]
    control: dict[str, Any]
    lam_reached: float
    steps: int
    solves: int
    attempts: int
    max_attempts: int
    cancel_requested: bool
    message: str
    runner: str
    created_at: str
    started_at: str | None
    finished_at: str | None
    progress: list[ProgressPoint]
    links: dict[str, str]


class Page(BaseModel):
    total: int
    limit: int
    next: str | None


class MotionPage(Page):
    items: list[MotionOut]


class JobPage(Page):
    items: list[JobOut]


class Problem(BaseModel):
    """RFC 9457 problem details."""

    type: str = "about:blank"
    title: str
    status: int
    detail: str
    instance: str | None = None
    errors: list[dict[str, Any]] | None = None
    quota: str | None = Field(None, description="on a 429: the quota the key is over (heavy_requests, jobs, "
                              "simulations, storage)")


class Health(BaseModel):
    status: Literal["ok", "degraded"]
    database: str
    runner: str
    broker: str | None = None
    compute: str | None = None
    schema_revision: str | None = None
    saturation: dict[str, Any] | None = Field(
        None, description="how busy the service is: compute processes, heavy requests running and waiting, "
        "keys with heavy requests; jobs queued, dispatched and running, job slots and per-key turns")


class Usage(BaseModel):
    """A key's usage next to its quotas (docs/service.md, "Sharing the service")."""

    storage_bytes: int
    storage_limit_bytes: int
    jobs_in_flight: int
    jobs_limit: int
    simulations_in_flight: int
    simulations_limit: int
    heavy_requests_limit: int


# --- libraries ---------------------------------------------------------------------------------

def _grid_field(ax: registry.Axis) -> tuple[Any, Any]:
    values = list[Annotated[float, Field(**_bounds(ax))]]  # type: ignore[misc]
    return (values | None, Field(None, min_length=1, max_length=25, description=ax.doc))


_GRID_AXES = [ax for ax in registry.axes() if ax.grid]
#: Axes of a library grid: every combination of the values is a cell (at most 125 cells).
GridIn = create_model("GridIn", __base__=Strict,  # type: ignore[call-overload]
                      __doc__="Axes of a library grid: every combination of the values is a cell (at most 125 cells).",
                      **{ax.name: _grid_field(ax) for ax in _GRID_AXES})
LibraryTargetIn = create_model("LibraryTargetIn", __base__=Strict,  # type: ignore[call-overload]
                               **{ax.name: (float | None, Field(None, description=ax.doc, **_bounds(ax)))
                                  for ax in _GRID_AXES})


def _grid_or_targets(schema: dict) -> None:
    for k in ("grid", "targets"):  # present means not null
        prop = schema["properties"][k]
        if "anyOf" in prop:
            (only,) = [x for x in prop.pop("anyOf") if x.get("type") != "null"]
            prop.update(only)
        prop.pop("default", None)
    schema["oneOf"] = [{"required": ["grid"], "not": {"required": ["targets"]}},
                       {"required": ["targets"], "not": {"required": ["grid"]}}]


class LibraryIn(Strict):
    """A motion library: a ``grid`` or an explicit list of ``targets`` (exactly one of them)."""

    model_config = ConfigDict(json_schema_extra=_grid_or_targets)

    grid: GridIn | None = None
    targets: list[LibraryTargetIn] | None = Field(None, min_length=1, max_length=125)
    control: StepControlIn = Field(default_factory=StepControlIn)
    tutor: TutorIn = Field(default_factory=TutorIn)

    @model_validator(mode="after")
    def _one(self) -> LibraryIn:
        given = self.model_fields_set & {"grid", "targets"}
        if len(given) != 1 or (self.grid is None and self.targets is None):
            raise ValueError("give either grid or targets (one of them, not null)")
        return self


class LibraryCellOut(BaseModel):
    key: str
    clip_motion_id: str | None = Field(description="the cell's clip: its last realistic λ optimum")
    clip_lam: float | None
    plausible: bool | None = Field(description="the clip's plausibility verdict (null: not checked)")
    parameters: dict[str, float]
    job_id: str
    status: Status
    at_impasse: bool
    lam_reached: float
    steps: int
    solves: int
    attempts: int
    message: str
    started_at: str | None
    finished_at: str | None
    wall_time_s: float | None
    links: dict[str, str]


class LibraryProgress(BaseModel):
    cells: int
    done: int
    fraction: float = Field(description="mean over cells of λ reached (1 for a finished cell)")
    queued: int
    running: int
    succeeded: int
    failed: int
    canceled: int
    impasse: int


class LibraryOut(_Finished):
    id: str
    status: Status
    motion_id: str
    axes: list[str]
    grid: dict[str, Any] | None
    targets: list[dict[str, Any]] | None
    control: dict[str, Any]
    cancel_requested: bool
    created_at: str
    finished_at: str | None
    progress: LibraryProgress
    cells: list[LibraryCellOut]
    links: dict[str, str]


class LibraryPage(Page):
    items: list[LibraryOut]
