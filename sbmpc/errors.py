"""Errors the command line turns into one clear message and an exit code."""


class InputError(Exception):
    """The user's input is wrong (exit code 2). The message names the file or option, the
    key or line, what was expected and what was found."""


class NoResult(Exception):
    """The job ran but its answer is negative (exit code 1), with the reason."""
