"""The one base class of every reader's bad-input error."""


class InputError(ValueError):
    """An input file cannot be turned into a trial; the message names the file and the problem."""
