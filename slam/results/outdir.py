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
marker (:mod:`slam.results.records`), made from the same input (the first of
the command's inputs: the recording, the scenario, the spec): replacing
the result of another input needs ``--force``, and the refusal names it.
The marker lists the files the command wrote: running again replaces
those and removes the ones it no longer writes; every other file there
(notes, the user's own figures) stays. A marker is input: one that names
a path outside its folder is refused, and nothing is removed through a link.
``--force`` writes into a folder that is not such a result: the command's
files join the user's, recorded as gslam's in ``.gslam-added.json``, and
replace nothing but what an earlier forced run of the same command wrote.

The result is built in a temporary sibling and put in place at the end
(:class:`ResultFolder`): renamed whole when nothing of the user's is in the
way, else file by file with the stopping signals held back until it
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

Every command creates the missing folders on the way to its ``--out``
(and ``--config-out``): a result folder's before its work starts (removed
again if it fails), a single file's as the file is written.

Everything is created with the permissions the umask allows (0644 files,
0755 folders under the usual umask), never the 0600/0700 of ``tempfile``.
"""

from __future__ import annotations

import errno
import logging
import os
import shutil
import sqlite3
import stat
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from slam.errors import GslamError
from slam.results.out_checks import (
    Existing, check_free, check_inputs, check_names, check_out_path, classify, disk_full, make_parents, refuse,
    remove_empty, resolve_path, source_of,
)
from slam.results.records import (
    ADDED_MARKER, MARKERS, RESULT_MARKER, Record, inside, list_files, only_gslams, read_record, result_command,
    write_added_record, write_result_marker,
)
from slam.results.atomic import atomic_path
from slam.results.tempfiles import TEMP_MARKER, TEMP_TAG, host_tag, make_temp_dir, remove_stale_temps, temp_name
from slam.processes.signals import held

__all__ = [
    "ADDED_MARKER", "RESULT_MARKER", "TEMP_MARKER", "TEMP_TAG", "Existing", "ResultFolder", "check_new_file",
    "check_out_path", "classify", "host_tag", "open_container", "remove_stale_temps", "result_command",
    "result_file_mark", "result_folder", "disk_full", "file_state", "write_result_file",
]

log = logging.getLogger(__name__)


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
    source: str | None = None  # the input the result is made from, for its marker

    @classmethod
    def prepare(cls, out: str | Path, command: str, inputs: Iterable[str | Path] = (), force: bool = False,
                names: Iterable[str] = (), need_bytes: int | None = None) -> "ResultFolder":
        """Every check, then the temporary folder (which proves ``out`` is
        writable); nothing of the user's is touched. ``names``: the files
        (and folders, ending in ``/``) the command will write, checked
        against what stands there; ``need_bytes``: the space it will need."""
        inputs = list(inputs)
        existing = classify(out, command, inputs, force)
        out = Path(out)
        target = resolve_path(out)
        record = read_record(target, command) if existing is not Existing.NEW else None
        if existing is not Existing.NEW:
            check_names(out, target, command, names, record)
        source = source_of(inputs)  # before any folder is made: an input can be a loop of links
        folder = None
        try:
            # From the first folder made to the object that removes it, a
            # signal waits (and is raised here, where the folder is removed).
            with held():
                created = make_parents(out, target.parent)
                remove_stale_temps(target.parent)
                try:
                    tmp = make_temp_dir(target, command)
                except OSError as e:
                    remove_empty(created)
                    raise refuse(out, f"cannot be written: {target.parent} ({e.strerror or e})") from None
                folder = cls(out, target, command, existing, tmp, record, created, source)
            check_free(out, target.parent, need_bytes)
        except BaseException:
            if folder is not None:
                folder.discard()
            raise
        return folder

    def publish(self) -> Path:
        """Put the finished result in place; returns ``out``."""
        (self.tmp / TEMP_MARKER).unlink()
        files = list_files(self.tmp, skip=MARKERS)
        if self.existing is Existing.NEW:
            write_result_marker(self.tmp, self.command, files, self.source)
            try:
                os.rename(self.tmp, self.target)  # also over an empty folder
            except OSError as e:
                raise refuse(self.out, f"was filled by someone else while this command ran ({e.strerror})") from None
            return self.out
        record = read_record(self.target, self.command)
        if self.existing is Existing.SAME and record is not None and not record.added and only_gslams(self.target, record):
            write_result_marker(self.tmp, self.command, files, self.source)
            _swap(self.tmp, self.target)
            return self.out
        self._publish_in_place(files, record)
        return self.out

    def _publish_in_place(self, files: set[str], record: Record | None) -> None:
        """Move the files in one by one, beside the user's: first check that
        nothing of the user's is in the way, then move with the signals held
        back, the marker listing old and new files until the old are gone."""
        check_names(self.out, self.target, self.command, files, record, what="would replace")
        old = set(record.files or ()) if record is not None else set()
        added = self.existing is Existing.FORCED

        def mark(names: set[str]) -> None:
            if added:
                write_added_record(self.target, self.command, names)
            else:
                write_result_marker(self.target, self.command, names, self.source)

        with held():
            mark(old | files)
            for name in sorted(files):
                dest = self.target / name
                dest.parent.mkdir(parents=True, exist_ok=True)
                os.replace(self.tmp / name, dest)
            for name in sorted(old - files):
                _remove_file(self.target, name)
            mark(files)
        shutil.rmtree(self.tmp, ignore_errors=True)

    def discard(self) -> None:
        """Remove the temporary folder and the parents this run created."""
        shutil.rmtree(self.tmp, ignore_errors=True)
        remove_empty(self.created)

    def hide(self, text: str) -> str:
        """``text`` with the temporary folder named as the result it becomes."""
        return text.replace(str(self.tmp), str(self.out))


def _remove_file(target: Path, name: str) -> None:
    """Remove a file gslam wrote earlier and no longer writes, and the
    folders it leaves empty; nothing outside ``target`` or behind a link."""
    path = inside(target, name)
    if path is None:
        return
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
    with held():
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
    folder: ResultFolder | None = None
    try:
        folder = ResultFolder.prepare(out, command, inputs, force, names, need_bytes)
        yield folder.tmp
        folder.publish()
    except sqlite3.Error as e:  # a ROS 2 bag being written (simulate, inject)
        why = "no space left to write" if "full" in str(e) else "cannot write"
        raise GslamError(f"{out}: {why} the {command} result's bag ({e}); nothing was written") from None
    except OSError as e:
        if disk_full(e):
            raise GslamError(f"{out}: no space left to write the {command} result ({e.strerror}); "
                             "nothing was written") from None
        if folder is not None and e.filename is not None and str(folder.tmp) in str(e.filename):
            raise GslamError(folder.hide(f"{e.filename}: {e.strerror or e}")) from None
        raise
    except GslamError as e:
        if folder is not None and str(folder.tmp) in str(e):
            raise GslamError(folder.hide(str(e))) from None
        raise
    finally:
        if folder is not None and folder.tmp.exists():
            folder.discard()


# --- containers --------------------------------------------------------------------


def open_container(out: str | Path, command: str, inputs: Iterable[str | Path] = (), force: bool = False,
                   names: Iterable[str] = ()) -> Path:
    """Check ``out`` for a command that fills its folder in place (ablate,
    demo), create and mark it; ``names``: the files and folders (ending in
    ``/``) it writes there, which must not be the user's when forced into
    a folder of theirs (they are then recorded as gslam's)."""
    inputs = list(inputs)
    existing = classify(out, command, inputs, force)
    out = Path(out)
    target = resolve_path(out)
    source = source_of(inputs)  # before any folder is made: an input can be a loop of links
    created = make_parents(out, target.parent)
    remove_stale_temps(target.parent)
    try:
        if existing is Existing.NEW:
            target.mkdir(exist_ok=True)
            write_result_marker(target, command, None, source)
        elif not os.access(target, os.W_OK | os.X_OK):
            raise refuse(out, "cannot be written (permission denied)")
        elif existing is Existing.FORCED:
            record = read_record(target, command)
            names = list(names)
            check_names(out, target, command, names, record)
            write_added_record(target, command, {n.rstrip("/") for n in names})
        elif force and (record := read_record(target, command)) is not None and record.input != source:
            write_result_marker(target, command, None, source)  # forced onto another input's container
    except OSError as e:
        remove_empty(created)
        raise refuse(out, f"cannot be written ({e.strerror})") from None
    except GslamError:
        remove_empty(created)
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


def file_state(path: str | Path) -> tuple[int, int, int, int] | None:
    """What :func:`write_result_file` compares: ``path``'s device, inode,
    size and time of change, or None if there is no file."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns


def write_result_file(path: str | Path, text: str, checked: tuple[int, int, int, int] | None,
                      flag: str = "--out") -> None:
    """Write ``text`` to ``path``, checked by :func:`check_new_file` when
    its :func:`file_state` was ``checked``, atomically, but never over a
    file that came there, or changed, while the command ran: another
    command writing the same file at once, or a file the user saved there.
    A new file is linked to its name, which fails if one came meanwhile."""
    path = Path(path)
    gone = refuse(path, "was written by someone else while this command ran; nothing was written (give a new "
                        "file name)", flag)

    def place(tmp: Path, path: Path) -> None:
        if checked is None:
            try:
                os.link(tmp, path)
                return
            except FileExistsError:
                raise gone from None
            except OSError as e:
                if e.errno not in (errno.EPERM, errno.EOPNOTSUPP, errno.ENOTSUP, errno.EMLINK):
                    raise
            if file_state(path) is not None:  # a file system without hard links: the check, then the rename
                raise gone
        elif file_state(path) != checked:
            raise gone
        os.replace(tmp, path)

    with atomic_path(path, place) as tmp:
        tmp.write_text(text)


def check_new_file(path: str | Path, inputs: Iterable[str | Path] = (), force: bool = False,
                   command: str | None = None, flag: str = "--out") -> Path:
    """A single output file (``--config-out``, calibrate's ``--out``): new,
    or an earlier result of ``command`` (its first line is
    :func:`result_file_mark`), or with ``force`` a result of another gslam
    command; never an input or a file inside an input folder, a folder, a
    link, a device, a pipe or a file of the user's."""
    if str(path).endswith((os.sep, os.sep + ".")):  # Path() would drop it, and write a file where a folder was meant
        raise refuse(path, "ends in '/', which names a folder; give a file name", flag)
    path = check_out_path(path, flag)
    target = resolve_path(path)
    check_inputs(path, target, inputs, flag)
    if path.is_dir():
        raise refuse(path, "is a folder; give a file name", flag)
    if path.exists():
        found = file_mark(path)
        if found is None:
            raise refuse(path, f"exists and is not a gslam {command} result (gslam replaces only files it wrote, "
                                "even with --force); give a new file name", flag)
        if found != command and not force:
            raise refuse(path, f"is a gslam {found} result, not a {command} result; give a new file name, or "
                                "--force to replace it", flag)
    # Missing folders on the way are created, as for a result folder: here
    # the nearest one that exists must be a folder that can be written.
    nearest = target.parent
    while not nearest.exists() and nearest.parent != nearest:
        nearest = nearest.parent
    if not nearest.is_dir():
        raise refuse(path, f"cannot be written: {nearest} is not a folder", flag)
    if not os.access(nearest, os.W_OK | os.X_OK):
        raise refuse(path, f"cannot be written: {nearest} (permission denied)", flag)
    if nearest == target.parent:
        remove_stale_temps(target.parent)
    return path
