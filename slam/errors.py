"""The exception type of the ``slam`` package, and how a command stops.

Bad input (a missing topic, a malformed file, an unknown config key) raises
:class:`GslamError` with a one-line message that names the file, line or
topic and what was expected. The CLI prints that line and exits with code 1;
a traceback is reserved for bugs.
"""

from validation.base.errors import InputError

GslamError = InputError
"""The pipeline's name for :class:`validation.base.errors.InputError`: bad
input, bad config, missing data."""


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP, raised where Ctrl-C raises KeyboardInterrupt so
    that a terminated command cleans up as an interrupted one does."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


def raise_terminated(signum: int, frame) -> None:
    """A signal handler: raise :class:`Terminated`."""
    raise Terminated(signum)


def run_script(name: str, main) -> None:
    """Run a script's ``main()`` and exit with its code; bad input (a
    :class:`GslamError` or a validation config error) ends it with one line
    on stderr and code 1, as the CLI does, instead of a traceback."""
    import sys

    try:
        code = main()
    except InputError as e:
        print(f"{name}: error: {e}", file=sys.stderr)
        sys.exit(1)
    sys.exit(code or 0)
