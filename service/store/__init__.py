"""The durable store: free functions over a SQLAlchemy session (keyword-only arguments).

Everything a job produces lives here, in SQL: jobs (status, attempts, lease), progress
points keyed by (job, attempt, seq), motions keyed by id — a job's λ optima also by
(job, step), so a re-run upserts instead of duplicating; a capture's tutor by (capture, tutor
key), made by one job at a time (:func:`claim_tutor`).

Callers own the transaction (``Database.write()`` / ``Database.read()``).

    sql          new ids, the clock, the dialect's upsert, blobs read in chunks
    keys         API keys
    motions      motions, tutors and a job's λ optima
    tutors       who makes each tutor (:func:`claim_tutor`)
    jobs         jobs: idempotency, per-key turns, cancel, leases, progress, outcome, stranded jobs
    libraries    motion libraries and their cell jobs
    simulations  simulations and their files
    usage        per-key usage (quotas)
    deletion     deletion with what hangs on a resource

Every name is importable from ``service.store``.
"""

from service.store.deletion import (
    Deletion,
    delete_all,
    deletion,
)
from service.store.jobs import (
    Claim,
    IdempotencyConflict,
    Lease,
    Outcome,
    append_progress,
    claim_job,
    create_job,
    dispatch_fair,
    fail_unfinished,
    find_idempotent,
    finish_job,
    forget_dispatches,
    get_job,
    list_jobs,
    mark_dispatched,
    progress,
    renew_lease,
    request_cancel,
    set_tutor,
    stranded_jobs,
    undo_dispatch,
)
from service.store.keys import (
    count_api_keys,
    create_api_key,
    hash_key,
    owner_for_key,
    revoke_api_key,
    static_owner,
)
from service.store.libraries import (
    create_library,
    get_library,
    library_jobs,
    list_libraries,
    request_library_cancel,
    step_row,
    stored_optima,
)
from service.store.motions import (
    add_encoded,
    add_motion,
    count_job_motions,
    encode_motion,
    find_tutor,
    get_motion,
    get_or_add_tutor,
    job_motions,
    list_motions,
    load_motion,
    motion_json,
    save_step,
    set_validation,
)
from service.store.simulations import (
    create_simulation,
    delete_simulations,
    finish_simulation,
    get_simulation,
    job_simulation,
    latest_simulation,
    motion_simulations,
    set_simulation_status,
    simulation_file,
    simulation_files,
    simulation_state,
)
from service.store.sql import (
    blob_chunk,
    blob_size,
    insert_for,
    new_id,
    now,
)
from service.store.tutors import (
    TutorOutcome,
    TutorTurn,
    claim_tutor,
    end_tutor_claim,
)
from service.store.usage import (
    ACTIVE,
    active_jobs,
    storage_bytes,
)

__all__ = [
    "ACTIVE",
    "Claim",
    "Deletion",
    "IdempotencyConflict",
    "Lease",
    "Outcome",
    "TutorOutcome",
    "TutorTurn",
    "active_jobs",
    "add_encoded",
    "add_motion",
    "append_progress",
    "blob_chunk",
    "blob_size",
    "claim_job",
    "claim_tutor",
    "count_api_keys",
    "count_job_motions",
    "create_api_key",
    "create_job",
    "create_library",
    "create_simulation",
    "delete_all",
    "delete_simulations",
    "deletion",
    "dispatch_fair",
    "encode_motion",
    "end_tutor_claim",
    "fail_unfinished",
    "find_idempotent",
    "find_tutor",
    "finish_job",
    "finish_simulation",
    "forget_dispatches",
    "get_job",
    "get_library",
    "get_motion",
    "get_or_add_tutor",
    "get_simulation",
    "hash_key",
    "insert_for",
    "job_motions",
    "job_simulation",
    "latest_simulation",
    "library_jobs",
    "list_jobs",
    "list_libraries",
    "list_motions",
    "load_motion",
    "mark_dispatched",
    "motion_json",
    "motion_simulations",
    "new_id",
    "now",
    "owner_for_key",
    "progress",
    "renew_lease",
    "request_cancel",
    "request_library_cancel",
    "revoke_api_key",
    "save_step",
    "set_simulation_status",
    "set_tutor",
    "set_validation",
    "simulation_file",
    "simulation_files",
    "simulation_state",
    "static_owner",
    "step_row",
    "storage_bytes",
    "stored_optima",
    "stranded_jobs",
    "undo_dispatch",
]
