"""The SQL store on SQLite (WAL) and PostgreSQL: one code path, same behaviour."""

from __future__ import annotations

import secrets
import threading
import time

import pytest
from sqlalchemy import func, select, text, update
from sqlalchemy.exc import IntegrityError
from svc_util import halfboy_motion

from service import store
from service.db import current_revision, get_database, upgrade
from service.models import JobRow, MotionRow


@pytest.fixture(params=["sqlite", "postgresql"])
def db(request, tmp_path):
    if request.param == "sqlite":
        url = f"sqlite:///{tmp_path / 'store.db'}"
    else:
        url = request.getfixturevalue("pg_url")
    upgrade(url)
    return get_database(url)


def owner() -> str:
    return "o_" + secrets.token_hex(6)


def _job(db, *, max_attempts=3, runner="celery", key=None, own=None):
    own = own or owner()
    with db.write() as s:
        m = store.add_motion(s, owner=own, motion=halfboy_motion(), kind="capture")
        j = store.create_job(s, owner=own, motion_id=m.id, spec={"target": {"slope_deg": 3.0}}, runner=runner,
                             max_attempts=max_attempts, idempotency_key=key, request_hash="h1")
        return j.id, m.id, own


def test_migrations_reach_head_and_are_idempotent(db):
    upgrade(db.url)  # second run: nothing to do
    assert current_revision(db.url) == "0005"
    if db.is_sqlite:
        with db.read() as s:
            assert s.execute(text("PRAGMA journal_mode")).scalar() == "wal"


def test_motion_round_trip_is_exact_and_owned(db):
    m = halfboy_motion(seed=3)
    a, b = owner(), owner()
    with db.write() as s:
        row = store.add_motion(s, owner=a, motion=m, kind="capture", name="walk")
        mid = row.id
    with db.read() as s:
        assert store.get_motion(s, motion_id=mid, owner=b) is None
        got = store.load_motion(store.get_motion(s, motion_id=mid, owner=a))
    assert (got.q == m.q).all() and got.fps == m.fps and got.character.coordinate_names == m.character.coordinate_names


def test_save_step_upserts_by_job_and_step(db):
    job_id, _, own = _job(db)
    m1, m2 = halfboy_motion(seed=1), halfboy_motion(seed=2)
    with db.write() as s:
        id1 = store.save_step(s, job_id=job_id, owner=own, step=0, lam=0.0, motion=m1)
        store.save_step(s, job_id=job_id, owner=own, step=1, lam=0.1, motion=m1)
    with db.write() as s:  # a re-run writes the same steps again
        id1b = store.save_step(s, job_id=job_id, owner=own, step=0, lam=0.0, motion=m2, validation={"plausible": True})
        store.save_step(s, job_id=job_id, owner=own, step=1, lam=0.1, motion=m2)
    assert id1 == id1b
    with db.read() as s:
        rows = store.job_motions(s, job_id=job_id)
        assert [r.step for r in rows] == [0, 1]
        assert (store.load_motion(rows[0]).q == m2.q).all() and rows[0].plausible is True
        assert store.count_job_motions(s, job_id=job_id) == 2
        assert s.get(JobRow, job_id).steps == 2


def test_claim_attempt_counter_and_cap(db):
    job_id, _, _ = _job(db, max_attempts=2)
    with db.write() as s:
        c1 = store.claim_job(s, job_id=job_id, token="h:1:a", lease_s=60)
    assert (c1.outcome, c1.attempt) == ("claimed", 1)
    with db.write() as s:  # a duplicate delivery while the first attempt is alive
        assert store.claim_job(s, job_id=job_id, token="h:2:b", lease_s=60).outcome == "busy"
    with db.write() as s:  # the holder died: a new attempt takes over at once
        c2 = store.claim_job(s, job_id=job_id, token="h:2:b", lease_s=60, holder_alive=lambda t: False)
    assert (c2.outcome, c2.attempt) == ("claimed", 2)
    with db.write() as s:
        c3 = store.claim_job(s, job_id=job_id, token="h:3:c", lease_s=60, holder_alive=lambda t: False)
    assert c3.outcome == "exhausted"
    with db.read() as s:
        j = s.get(JobRow, job_id)
        assert j.status == "failed" and "2 attempts" in j.message
    with db.write() as s:  # a terminal job is never run again
        assert store.claim_job(s, job_id=job_id, token="h:4:d", lease_s=60).outcome == "terminal"


