"""Service configuration: one pydantic-settings model, read through :func:`get_settings`.

Nothing here runs at import time: ``get_settings()`` reads the environment when called
(and caches the result per process; ``get_settings.cache_clear()`` re-reads it). The API
takes its settings through a FastAPI dependency, so tests override them
(``app.dependency_overrides[get_settings] = ...``) or pass them to ``create_app``.

Environment variables are prefixed ``MOTIONX_`` (e.g. ``MOTIONX_RUNNER=celery``); the
database also answers to ``DATABASE_URL`` and the broker to ``REDIS_URL``.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
from collections.abc import Mapping
from functools import lru_cache
from pathlib import Path
from typing import Any, Literal

from pydantic import AliasChoices, Field, field_validator, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from solver.native import default_cache_dir


def _default_data_dir() -> Path:
    return Path.home() / ".local" / "share" / "motionx"


def _machine_processes() -> int:
    """One compute process per core, 2 to 8."""
    return min(8, max(2, os.cpu_count() or 2))


#: the runners' names (service.runners.RUNNERS maps each to its class; a test checks they agree)
RUNNER_NAMES = ("local", "celery")
RunnerName = Literal[RUNNER_NAMES]  # type: ignore[valid-type]

class Settings(BaseSettings):
    model_config = SettingsConfigDict(env_prefix="MOTIONX_", extra="ignore", frozen=True)

    # --- storage ---------------------------------------------------------------------
    data_dir: Path = Field(default_factory=_default_data_dir, description="where the default SQLite file lives")
    database_url: str | None = Field(
        default=None,
        validation_alias=AliasChoices("MOTIONX_DATABASE_URL", "DATABASE_URL", "database_url"),
        description="SQLAlchemy URL; default sqlite:///<data_dir>/motionx.db (WAL). "
        "postgresql://... is mapped to the psycopg 3 driver.",
    )
    auto_migrate: bool = Field(True, description="`motionx serve` upgrades the schema (Alembic) on start")

    # --- runner ----------------------------------------------------------------------
    runner: RunnerName = "local"
    local_workers: int = Field(2, ge=1, le=64, description="process-pool size of the LocalRunner")

    # --- Celery / Redis --------------------------------------------------------------
    broker_url: str = Field(
        "redis://127.0.0.1:6379/0",
        validation_alias=AliasChoices("MOTIONX_BROKER_URL", "REDIS_URL", "broker_url"),
    )
    result_backend: str | None = Field(None, description="results live in SQL; a Celery result backend is optional")
    celery_queue: str = "motionx"
    job_time_limit_s: float = Field(3600.0, gt=0, description="a job running longer is stopped and marked failed")
    visibility_timeout_s: int = Field(
        7200, gt=0, description="Redis redelivers an unacknowledged job after this; must exceed job_time_limit_s"
    )
    unacked_restore_interval_s: int = Field(10, ge=1, description="kombu: seconds between unacked-restore sweeps")
    unacked_restore_throttle: int = Field(10, ge=1, description="kombu: scan Redis on every Nth sweep")
    worker_concurrency: int = Field(1, ge=1, le=64, description="pool processes per `motionx worker`")

    # --- jobs ------------------------------------------------------------------------
    job_max_attempts: int = Field(3, ge=1, le=100, description="a job is given up (failed) after this many starts")
    job_lease_s: float = Field(
        15.0, gt=0, description="a running job's lease; renewed every lease/4 (at most 5 s) while it runs, "
        "another attempt may take over after it expires"
    )
    job_memory_mb: float = Field(
        2048.0, ge=0, description="address-space cap (RLIMIT_AS) of each job process, MB; 0 = none"
    )
    job_stop_grace_s: float = Field(
        10.0, gt=0, description="a job still inside a solve this long after a cancel or its time limit is "
        "stopped by its watchdog (status recorded, process replaced)"
    )
    sweep_interval_s: float = Field(5.0, gt=0, description="how often the API re-dispatches stranded jobs")
    redispatch_after_s: float | None = Field(
        None, description="re-dispatch a job still queued this long after its dispatch; "
        "default: visibility_timeout_s + 300"
    )
    redispatch_expired_s: float = Field(
        2.0, ge=0, description="re-dispatch a running job whose lease expired this long ago (its worker died)"
    )
    redispatch_gap_s: float = Field(
        60.0, ge=0, description="at most one re-dispatch of a running job per this interval"
    )
    validate_steps: bool = Field(True, description="store the plausibility report (MuJoCo replay) of every λ optimum")
    default_character: Literal["halfboy", "fullbody"] = Field(
        "fullbody", description="the synthesis character of a tutor a request does not name (solver.pipeline."
        "DEFAULT_CHARACTER: the full body keeps the subject's gait; halfboy is the thesis's, faster)")
    compiled_derivatives: bool = Field(
        True, description="compile each character's NLP derivative functions to machine code (a C compiler, "
        "cached under compiled_dir; 1.3-1.6x faster HalfBoy solves after a one-off compile per character)")
    compiled_dir: Path = Field(default_factory=default_cache_dir,
                               description="cache of compiled derivatives and of the BLAS shim "
                               "(default ~/.cache/motionx/compiled)")
    optimized_blas: bool = Field(
        True, description="run IPOPT's linear solver (MUMPS) on scipy-openblas32's kernels for this CPU instead of "
        "CasADi's generic OpenBLAS (each IPOPT iteration 1.3-1.8x faster; needs a C compiler once)")
    check_modules: str = Field(
        "", description="comma-separated Python modules that register extra sections of the validation report "
        "(solver.checks.register_check); the compute and job processes import them, the report and the page show "
        "their checks")
    default_tutor_fps: float | None = Field(
        None, ge=5, le=30, description="the frame rate of a tutor a request does not give (default: 30 frames/s "
        "for the full body, 15 for HalfBoy: solver.pipeline.DEFAULT_FPS)")

    def tutor_of(self, tutor: Mapping[str, Any] | None) -> tuple[str, float]:
        """(character, fps) of a request's tutor options, the service's defaults filling what it omits."""
        opts = tutor or {}
        character = opts.get("character") or self.default_character
        fps = opts.get("fps") or self.default_tutor_fps or (30.0 if character == "fullbody" else 15.0)
        return str(character), float(fps)

    # --- the API's compute processes (uploads, exports, reports, plots) --------------------
    compute_workers: int = Field(default_factory=_machine_processes, ge=0, le=64,
                                 description="compute processes of the API, default one per core (2 to 8; 0: its "
                                 "threads, for debugging only)")
    compute_lane_running: int | None = Field(
        None, ge=1, description="heavy requests of one API key computed at once; default one process fewer than "
        "compute_workers (at least 1), so another key always finds one free")
    compute_timeout_s: float = Field(120.0, gt=0, description="time limit of one heavy request")
    compute_memory_mb: float = Field(2048.0, ge=0, description="address-space cap of each compute process, MB")
    compute_queue: int = Field(64, ge=0, description="heavy requests of all keys waiting beyond this get 429")
    export_cache_bytes: int = Field(64 * 1024 * 1024, ge=0, description="in-memory cache of exports and plots")
    failure_memo_s: float = Field(3600.0, gt=0, description="a heavy request refused for its input is answered "
                                  "the same way this long without computing it again")

    # --- per-key quotas (429 with Retry-After for that key only) --------------------------
    quota_heavy_requests: int = Field(8, ge=1, description="heavy requests (uploads, exports, reports, plots) of "
                                      "one key in flight, computed or waiting")
    quota_jobs: int = Field(250, ge=1, description="jobs of one key queued or running (a library's cells "
                            "included)")
    quota_simulations: int = Field(16, ge=1, description="simulations of one key queued or running")
    quota_storage_mb: float = Field(2048.0, gt=0, description="what one key stores: motions (compressed) and "
                                    "simulation files, MB")
    job_slots: int | None = Field(None, ge=1, description="job processes of the whole service (default: "
                                  "local_workers; `motionx stack` sets workers x concurrency)")
    jobs_per_key: int | None = Field(None, ge=1, description="jobs of one key running (or dispatched) at once; "
                                     "default one slot fewer than job_slots (at least 1), so another key's job "
                                     "starts at once")

    # --- HTTP ------------------------------------------------------------------------
    host: str = "127.0.0.1"
    port: int = Field(8000, ge=0, le=65535)
    max_body_bytes: int = Field(32 * 1024 * 1024, ge=1024, description="larger request bodies get 413")
    api_keys: str = Field("", description="comma-separated API keys accepted besides those stored in SQL")
    page_size: int = Field(50, ge=1, le=1000)
    sse_poll_s: float = Field(0.5, gt=0)
    sse_max_s: float = Field(3600.0, gt=0, description="an event stream closes after this")

    @field_validator("database_url")
    @classmethod
    def _driver(cls, v: str | None) -> str | None:
        if v and v.startswith("postgres://"):
            v = "postgresql://" + v[len("postgres://"):]
        if v and v.startswith("postgresql://"):
            v = "postgresql+psycopg://" + v[len("postgresql://"):]
        return v or None

    @model_validator(mode="after")
    def _timeouts(self) -> Settings:
        if self.visibility_timeout_s <= self.hard_time_limit_s:
            raise ValueError(
                f"visibility_timeout_s ({self.visibility_timeout_s}) must exceed the longest job "
                f"({self.hard_time_limit_s:g} s: job_time_limit_s plus Celery's hard-limit margin), "
                "otherwise Redis hands a running job to a second worker"
            )
        return self

    @property
    def hard_time_limit_s(self) -> float:
        """Celery's hard time limit: a backstop after the job's own limit and its watchdog
        (which stops a job ``job_stop_grace_s`` past the limit and records it)."""
        return self.job_time_limit_s + self.job_stop_grace_s + max(5.0, 0.1 * self.job_time_limit_s)

    @property
    def lane_running(self) -> int:
        return self.compute_lane_running or max(1, self.compute_workers - 1)

    @property
    def total_job_slots(self) -> int:
        return self.job_slots or (self.local_workers if self.runner == "local" else 2)

    @property
    def key_job_slots(self) -> int:
        return self.jobs_per_key or max(1, self.total_job_slots - 1)

    @property
    def sqlalchemy_url(self) -> str:
        if self.database_url:
            return self.database_url
        return f"sqlite:///{self.data_dir / 'motionx.db'}"

    @property
    def redispatch_after(self) -> float:
        return self.redispatch_after_s if self.redispatch_after_s is not None else self.visibility_timeout_s + 300.0

    @property
    def check_module_names(self) -> tuple[str, ...]:
        return _module_names(self.check_modules)

    @field_validator("check_modules")
    @classmethod
    def _valid_module_names(cls, v: str) -> str:
        for name in _module_names(v):
            if not all(part.isidentifier() for part in name.split(".")):
                raise ValueError(f"check module {name!r} is not a Python module name (dotted identifiers)")
        return v

    @property
    def static_api_keys(self) -> tuple[str, ...]:
        return tuple(k.strip() for k in self.api_keys.split(",") if k.strip())


def enable_native_code(settings: Settings) -> None:
    """Turn on compiled derivatives and the optimized BLAS in this process as the settings say
    (``solver.native``; job processes and the CLI's solving commands call it before they solve;
    it loads CasADi)."""
    from solver import native

    native.enable(compiled=settings.compiled_derivatives, blas=settings.optimized_blas,
                  cache_dir=settings.compiled_dir)


def _module_names(text: str) -> tuple[str, ...]:
    return tuple(m.strip() for m in text.split(",") if m.strip())


def load_check_modules(settings: Settings) -> None:
    """Import the modules that register extra check sections (``check_modules``) in this process,
    where reports are made (job processes, the CLI; the API's compute processes import them at
    start)."""
    for name in settings.check_module_names:
        importlib.import_module(name)


def find_check_modules(settings: Settings) -> None:
    """Refuse, naming it, a check module this interpreter cannot find (without importing it: the
    API process does not load the solver)."""
    for name in settings.check_module_names:
        try:
            found = importlib.util.find_spec(name) is not None
        except ImportError:
            found = False
        if not found:
            raise RuntimeError(f"MOTIONX_CHECK_MODULES names {name!r}, which is not importable here "
                               "(install it or put its folder on PYTHONPATH)")


@lru_cache(maxsize=1)
def get_settings() -> Settings:
    """The process's settings, read from the environment on first call."""
    return Settings()
