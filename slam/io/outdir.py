"""Where results go: the one rule every command follows for ``--out``
(and for inspect's ``--config-out``).

Refused, with or without ``--force``, before any work starts:

* an empty path (an unset shell variable);
* anything that is not a regular file or folder: a device, a named pipe,
  a socket, a symbolic link;
* an input of the command, a folder holding one, or a path inside an input
  folder (also through other names of the same file or folder);
* the file system root, or a place that cannot be written;
* a name the command writes that is taken by something of the user's.

A **result folder** (simulate, map, compare, inject) must be new (or an
empty folder) or an earlier result of the same command, recognised by its
marker (:mod:`slam.io.records`). The marker lists the files the command
wrote: running again replaces those and removes the ones it no longer
writes; every other file there (notes, the user's own figures) stays.
``--force`` writes into a folder that is not such a result: the command's
files join the user's, recorded as gslam's in ``.gslam-added.json``, and
replace nothing but what an earlier forced run of the same command wrote.

The result is built in a temporary sibling and put in place at the end
(:class:`ResultFolder`): renamed whole when nothing of the user's is in the
way, else file by file with SIGINT, SIGTERM and SIGHUP held back until it
is done. A failure before that leaves nothing of the run; one that would
come at that step (a file of the user's in the way) is checked before any
file moves.

*Containers* (ablate, demo) fill their folder in place over several runs,
each part atomically, so that an interrupted run resumes
(:func:`open_container`). A **single-file result** (calibrate's
``--out``, inspect's ``--config-out``) must be new or an earlier result of
the same command (its first line says so); ``--force`` replaces a file
another gslam command wrote, never one of the user's
(:func:`check_new_file`).

Everything is created with the permissions the umask allows (0644 files,
0755 folders under the usual umask), never the 0600/0700 of ``tempfile``.
"""

from __future__ import annotations

import errno
import logging
import os
import shutil
import signal
import stat
import threading
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path

from slam.errors import GslamError
from slam.io.records import (
    ADDED_MARKER, MARKERS, RESULT_MARKER, Record, in_the_way, list_files, only_gslams, read_record, result_command,
    write_added_record, write_result_marker,
)
from slam.io.tempfiles import TEMP_MARKER, TEMP_TAG, host_tag, make_temp_dir, remove_stale_temps, temp_name

__all__ = [
    "ADDED_MARKER", "RESULT_MARKER", "TEMP_MARKER", "TEMP_TAG", "Existing", "ResultFolder", "check_new_file",
    "check_out_path", "classify", "host_tag", "open_container", "remove_stale_temps", "result_command",
    "result_file_mark", "result_folder", "disk_full",
]

log = logging.getLogger(__name__)

_FULL = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)


class Existing(Enum):
    """What ``--out`` is before the command runs."""

    NEW = "new"  # nothing there, or an empty folder
    SAME = "same"  # an earlier result of this command
    FORCED = "forced"  # a folder that is not such a result, with force


# --- checks shared by every output -------------------------------------------------


def _refuse(out: Path | str, why: str, flag: str = "--out") -> GslamError:
    return GslamError(f"{out}: {flag} {why}")


