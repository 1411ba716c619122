"""Work on the second core: a function run in a forked child process.

``gslam map`` spends most of its time in KISS-ICP, which holds Python's
GIL for the whole registration, so a thread cannot work beside it. A child
process forked from the pipeline can: it starts in a few milliseconds,
inherits what the parent has read and imported, and sends its result back
through a pipe. :class:`Forked` runs ``fn(inbox, *args)`` in such a child;
the parent may :meth:`~Forked.send` it objects that ``inbox()`` returns
there, in order, and :meth:`~Forked.result` waits for the return value (or
raises the child's exception). :class:`Inline` has the same interface and
runs the function in the calling process when its result is asked for:
where fork is not available, inside a daemonic process (an ablation
worker), or when the caller asks for the plain path. Both give the same
result; only the time differs.

The child is forked, not spawned: a spawned interpreter would import
numpy, pydantic and the rest again (half a second) before it could start.
Fork is safe here because the pipeline forks before it starts threads of
its own (numpy's BLAS pool is fork-aware); the child only computes and
writes files, and ends with ``os._exit``.
"""

from __future__ import annotations

import gc
import multiprocessing
import os
import pickle
import signal
from collections import deque
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from slam.errors import GslamError
from slam.processes.signals import blocked, child_defaults

Inbox = Callable[[], Any]


def can_fork() -> bool:
    """True where a child process can be forked from this one."""
    return "fork" in multiprocessing.get_all_start_methods() and not multiprocessing.current_process().daemon


def start(what: str, fn: Callable[..., Any], *args: Any, concurrent: bool = True) -> "Forked | Inline":
    """``fn(inbox, *args)`` in a forked child if ``concurrent`` and
    possible, else inline; ``what`` names the work in error messages."""
    if concurrent and can_fork():
        return Forked(what, fn, *args)
    return Inline(what, fn, *args)


class Inline:
    """:class:`Forked`'s interface, run in this process by :meth:`result`."""

    def __init__(self, what: str, fn: Callable[..., Any], *args: Any):
        self.what, self.fn, self.args = what, fn, args
        self.sent: deque[Any] = deque()

    def send(self, obj: Any) -> None:
        self.sent.append(obj)

    def result(self) -> Any:
        return self.fn(self.sent.popleft, *self.args)

    def close(self) -> None:
        self.sent.clear()


@contextmanager
def _frozen_heap() -> Iterator[None]:
    """Fork inside this: the objects that exist now are moved out of the
    garbage collector's reach (``gc.freeze``) for the fork, so the child's
    collections never walk them. Otherwise each collection in the child
    writes to every inherited object's header, and the kernel copies each
    page the parent shares with it (a fifth of a second of CPU time for a
    child that imports rosbags). The parent's objects go back to the
    collector right after."""
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


def _end_with_parent(parent: int) -> None:
    """On Linux, have the kernel end this child when the parent dies (a
    killed ``gslam map`` leaves no orphans: a sibling forked later holds
    the parent's end of this child's pipe, so no EOF would arrive)."""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # not Linux: the pipe's EOF ends the child where it can
        return
    if os.getppid() != parent:  # the parent died before prctl took effect
        os._exit(1)


def _child(conn, fn: Callable[..., Any], args: tuple, parent: int) -> None:
    _end_with_parent(parent)
    # The parent ends a child with SIGTERM; a handler it had when it forked
    # (one that holds signals back while a result is renamed into place)
    # must not keep the child alive: see slam.processes.signals.
    child_defaults()
    try:
        value = ("ok", fn(conn.recv, *args))
    except BaseException as e:  # noqa: BLE001 - every failure goes back to the parent
        value = ("error", e)
    try:
        conn.send(value)
    except (pickle.PicklingError, TypeError, AttributeError):  # an exception that does not pickle
        conn.send(("error", GslamError(f"{type(value[1]).__name__}: {value[1]}")))
    except (BrokenPipeError, EOFError):  # the parent is gone
        pass


class Forked:
    """``fn(inbox, *args)`` in a forked child process; see the module docstring."""

    def __init__(self, what: str, fn: Callable[..., Any], *args: Any):
        self.what = what
        ctx = multiprocessing.get_context("fork")
        self.conn, child_conn = ctx.Pipe()
        self.process = ctx.Process(target=_child, args=(child_conn, fn, args, os.getpid()), name=f"gslam {what}", daemon=True)
        with _frozen_heap(), blocked():  # blocked: see slam.processes.signals
            self.process.start()
        child_conn.close()

    def send(self, obj: Any) -> None:
        try:
            self.conn.send(obj)
        except (BrokenPipeError, ConnectionResetError, EOFError):
            # The child has ended: its error, if it sent one, says why.
            self.result()
            self._died()

    def result(self) -> Any:
        try:
            status, value = self.conn.recv()
        except (EOFError, ConnectionResetError):
            self._died()
        finally:
            self.close()
        if status == "error":
            raise value
        return value

    def _died(self) -> None:
        self.process.join(timeout=5.0)
        code = self.process.exitcode
        how = f"signal {-code}" if code is not None and code < 0 else f"exit code {code}"
        raise GslamError(f"{self.what}: its process ended without a result ({how})")

    def close(self) -> None:
        """End the child if it still runs (an error elsewhere) and reap it."""
        if self.process.is_alive():
            self.conn.close()
            self.process.join(timeout=0.05)
        if self.process.is_alive():
            os.kill(self.process.pid, signal.SIGTERM)
            self.process.join()
        elif self.process.exitcode is None:
            self.process.join()
        self.conn.close()



class Subforked(Forked):
    """:class:`Forked` for a process that :mod:`multiprocessing` will not
    let have children (a :class:`Forked` child is daemonic): the child is
    made with ``os.fork`` and reaped with ``os.waitpid``."""

    def __init__(self, what: str, fn: Callable[..., Any], *args: Any):
        self.what = what
        parent = os.getpid()
        self.conn, child_conn = multiprocessing.Pipe()
        stops = blocked()  # see slam.processes.signals; the child unblocks them in _child
        stops.__enter__()
        with _frozen_heap():
            pid = os.fork()
        if pid == 0:  # the child: no return from here (and its signals unblocked in _child)
            try:
                self.conn.close()
                _child(child_conn, fn, args, parent)
            finally:
                os._exit(0)
        stops.__exit__(None, None, None)
        self.pid: int | None = pid
        child_conn.close()

    def _died(self) -> None:
        status = self._reap(block=True)
        raise GslamError(f"{self.what}: its process ended without a result (status {status})")

    def _reap(self, block: bool) -> int | None:
        if self.pid is None:
            return None
        pid, status = os.waitpid(self.pid, 0 if block else os.WNOHANG)
        if pid == 0:
            return None
        self.pid = None
        return status

    def close(self) -> None:
        """End the child if it still runs (an error elsewhere) and reap it."""
        if self.pid is not None and self._reap(block=False) is None:
            self.conn.close()
            os.kill(self.pid, signal.SIGTERM)
            self._reap(block=True)
        self.conn.close()