def test_expired_lease_can_be_taken_over_and_fences_the_old_holder(db):
    job_id, _, own = _job(db)
    with db.write() as s:
        store.claim_job(s, job_id=job_id, token="old", lease_s=0.05)
    time.sleep(0.1)
    with db.write() as s:
        assert store.claim_job(s, job_id=job_id, token="new", lease_s=60).outcome == "claimed"
    with db.write() as s:
        assert not store.renew_lease(s, job_id=job_id, token="old", lease_s=60).held
        assert store.renew_lease(s, job_id=job_id, token="new", lease_s=60).held
        assert not store.finish_job(s, job_id=job_id, token="old", status="succeeded")
        assert store.finish_job(s, job_id=job_id, token="new", status="impasse", lam_reached=0.4, steps=0)
    with db.read() as s:
        j = s.get(JobRow, job_id)
        assert (j.status, j.lam_reached, j.attempts) == ("impasse", 0.4, 2)


def test_finish_removes_steps_beyond_the_final_attempts_count(db):
    job_id, _, own = _job(db)
    with db.write() as s:
        store.claim_job(s, job_id=job_id, token="t", lease_s=60)
        for k in range(4):
            store.save_step(s, job_id=job_id, owner=own, step=k, lam=k / 4, motion=halfboy_motion(seed=k))
    with db.write() as s:
        assert store.finish_job(s, job_id=job_id, token="t", status="succeeded", lam_reached=1.0, steps=3)
    with db.read() as s:
        assert [r.step for r in store.job_motions(s, job_id=job_id)] == [0, 1, 2]


def test_progress_points_are_per_attempt_and_never_duplicated(db):
    job_id, _, _ = _job(db)
    kw = dict(phase="extrapolate", wall_time=0.5, lam=0.1, lam_reached=0.1, environment={"slope_deg": 0.3},
              iterations=7, accepted=True, status="Solve_Succeeded")
    with db.write() as s:
        store.claim_job(s, job_id=job_id, token="t1", lease_s=60)
        store.append_progress(s, job_id=job_id, attempt=1, seq=0, **kw)
        store.append_progress(s, job_id=job_id, attempt=1, seq=0, **kw)  # replayed write: ignored
        store.append_progress(s, job_id=job_id, attempt=1, seq=1, **kw)
    with db.read() as s:
        pts = store.progress(s, job_id=job_id)
        assert [p.seq for p in pts] == [0, 1] and pts[0].environment == {"slope_deg": 0.3}
        assert store.progress(s, job_id=job_id, attempt=2) == []


def test_idempotency_key_is_unique_per_owner(db):
    own = owner()
    job_id, motion_id, _ = _job(db, key="k-1", own=own)
    with db.read() as s:
        assert store.find_idempotent(s, owner=own, key="k-1", request_hash="h1").id == job_id
        assert store.find_idempotent(s, owner=owner(), key="k-1", request_hash="h1") is None
        with pytest.raises(store.IdempotencyConflict):
            store.find_idempotent(s, owner=own, key="k-1", request_hash="other")
    with pytest.raises(IntegrityError), db.write() as s:  # a racing second insert loses at commit
        store.create_job(s, owner=own, motion_id=motion_id, spec={}, runner="celery", max_attempts=3,
                         idempotency_key="k-1", request_hash="h1")


def test_cancel_queued_is_immediate_running_is_flagged(db):
    q_id, _, _ = _job(db)
    r_id, _, _ = _job(db)
    with db.write() as s:
        store.claim_job(s, job_id=r_id, token="t", lease_s=60)
    with db.write() as s:
        assert store.request_cancel(s, job_id=q_id).status == "canceled"
        j = store.request_cancel(s, job_id=r_id)
        assert j.status == "running" and j.cancel_requested
    with db.write() as s:
        assert store.renew_lease(s, job_id=r_id, token="t", lease_s=60).cancel_requested
        assert store.claim_job(s, job_id=q_id, token="x", lease_s=60).outcome == "terminal"


