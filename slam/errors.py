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
    """A signal that ends a process (Ctrl-C's SIGINT, SIGTERM, SIGHUP,
    SIGQUIT, ...: ``slam.processes.signals.STOPS``), a KeyboardInterrupt so
    that a terminated command cleans up as an interrupted one does.

    Ctrl-C raises it too, not KeyboardInterrupt itself: CPython ends a
    process run with ``python -m`` by SIGINT at its exit once a
    KeyboardInterrupt of that exact type has passed through code it ran with
    ``exec`` (a namedtuple's, a library's at import), even one gslam caught;
    the exit code 130 gslam returns would be lost."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


def raise_terminated(signum: int, frame) -> None:
    """A signal handler: raise :class:`Terminated`."""
    raise Terminated(signum)


def reader_left() -> int:
    """After a ``BrokenPipeError``: the reader of standard output left
    (``... | head``), so there is no more to say. Standard output is pointed
    at /dev/null so that the interpreter's last flush cannot fail either;
    the code returned, 141, is a process's killed by SIGPIPE, what a shell
    reports for the other commands of a pipe."""
    import os
    import sys

    try:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    except (AttributeError, OSError, ValueError):  # no descriptor (a captured or closed stream)
        sys.stdout = open(os.devnull, "w")
    return 141


def run_script(name: str, main) -> None:
    """Run a script's ``main()`` and exit with its code; bad input (a
    :class:`GslamError` or a validation config error) ends it with one line
    on stderr and code 1, as the CLI does, instead of a traceback; a reader
    that leaves early (``python scripts/datasets.py list | head -1``) ends
    it quietly, as the CLI does."""
    import sys

    try:
        code = main()
        if sys.stdout is not None:  # None: started with the stream closed (script ... >&-)
            sys.stdout.flush()  # a broken pipe now, not in the interpreter's last flush
    except InputError as e:
        print(f"{name}: error: {e}", file=sys.stderr)
        sys.exit(1)
    except BrokenPipeError:
        sys.exit(reader_left())
    sys.exit(code or 0)
