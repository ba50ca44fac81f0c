"""SQL tables (SQLAlchemy 2 declarative). Durable state: motions, jobs, progress points,
libraries, and who makes each tutor.

Times are epoch seconds (double precision) so SQLite and PostgreSQL behave alike.
The schema is created and upgraded by Alembic (``service/migrations``), never by
``create_all`` in production code.
"""

from __future__ import annotations

from typing import Any

from sqlalchemy import JSON, Boolean, Float, ForeignKey, Index, Integer, LargeBinary, String, Text, UniqueConstraint
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

from solver.status import TERMINAL as STATUS_TERMINAL
from solver.status import Status

JOB_STATUSES = tuple(s.value for s in Status)  # one status type: solver.status
TERMINAL = frozenset(s.value for s in STATUS_TERMINAL)
MOTION_KINDS = ("capture", "motion", "tutor", "step")
JOB_KINDS = ("extrapolate", "simulation")


class Base(DeclarativeBase):
    pass


class ApiKey(Base):
    __tablename__ = "api_keys"

    id: Mapped[str] = mapped_column(String(40), primary_key=True)
    name: Mapped[str] = mapped_column(String(200), default="")
    key_hash: Mapped[str] = mapped_column(String(64), unique=True)
    created_at: Mapped[float] = mapped_column(Float)
    revoked_at: Mapped[float | None] = mapped_column(Float, nullable=True)


class MotionRow(Base):
    __tablename__ = "motions"
    __table_args__ = (
        UniqueConstraint("job_id", "step", name="uq_motions_job_step"),
        UniqueConstraint("parent_id", "tutor_key", name="uq_motions_parent_tutor"),
        Index("ix_motions_owner_created", "owner", "created_at"),
        Index("ix_motions_parent", "parent_id"),
    )

    id: Mapped[str] = mapped_column(String(40), primary_key=True)
    owner: Mapped[str] = mapped_column(String(40), index=True)
    kind: Mapped[str] = mapped_column(String(16))  # capture | motion | tutor | step
    name: Mapped[str] = mapped_column(String(200), default="")
    character: Mapped[str] = mapped_column(String(200))
    n: Mapped[int] = mapped_column(Integer)
    frames: Mapped[int] = mapped_column(Integer)
    fps: Mapped[float] = mapped_column(Float)
    has_wrenches: Mapped[bool] = mapped_column(Boolean, default=False)
    job_id: Mapped[str | None] = mapped_column(String(40), ForeignKey("jobs.id", ondelete="CASCADE"), nullable=True)
    step: Mapped[int | None] = mapped_column(Integer, nullable=True)
    lam: Mapped[float | None] = mapped_column(Float, nullable=True)
    parent_id: Mapped[str | None] = mapped_column(String(40), nullable=True)
    tutor_key: Mapped[str | None] = mapped_column(String(100), nullable=True)
    data: Mapped[bytes] = mapped_column(LargeBinary, deferred=True)  # zlib-compressed motion file v2 (JSON)
    sha256: Mapped[str] = mapped_column(String(64))  # of the uncompressed JSON
    size: Mapped[int] = mapped_column(Integer, default=0, server_default="0")  # bytes of data (storage quota)
    validation: Mapped[dict[str, Any] | None] = mapped_column(JSON, nullable=True, deferred=True)
    plausible: Mapped[bool | None] = mapped_column(Boolean, nullable=True)
    created_at: Mapped[float] = mapped_column(Float)


class JobRow(Base):
    __tablename__ = "jobs"
    __table_args__ = (Index("ix_jobs_status_dispatched", "status", "dispatched_at"),
                      Index("ix_jobs_owner_status", "owner", "status"))

    id: Mapped[str] = mapped_column(String(40), primary_key=True)
    owner: Mapped[str] = mapped_column(String(40), index=True)
    motion_id: Mapped[str] = mapped_column(String(40), index=True)  # the source motion
    kind: Mapped[str] = mapped_column(String(16), default="extrapolate", server_default="extrapolate")
    tutor_motion_id: Mapped[str | None] = mapped_column(String(40), nullable=True)
    spec: Mapped[dict[str, Any]] = mapped_column(JSON)
    status: Mapped[str] = mapped_column(String(16), default="queued")
    message: Mapped[str] = mapped_column(Text, default="")
    lam_reached: Mapped[float] = mapped_column(Float, default=0.0)
    steps: Mapped[int] = mapped_column(Integer, default=0)
    solves: Mapped[int] = mapped_column(Integer, default=0)
    attempts: Mapped[int] = mapped_column(Integer, default=0)
    max_attempts: Mapped[int] = mapped_column(Integer, default=3)
    cancel_requested: Mapped[bool] = mapped_column(Boolean, default=False)
    lease_owner: Mapped[str | None] = mapped_column(String(200), nullable=True)
    lease_until: Mapped[float | None] = mapped_column(Float, nullable=True)
    runner: Mapped[str] = mapped_column(String(16), default="local")
    created_at: Mapped[float] = mapped_column(Float)
    dispatched_at: Mapped[float | None] = mapped_column(Float, nullable=True)
    started_at: Mapped[float | None] = mapped_column(Float, nullable=True)
    finished_at: Mapped[float | None] = mapped_column(Float, nullable=True)
    updated_at: Mapped[float] = mapped_column(Float)