def test_stranded_jobs(db):
    never, _, _ = _job(db, runner="celery")
    sent, _, _ = _job(db, runner="celery")
    dead, _, _ = _job(db, runner="celery")
    with db.write() as s:
        store.mark_dispatched(s, job_id=sent)
        store.mark_dispatched(s, job_id=dead)
        store.claim_job(s, job_id=dead, token="t", lease_s=0.01)
    time.sleep(0.05)
    with db.read() as s:
        ids = store.stranded_jobs(s, runner="celery", queued_after=3600, running_after=3600, limit=10**6)
        assert never in ids and sent not in ids and dead not in ids
        ids = store.stranded_jobs(s, runner="celery", queued_after=3600, running_after=0.0, limit=10**6)
        assert dead in ids
        assert never not in store.stranded_jobs(s, runner="local", queued_after=0, running_after=0, limit=10**6)
    # dispatched before its lease expired (the original delivery): re-dispatched at once, whatever
    # the gap; once re-dispatched for this expiry, not again within the gap
    with db.read() as s:
        assert dead in store.stranded_jobs(s, runner="celery", queued_after=3600, running_after=0.0,
                                           redispatch_gap=3600, limit=10**6)
    with db.write() as s:
        store.mark_dispatched(s, job_id=dead)
    with db.read() as s:
        assert dead not in store.stranded_jobs(s, runner="celery", queued_after=3600, running_after=0.0,
                                               redispatch_gap=3600, limit=10**6)
        assert dead in store.stranded_jobs(s, runner="celery", queued_after=3600, running_after=0.0,
                                           redispatch_gap=0.0, limit=10**6)
    with db.write() as s:  # a fail_unfinished is final
        assert store.fail_unfinished(s, job_id=dead, message="stopped")
        assert not store.fail_unfinished(s, job_id=dead, message="again")
    with db.read() as s:
        assert dead not in store.stranded_jobs(s, runner="celery", queued_after=0, running_after=0, limit=10**6)
        assert store.get_job(s, job_id=dead, owner=None).status == "failed"


