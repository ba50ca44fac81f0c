"""One status type for every result: a tutor, a walk in λ, a library cell, a service job.

``Status`` is a ``str`` enum, so a status compares equal to its text (``Status.SUCCEEDED ==
"succeeded"``) and serializes as that text in JSON, the motion file, the API and the page.

    queued, running      a job or a library cell not finished yet (the service's)
    succeeded            done: the tutor, or every λ up to the target's λ = 1
    impasse              a walk in λ stopped before λ = 1 (its step fell below ε); what it reached is kept
    canceled             stopped on request (the user, Ctrl-C, SIGTERM); what was reached is kept
    failed               no result (the solver did not converge, or the input could not be solved)
"""

from __future__ import annotations

from collections.abc import Iterable
from enum import StrEnum


class Status(StrEnum):
    QUEUED = "queued"
    RUNNING = "running"
    SUCCEEDED = "succeeded"
    IMPASSE = "impasse"
    CANCELED = "canceled"
    FAILED = "failed"

    @property
    def terminal(self) -> bool:
        """Finished: the status will not change any more."""
        return self in TERMINAL

    @property
    def ok(self) -> bool:
        """A result worth keeping: succeeded, or an impasse that reached part of the way."""
        return self in (Status.SUCCEEDED, Status.IMPASSE)


#: the statuses a job or a result ends in
TERMINAL = frozenset({Status.SUCCEEDED, Status.IMPASSE, Status.CANCELED, Status.FAILED})


def combined(statuses: Iterable[str], *, cancel_requested: bool = False) -> Status:
    """The status of a whole made of parts (a library's cells): queued while every part is,
    running while any part is not finished; then canceled when a cancel was asked and a part
    was canceled; else the first of failed, canceled, impasse that a part ended in; else
    succeeded."""
    st = [Status(s) for s in statuses]
    if not all(s.terminal for s in st):
        return Status.QUEUED if all(s == Status.QUEUED for s in st) else Status.RUNNING
    if cancel_requested and Status.CANCELED in st:
        return Status.CANCELED
    for s in (Status.FAILED, Status.CANCELED, Status.IMPASSE):
        if s in st:
            return s
    return Status.SUCCEEDED
