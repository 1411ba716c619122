"""How gslam stops: Ctrl-C and every signal whose default action ends a
process (SIGTERM, SIGHUP, SIGQUIT, SIGUSR1, SIGUSR2, SIGALRM: ``STOPS``) end
a command the same way.

While a command runs (:func:`as_interrupt`), they raise
:class:`~slam.errors.Terminated`, a KeyboardInterrupt, so every ``finally``
that removes a half-written result runs for them as for Ctrl-C. Two places
must not be cut in the middle: putting a result in place (and making its
temporary folder), where the signals are held back until it is done
(:func:`held`), and forking a child, where they are blocked (:func:`blocked`;
an exception raised inside the fork's hooks would be swallowed, and the
signal lost). A forked child takes the default actions back
(:func:`child_defaults`).

An interrupt raised where Python cannot raise it (a callback from C, such
as numba's compiler caching its code, or a destructor) is swallowed there,
printed as "Exception ignored ... Traceback", and the command went on to
its end. It is delivered again instead, until it lands where it stops the
command.
"""

from __future__ import annotations

import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager

from slam.errors import raise_terminated

STOPS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP", "SIGQUIT", "SIGUSR1", "SIGUSR2", "SIGALRM")
              if hasattr(signal, n))
"""The signals that end a command through its cleanup. SIGPIPE is left to
Python (ignored: a closed pipe surfaces as BrokenPipeError); SIGKILL cannot
be caught, and a killed run's folder is cleaned up by the next run into it."""


RETRY_S = 0.05
"""Seconds after an interrupt was swallowed (see the module docstring)
before it is delivered again: time for the C code that called back to
return to Python."""


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


@contextmanager
def as_interrupt(received: list[int]) -> Iterator[None]:
    """``STOPS`` raise :class:`~slam.errors.Terminated`; each signal that came is appended to
    ``received`` (one that lands inside a module's import surfaces as that
    import's error, and the caller can still tell; one swallowed where
    Python cannot raise is delivered again). Signals ignored when the
    process started (a background job of a shell) stay ignored."""
    if not _main_thread():
        yield
        return

    def interrupt(signum: int, frame) -> None:
        received.append(signum)
        raise_terminated(signum, frame)

    retries: list[threading.Timer] = []
    unraisable = sys.unraisablehook
    main = threading.main_thread().ident

    def again(signum: int) -> None:
        if signal.getsignal(signum) is interrupt:  # not once the command has ended
            signal.pthread_kill(main, signum)  # a signal, not a flag: it also ends a wait (sleep, a pipe's read)

    def swallowed(what) -> None:
        if not (isinstance(what.exc_value, KeyboardInterrupt) and received):
            unraisable(what)
            return
        retry = threading.Timer(RETRY_S, again, (received[-1],))
        retry.daemon = True
        retries.append(retry)
        retry.start()

    old = {s: signal.signal(s, interrupt) for s in STOPS if signal.getsignal(s) is not signal.SIG_IGN}
    sys.unraisablehook = swallowed
    try:
        yield
    finally:
        for retry in retries:
            retry.cancel()
        sys.unraisablehook = unraisable
        for s, handler in old.items():
            signal.signal(s, handler)


@contextmanager
def held() -> Iterator[None]:
    """Hold ``STOPS`` back until the block is done, then
    deliver the first that came (on the main thread; elsewhere no-op)."""
    if not _main_thread():
        yield
        return
    caught: list[int] = []
    old = {s: signal.signal(s, lambda n, f: caught.append(n)) for s in STOPS}
    try:
        yield
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)
        if caught:
            signal.raise_signal(caught[0])


@contextmanager
def blocked() -> Iterator[None]:
    """Block ``STOPS`` in this thread (delivered after)."""
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, STOPS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def child_defaults() -> None:
    """In a forked child: Ctrl-C ignored (the parent handles it and ends the
    child), the other ``STOPS`` end it, and the signals blocked around the
    fork unblocked."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for s in STOPS:
        if s != signal.SIGINT:
            signal.signal(s, signal.SIG_DFL)
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, STOPS)