def test_concurrent_claims_only_one_wins(db):
    """Eight threads claim the same job at once: exactly one attempt is started."""
    job_id, _, _ = _job(db)
    outcomes, barrier = [], threading.Barrier(8)

    def claim(i):
        barrier.wait()
        with db.write() as s:
            outcomes.append(store.claim_job(s, job_id=job_id, token=f"h:{i}:x", lease_s=60).outcome)

    threads = [threading.Thread(target=claim, args=(i,)) for i in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(30)
    assert sorted(outcomes) == ["busy"] * 7 + ["claimed"]
    with db.read() as s:
        assert s.get(JobRow, job_id).attempts == 1


def test_concurrent_step_upserts_never_duplicate(db):
    job_id, _, own = _job(db)
    barrier = threading.Barrier(6)
    errors = []

    def write(i):
        barrier.wait()
        try:
            for step in range(3):
                with db.write() as s:
                    store.save_step(s, job_id=job_id, owner=own, step=step, lam=step / 3, motion=halfboy_motion(seed=i))
        except Exception as e:
            errors.append(e)

    threads = [threading.Thread(target=write, args=(i,)) for i in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert not errors
    with db.read() as s:
        n = s.scalar(select(func.count()).select_from(MotionRow).where(MotionRow.job_id == job_id))
    assert n == 3


def test_api_keys_hashed_and_revocable(db):
    with db.write() as s:
        kid, key = store.create_api_key(s, name="lab")
    with db.read() as s:
        assert store.owner_for_key(s, key=key) == kid
        assert store.owner_for_key(s, key=key + "x") is None
        assert store.owner_for_key(s, key="static-1", static_keys=("static-1",)) == store.static_owner("static-1")
        assert key not in str(s.execute(text("SELECT key_hash FROM api_keys")).all())
    with db.write() as s:
        assert store.revoke_api_key(s, key_id=kid)
    with db.read() as s:
        assert store.owner_for_key(s, key=key) is None


def _running_job(db, motion_id: str, own: str, token: str) -> str:
    """A job on ``motion_id`` that is running under the lease ``token``."""
    with db.write() as s:
        j = store.create_job(s, owner=own, motion_id=motion_id, spec={"target": {"slope_deg": 3.0}}, runner="local",
                             max_attempts=3)
        jid, created = j.id, j.created_at
    with db.write() as s:
        assert store.claim_job(s, job_id=jid, token=token, lease_s=60).outcome == "claimed"
    return jid, created


def _turn(db, capture: str, job: tuple[str, float], token: str, key: str = "halfboy@15", **kw) -> store.TutorTurn:
    with db.write() as s:
        return store.claim_tutor(s, parent_id=capture, tutor_key=key, job_id=job[0], token=token,
                                 job_created_at=job[1], **kw)


def test_a_tutor_is_made_by_one_job_and_shared(db):
    """Of the jobs needing the same tutor, one makes it and the others wait for it while the
    maker holds its lease; its result (the stored tutor, or its failure) is theirs."""
    _, capture, own = _job(db)
    a, b = _running_job(db, capture, own, "h:1:a"), _running_job(db, capture, own, "h:2:b")
    assert _turn(db, capture, a, "h:1:a").outcome == "make"
    assert _turn(db, capture, b, "h:2:b") == store.TutorTurn("wait", maker=a[0])
    assert _turn(db, capture, a, "h:1:a").outcome == "make"  # asked again by its maker: still its own
    assert _turn(db, capture, b, "h:2:b", key="halfboy@30").outcome == "make"  # another tutor: another claim
    # the maker fails: the jobs created before share the failure, a job created after makes it again
    with db.write() as s:
        assert store.end_tutor_claim(s, parent_id=capture, tutor_key="halfboy@15", token="h:1:a", state="failed",
                                     message="no gait cycle")
        assert not store.end_tutor_claim(s, parent_id=capture, tutor_key="halfboy@15", token="h:2:b",
                                         state="made")  # fenced: not b's claim
    assert _turn(db, capture, b, "h:2:b") == store.TutorTurn("failed", maker=a[0], message="no gait cycle")
    time.sleep(0.01)  # the next job is created after the failure (epoch seconds)
    c = _running_job(db, capture, own, "h:3:c")
    assert _turn(db, capture, c, "h:3:c").outcome == "make"
    assert _turn(db, capture, b, "h:2:b") == store.TutorTurn("wait", maker=c[0])
    with db.write() as s:  # c stores it and ends its claim in the same transaction
        tutor = store.get_or_add_tutor(s, owner=own, parent_id=capture, tutor_key="halfboy@15",
                                       motion=halfboy_motion(seed=5)).id
        assert store.end_tutor_claim(s, parent_id=capture, tutor_key="halfboy@15", token="h:3:c", state="made")
    for job, token in ((b, "h:2:b"), (a, "h:1:a"), (c, "h:3:c")):
        assert _turn(db, capture, job, token) == store.TutorTurn("ready", tutor_id=tutor, maker=c[0])
    with db.read() as s:
        assert s.scalar(select(func.count()).select_from(MotionRow).where(MotionRow.parent_id == capture)) == 1


def test_a_tutor_claim_is_taken_over_when_its_maker_stops(db):
    _, capture, own = _job(db)
    a, b = _running_job(db, capture, own, "h:1:a"), _running_job(db, capture, own, "h:2:b")
    assert _turn(db, capture, a, "h:1:a").outcome == "make"
    # the maker's process is gone (a dead process of this host): taken over at once
    assert _turn(db, capture, b, "h:2:b", holder_alive=lambda t: t != "h:1:a").outcome == "make"
    assert _turn(db, capture, a, "h:1:a") == store.TutorTurn("wait", maker=b[0])
    # the maker's job ends without making it (e.g. its watchdog stopped it): no longer its lease
    with db.write() as s:
        assert store.finish_job(s, job_id=b[0], token="h:2:b", status="canceled")
    assert _turn(db, capture, a, "h:1:a").outcome == "make"
    # released (canceled while making it): the next job needing it makes it, failure or not
    with db.write() as s:
        assert store.end_tutor_claim(s, parent_id=capture, tutor_key="halfboy@15", token="h:1:a", state="released")
    c = _running_job(db, capture, own, "h:3:c")
    assert _turn(db, capture, c, "h:3:c").outcome == "make"


def test_concurrent_jobs_claim_a_tutor_once(db):
    """Jobs asking at the same moment, each in its own transaction and connection: one makes it."""
    _, capture, own = _job(db)
    jobs = [_running_job(db, capture, own, f"h:{i}:x") for i in range(6)]
    barrier, turns = threading.Barrier(len(jobs)), {}

    def ask(i: int) -> None:
        barrier.wait()
        turns[i] = _turn(db, capture, jobs[i], f"h:{i}:x")

    threads = [threading.Thread(target=ask, args=(i,)) for i in range(len(jobs))]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=60)
    outcomes = sorted(t.outcome for t in turns.values())
    assert len(turns) == len(jobs) and outcomes.count("make") == 1 and outcomes.count("wait") == len(jobs) - 1, turns
    maker = next(jobs[i][0] for i, t in turns.items() if t.outcome == "make")
    assert all(t.maker in (None, maker) for t in turns.values())  # None: lost the insert race, asks again


def test_jobs_are_dispatched_in_turns_per_key(db):
    runner = "turns-" + secrets.token_hex(3)
    a = [_job(db, runner=runner)[0]]
    own_a = None
    with db.read() as s:
        own_a = s.get(JobRow, a[0]).owner
    for _ in range(3):  # A's later jobs, then one of B
        a.append(_job(db, runner=runner, own=own_a)[0])
    b = _job(db, runner=runner)[0]
    with db.write() as s:
        first = store.dispatch_fair(s, runner=runner, per_key=1)
    assert first == [a[0], b]  # one turn each; A's other jobs wait in SQL, oldest first
    with db.write() as s:
        assert store.dispatch_fair(s, runner=runner, per_key=1) == []
        s.execute(update(JobRow).where(JobRow.id == a[0]).values(status="succeeded"))
    with db.write() as s:
        assert store.dispatch_fair(s, runner=runner, per_key=1) == [a[1]]  # A's next turn
        assert store.dispatch_fair(s, runner=runner, per_key=3) == [a[2], a[3]]
        store.undo_dispatch(s, job_ids=[a[3]])  # the broker refused it: its turn comes again
    with db.write() as s:
        assert store.dispatch_fair(s, runner=runner, per_key=3) == [a[3]]


def test_deletion_takes_what_hangs_on_a_motion_and_frees_its_storage(db):
    own = owner()
    with db.write() as s:
        keep = store.add_motion(s, owner=own, motion=halfboy_motion(seed=1), kind="capture").id
        before = store.storage_bytes(s, owner=own)
        src = store.add_motion(s, owner=own, motion=halfboy_motion(seed=2), kind="capture").id
        tutor = store.get_or_add_tutor(s, owner=own, parent_id=src, tutor_key="halfboy@15",
                                       motion=halfboy_motion(seed=3, capture=False)).id
        job = store.create_job(s, owner=own, motion_id=src, spec={}, runner="local", max_attempts=3,
                               idempotency_key="k", request_hash="h")
        job.tutor_motion_id = tutor
        job.status = "succeeded"
        step = store.save_step(s, job_id=job.id, owner=own, step=0, lam=1.0, motion=halfboy_motion(seed=4))
        later = store.create_job(s, owner=own, motion_id=step, spec={}, runner="local", max_attempts=3)
        later.status = "failed"
        sim = store.create_simulation(s, owner=own, motion_id=step, job_id=later.id, cycles=1)
        store.finish_simulation(s, simulation_id=sim.id, report={}, files={"report.json": b"x" * 1000},
                                message="")
        lib, _ = store.create_library(s, owner=own, motion_id=src, spec={}, cells=[("c", {}, {})], runner="local",
                                      max_attempts=3)
        lib_id = lib.id
        for j in s.scalars(select(JobRow).where(JobRow.motion_id == src, JobRow.status == "queued")):
            j.status = "canceled"
        job_id, later_id = job.id, later.id
    with db.read() as s:
        assert store.storage_bytes(s, owner=own) > before + 1000
        plan = store.deletion(s, motions=[src])
        assert plan.motions == {src, tutor, step} and {job_id, later_id} <= plan.jobs and plan.libraries == {lib_id}
        assert plan.simulations == {sim.id} and not plan.active_jobs(s)
    with db.write() as s:
        store.delete_all(s, plan)
    with db.read() as s:
        assert store.storage_bytes(s, owner=own) == before
        assert store.get_motion(s, motion_id=keep, owner=own) is not None
        assert s.scalar(select(func.count()).select_from(MotionRow).where(MotionRow.owner == own)) == 1
        assert s.scalar(select(func.count()).select_from(JobRow).where(JobRow.owner == own)) == 0
        assert store.get_library(s, library_id=lib_id, owner=own) is None