def _special(mode: int) -> str | None:
    """What a file that is neither regular nor a folder is, else None."""
    for test, name in ((stat.S_ISCHR, "a device"), (stat.S_ISBLK, "a device"), (stat.S_ISFIFO, "a named pipe"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return None


def check_out_path(out: str | Path, flag: str = "--out") -> Path:
    """The checks that need no command: not empty, not a symbolic link, a
    device, a pipe or a socket, not the root. Returns ``out`` as a path."""
    if isinstance(out, str) and not out.strip():
        raise GslamError(f"{flag} is empty; give a path (an unset shell variable?)")
    out = Path(out)
    try:
        mode = out.lstat().st_mode
    except OSError:
        mode = None
    if mode is not None and stat.S_ISLNK(mode):
        raise _refuse(out, "is a symbolic link; give the place it points to, or a new name", flag)
    if mode is not None and _special(mode):
        raise _refuse(out, f"is {_special(mode)}, not a regular file or folder; give a new name", flag)
    if out.resolve().parent == out.resolve():
        raise _refuse(out, "is the file system root; give a new folder name", flag)
    return out


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def _check_inputs(out: Path, target: Path, inputs: Iterable[str | Path], flag: str = "--out") -> None:
    """``target`` must not be an input, hold one, or lie inside an input folder."""
    for given in inputs:
        if given is None or str(given) == "":
            continue
        path = Path(given)
        if not path.exists():
            continue
        p = path.resolve()
        if p == target or _same_file(p, target):
            raise _refuse(out, f"is the input {given}; give a new name", flag)
        if target in p.parents:
            raise _refuse(out, f"holds the input {given}; give a new folder name", flag)
        if p.is_dir() and (p in target.parents or any(_same_file(p, a) for a in target.parents)):
            raise _refuse(out, f"is inside the input folder {given}; give a place elsewhere", flag)


def classify(out: str | Path, command: str, inputs: Iterable[str | Path] = (), force: bool = False) -> Existing:
    """Check a result folder ``out`` against the rule of the module
    docstring, without writing anything; a one-line :class:`GslamError` if
    it is refused."""
    out = check_out_path(out)
    target = out.resolve()
    _check_inputs(out, target, inputs)
    if not out.exists():
        return Existing.NEW
    if not out.is_dir():
        raise _refuse(out, "exists and is not a folder; give a new folder name")
    found = result_command(out)
    if found == command:
        return Existing.SAME
    if not any(out.iterdir()):
        return Existing.NEW
    if force:
        return Existing.FORCED
    what = f"a gslam {found} result, not a {command} result" if found else f"not a gslam {command} result (no {RESULT_MARKER})"
    raise _refuse(
        out, f"is a folder that is {what}; give a new folder name, or --force to add the {command} files "
        "to it (nothing of yours there is replaced)"
    )


def _check_free(out: Path, folder: Path, need_bytes: int | None) -> None:
    if not need_bytes:
        return
    try:
        st = os.statvfs(folder)
    except OSError:
        return
    free = st.f_bavail * st.f_frsize
    if free < need_bytes:
        raise _refuse(out, f"needs about {_mb(need_bytes)} and {folder} has {_mb(free)} free; free some space "
                           "or give a place on another disk")


def _mb(n: int) -> str:
    return f"{n / 2**20:.1f} MB" if n < 2**30 else f"{n / 2**30:.1f} GB"


def disk_full(e: OSError) -> bool:
    """The error of a full disk or quota (or a file size limit)."""
    return e.errno in _FULL


def _make_parents(out: Path, folder: Path) -> list[Path]:
    """Create the missing ancestors of ``folder``; the created ones, deepest first."""
    missing = []
    p = folder
    while not p.exists():
        missing.append(p)
        p = p.parent
    for p in reversed(missing):
        try:
            p.mkdir()
        except FileExistsError:
            pass
        except OSError as e:
            _remove_empty(missing)
            raise _refuse(out, f"cannot be created: {p} ({e.strerror})") from None
    return missing


def _remove_empty(folders: list[Path]) -> None:
    for p in folders:  # deepest first
        try:
            p.rmdir()
        except OSError:
            pass


@contextmanager
def signals_held() -> Iterator[None]:
    """Hold SIGINT, SIGTERM and SIGHUP back until the block is done, then
    deliver the first that came (on the main thread; elsewhere no-op)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    held = [s for s in (signal.SIGINT, signal.SIGTERM, getattr(signal, "SIGHUP", None)) if s is not None]
    old = {s: signal.signal(s, lambda n, f: caught.append(n)) for s in held}
    try:
        yield
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)
        if caught:
            signal.raise_signal(caught[0])


# --- result folders ----------------------------------------------------------------


@dataclass
class ResultFolder:
    """A result being built: write into :attr:`tmp`; :meth:`publish` puts it
    at :attr:`target` by the rule of the module docstring."""

    out: Path
    target: Path
    command: str
    existing: Existing
    tmp: Path
    record: Record | None = None
    created: list[Path] = field(default_factory=list)

    @classmethod
    def prepare(cls, out: str | Path, command: str, inputs: Iterable[str | Path] = (), force: bool = False,
                names: Iterable[str] = (), need_bytes: int | None = None) -> "ResultFolder":
        """Every check, then the temporary folder (which proves ``out`` is
        writable); nothing of the user's is touched. ``names``: the files
        (and folders, ending in ``/``) the command will write, checked
        against what stands there; ``need_bytes``: the space it will need."""
        existing = classify(out, command, inputs, force)
        out = Path(out)
        target = out.resolve()
        record = read_record(target, command) if existing is not Existing.NEW else None
        if existing is not Existing.NEW:
            _check_names(out, target, command, names, record)
        created = _make_parents(out, target.parent)
        remove_stale_temps(target.parent)
        try:
            _check_free(out, target.parent, need_bytes)
            try:
                tmp = make_temp_dir(target, command)
            except OSError as e:
                raise _refuse(out, f"cannot be written: {target.parent} ({e.strerror or e})") from None
        except GslamError:
            _remove_empty(created)
            raise
        return cls(out, target, command, existing, tmp, record, created)

    def publish(self) -> Path:
        """Put the finished result in place; returns ``out``."""
        (self.tmp / TEMP_MARKER).unlink()
        files = list_files(self.tmp, skip=MARKERS)
        if self.existing is Existing.NEW:
            write_result_marker(self.tmp, self.command, files)
            try:
                os.rename(self.tmp, self.target)  # also over an empty folder
            except OSError as e:
                raise _refuse(self.out, f"was filled by someone else while this command ran ({e.strerror})") from None
            return self.out
        record = read_record(self.target, self.command)
        if self.existing is Existing.SAME and record is not None and not record.added and only_gslams(self.target, record):
            write_result_marker(self.tmp, self.command, files)
            _swap(self.tmp, self.target)
            return self.out
        self._publish_in_place(files, record)
        return self.out

    def _publish_in_place(self, files: set[str], record: Record | None) -> None:
        """Move the files in one by one, beside the user's: first check that
        nothing of the user's is in the way, then move with the signals held
        back, the marker listing old and new files until the old are gone."""
        _check_names(self.out, self.target, self.command, files, record, what="would replace")
        old = set(record.files or ()) if record is not None else set()
        added = self.existing is Existing.FORCED
        mark = write_added_record if added else write_result_marker
        with signals_held():
            mark(self.target, self.command, old | files)
            for name in sorted(files):
                dest = self.target / name
                dest.parent.mkdir(parents=True, exist_ok=True)
                os.replace(self.tmp / name, dest)
            for name in sorted(old - files):
                _remove_file(self.target, name)
            mark(self.target, self.command, files)
        shutil.rmtree(self.tmp, ignore_errors=True)

    def discard(self) -> None:
        """Remove the temporary folder and the parents this run created."""
        shutil.rmtree(self.tmp, ignore_errors=True)
        _remove_empty(self.created)

    def hide(self, text: str) -> str:
        """``text`` with the temporary folder named as the result it becomes."""
        return text.replace(str(self.tmp), str(self.out))


def _check_names(out: Path, target: Path, command: str, names: Iterable[str], record: Record | None,
                 what: str = "may write") -> None:
    names = [n for n in names if n not in MARKERS]
    blocked = in_the_way(target, names, record)
    if blocked is not None:
        raise _refuse(out, f"holds {blocked}, which gslam {command} {what} and did not write; nothing was "
                           "written: move it, or give another folder")


def _remove_file(target: Path, name: str) -> None:
    """Remove a file gslam wrote earlier and no longer writes, and the
    folders it leaves empty."""
    path = target / name
    try:
        if stat.S_ISREG(path.lstat().st_mode):
            path.unlink()
    except OSError:
        return
    parent = path.parent
    while parent != target:
        try:
            parent.rmdir()
        except OSError:
            return
        parent = parent.parent


def _swap(new: Path, target: Path) -> None:
    """Swap ``new`` in for the earlier result ``target``; the old folder is
    renamed to a temporary name first, so a kill between the renames leaves
    it recognisable for the next run to remove."""
    old = temp_name(target, "old")
    with signals_held():
        os.rename(target, old)
        os.rename(new, target)
    shutil.rmtree(old, ignore_errors=True)


@contextmanager
def result_folder(
    out: str | Path, command: str, inputs: Iterable[str | Path] = (), force: bool = False,
    names: Iterable[str] = (), need_bytes: int | None = None,
) -> Iterator[Path]:
    """``with result_folder(out, "map", [input]) as tmp:`` write into ``tmp``;
    on success the result is published at ``out``, on any error (or a
    signal) nothing of it remains. A full disk is a one-line error naming
    ``out``; other errors that name the temporary folder name ``out``."""
    folder = ResultFolder.prepare(out, command, inputs, force, names, need_bytes)
    try:
        yield folder.tmp
        folder.publish()
    except OSError as e:
        if disk_full(e):
            raise GslamError(f"{folder.out}: no space left to write the {command} result ({e.strerror}); "
                             "nothing was written") from None
        if e.filename is not None and str(folder.tmp) in str(e.filename):
            raise GslamError(folder.hide(f"{e.filename}: {e.strerror or e}")) from None
        raise
    except GslamError as e:
        if str(folder.tmp) in str(e):
            raise GslamError(folder.hide(str(e))) from None
        raise
    finally:
        if folder.tmp.exists():
            folder.discard()


# --- containers --------------------------------------------------------------------


def open_container(out: str | Path, command: str, inputs: Iterable[str | Path] = (), force: bool = False,
                   names: Iterable[str] = ()) -> Path:
    """Check ``out`` for a command that fills its folder in place (ablate,
    demo), create and mark it; ``names``: the files and folders (ending in
    ``/``) it writes there, which must not be the user's when forced into
    a folder of theirs (they are then recorded as gslam's)."""
    existing = classify(out, command, inputs, force)
    out = Path(out)
    target = out.resolve()
    created = _make_parents(out, target.parent)
    remove_stale_temps(target.parent)
    try:
        if existing is Existing.NEW:
            target.mkdir(exist_ok=True)
            write_result_marker(target, command, None)
        elif not os.access(target, os.W_OK | os.X_OK):
            raise _refuse(out, "cannot be written (permission denied)")
        elif existing is Existing.FORCED:
            record = read_record(target, command)
            names = list(names)
            _check_names(out, target, command, names, record)
            write_added_record(target, command, {n.rstrip("/") for n in names})
    except OSError as e:
        _remove_empty(created)
        raise _refuse(out, f"cannot be written ({e.strerror})") from None
    except GslamError:
        _remove_empty(created)
        raise
    return out


# --- single files ------------------------------------------------------------------


def result_file_mark(command: str) -> str:
    """The first line of a text file ``command`` wrote as its result."""
    return f"# gslam {command} result"


def file_mark(path: Path) -> str | None:
    """The command whose result the text file ``path`` is (its first line), or None."""
    try:
        with open(path, "rb") as f:
            first = f.readline(200).decode("utf-8", errors="replace")
    except OSError:
        return None
    prefix = "# gslam "
    if not first.startswith(prefix) or " result" not in first:
        return None
    command = first[len(prefix):].split(" ", 1)[0]
    return command if first.startswith(result_file_mark(command)) else None


def check_new_file(path: str | Path, inputs: Iterable[str | Path] = (), force: bool = False,
                   command: str | None = None, flag: str = "--out") -> Path:
    """A single output file (``--config-out``, calibrate's ``--out``): new,
    or an earlier result of ``command`` (its first line is
    :func:`result_file_mark`), or with ``force`` a result of another gslam
    command; never an input or a file inside an input folder, a folder, a
    link, a device, a pipe or a file of the user's."""
    path = check_out_path(path, flag)
    target = path.resolve()
    _check_inputs(path, target, inputs, flag)
    if path.is_dir():
        raise _refuse(path, "is a folder; give a file name", flag)
    if path.exists():
        found = file_mark(path)
        if found is None:
            raise _refuse(path, f"exists and is not a gslam {command} result (gslam replaces only files it wrote, "
                                "even with --force); give a new file name", flag)
        if found != command and not force:
            raise _refuse(path, f"is a gslam {found} result, not a {command} result; give a new file name, or "
                                "--force to replace it", flag)
    if not target.parent.is_dir():
        raise _refuse(path, f"cannot be written: no folder {target.parent}", flag)
    if not os.access(target.parent, os.W_OK | os.X_OK):
        raise _refuse(path, f"cannot be written: {target.parent} (permission denied)", flag)
    remove_stale_temps(target.parent)
    return path