class ProgressRow(Base):
    __tablename__ = "progress"

    job_id: Mapped[str] = mapped_column(String(40), ForeignKey("jobs.id", ondelete="CASCADE"), primary_key=True)
    attempt: Mapped[int] = mapped_column(Integer, primary_key=True)
    seq: Mapped[int] = mapped_column(Integer, primary_key=True)
    phase: Mapped[str] = mapped_column(String(16), default="extrapolate")  # tutor | extrapolate
    wall_time: Mapped[float] = mapped_column(Float)
    lam: Mapped[float] = mapped_column(Float)
    lam_reached: Mapped[float] = mapped_column(Float)
    environment: Mapped[dict[str, Any]] = mapped_column(JSON)
    iterations: Mapped[int] = mapped_column(Integer)
    accepted: Mapped[bool] = mapped_column(Boolean)
    status: Mapped[str] = mapped_column(String(200))
    at: Mapped[float] = mapped_column(Float)


class IdempotencyRow(Base):
    __tablename__ = "idempotency"

    owner: Mapped[str] = mapped_column(String(40), primary_key=True)
    key: Mapped[str] = mapped_column(String(255), primary_key=True)
    request_hash: Mapped[str] = mapped_column(String(64))
    job_id: Mapped[str] = mapped_column(String(40), ForeignKey("jobs.id", ondelete="CASCADE"))
    created_at: Mapped[float] = mapped_column(Float)


class LibraryRow(Base):
    """A motion library: one cell job (a row of ``jobs``) per target. Its status and progress are
    derived from its cells' jobs (service.library); the cells are listed in ``spec["cells"]``
    (key, parameters, job id) and each cell job's spec names its library and cell."""

    __tablename__ = "libraries"
    __table_args__ = (Index("ix_libraries_owner_created", "owner", "created_at"),)

    id: Mapped[str] = mapped_column(String(40), primary_key=True)
    owner: Mapped[str] = mapped_column(String(40))
    motion_id: Mapped[str] = mapped_column(String(40))  # the source motion
    spec: Mapped[dict[str, Any]] = mapped_column(JSON)
    cancel_requested: Mapped[bool] = mapped_column(Boolean, default=False)
    created_at: Mapped[float] = mapped_column(Float)


class TutorClaimRow(Base):
    """Who makes the tutor of a capture (``parent_id``) for ``tutor_key`` (character@fps): one
    row per tutor, the key being the tutor's own unique key in ``motions``. A job that finds no
    tutor inserts this row (``INSERT … ON CONFLICT DO NOTHING``: one winner, on SQLite and
    PostgreSQL alike) and makes it; other jobs needing it wait while the maker's job lease is live
    (``token`` is that lease's holder). ``state``: ``making``, then ``made`` (the tutor is in
    ``motions``) or ``failed`` (``message``; ``ended_at``): jobs created before the failure share
    it, later ones make the tutor again (service.store.claim_tutor)."""

    __tablename__ = "tutor_claims"

    parent_id: Mapped[str] = mapped_column(String(40), primary_key=True)
    tutor_key: Mapped[str] = mapped_column(String(100), primary_key=True)
    job_id: Mapped[str] = mapped_column(String(40))
    token: Mapped[str] = mapped_column(String(200))
    state: Mapped[str] = mapped_column(String(16))  # making | made | failed
    message: Mapped[str] = mapped_column(Text, default="")
    claimed_at: Mapped[float] = mapped_column(Float)
    ended_at: Mapped[float | None] = mapped_column(Float, nullable=True)


class SimulationRow(Base):
    """A forward simulation of a stored motion in MuJoCo (service.simulation): asked for over the
    API (run by its own job of kind ``simulation``) or by an extrapolation job for its final
    motion (``simulate_cycles``). ``status``: queued, running, succeeded (the report says whether
    the character fell) or failed (``message``); the files are rows of ``simulation_files``."""

    __tablename__ = "simulations"
    __table_args__ = (Index("ix_simulations_motion_created", "motion_id", "created_at"),)

    id: Mapped[str] = mapped_column(String(40), primary_key=True)
    owner: Mapped[str] = mapped_column(String(40))
    motion_id: Mapped[str] = mapped_column(String(40), ForeignKey("motions.id", ondelete="CASCADE"))
    job_id: Mapped[str] = mapped_column(String(40), ForeignKey("jobs.id", ondelete="CASCADE"), index=True)
    cycles: Mapped[int] = mapped_column(Integer)
    status: Mapped[str] = mapped_column(String(16), default="queued")
    message: Mapped[str] = mapped_column(Text, default="")
    report: Mapped[dict[str, Any] | None] = mapped_column(JSON, nullable=True)
    created_at: Mapped[float] = mapped_column(Float)
    started_at: Mapped[float | None] = mapped_column(Float, nullable=True)
    finished_at: Mapped[float | None] = mapped_column(Float, nullable=True)


class SimulationFileRow(Base):
    """One file of a simulation (service.simulation_files.FILES), stored as it was written."""

    __tablename__ = "simulation_files"

    simulation_id: Mapped[str] = mapped_column(String(40), ForeignKey("simulations.id", ondelete="CASCADE"),
                                               primary_key=True)
    name: Mapped[str] = mapped_column(String(40), primary_key=True)
    media_type: Mapped[str] = mapped_column(String(100))
    size: Mapped[int] = mapped_column(Integer)
    data: Mapped[bytes] = mapped_column(LargeBinary, deferred=True)
