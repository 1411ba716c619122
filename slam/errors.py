"""The one exception type of the ``slam`` package.

Bad input (a missing topic, a malformed file, an unknown config key) raises
:class:`GslamError` with a one-line message that names the file, line or
topic and what was expected. The CLI prints that line and exits with code 1;
a traceback is reserved for bugs.
"""


class GslamError(Exception):
    """A user-facing error: bad input, bad config, missing data."""
