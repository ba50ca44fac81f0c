"""The one base class of every bad-input error: the readers' (solver/io/), gait processing's, the
force-plate files' (solver.grf_compare). Front ends catch :class:`InputError` and show its message."""

from __future__ import annotations


class InputError(ValueError):
    """An input (a trial's files or the options given with them) cannot be turned into a
    trial; the message names the file and the problem.

    When one argument of the importer would fix it (the subject's mass of a file that does
    not state it), ``parameter`` names it: ``str(e)`` then advises the Python argument
    (``…; pass mass=... (kg)``) while ``reason`` is the message without the advice, so that
    a front end names its own control instead (the CLI's ``--mass``, the upload's form field).
    """

    def __init__(self, reason: str = "", *, parameter: str | None = None, unit: str = "") -> None:
        advice = f"; pass {parameter}=...{f' ({unit})' if unit else ''}" if parameter else ""
        super().__init__(reason + advice)
        self.reason = reason
        self.parameter = parameter
