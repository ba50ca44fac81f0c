"""The one base of every reader error: a bad input file or argument, with a message naming it."""

from __future__ import annotations


class InputError(ValueError):
    """An input (a trial's files or the options given with them) is unreadable or inconsistent.

    ``parameter`` names the keyword argument that would fix it when there is one (e.g.
    ``"mass"`` when the source does not state the subject's mass), so that a front end can
    name its own flag or field for it (``--mass`` on the command line).
    """

    def __init__(self, message: str = "", *, parameter: str | None = None) -> None:
        super().__init__(message)
        self.parameter = parameter
