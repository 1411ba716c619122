"""The project's one error type: bad input, told in one line.

The command line prints an :class:`InputError` as one line (naming the
file, line, topic or key and what was expected) and exits 1; a traceback is
kept for bugs. The validation package calls it :data:`ValidationError`, the
pipeline ``slam.errors.GslamError``: one type, so that whoever catches one
catches what the other raises.
"""


class InputError(Exception):
    """Bad input, told in one line."""


ValidationError = InputError
"""The validation package's name for :class:`InputError`."""
