"""Result folders: the one rule every command follows for ``--out``.

A result folder carries a marker, ``.gslam-result.json``, naming the
command that wrote it. ``--out`` must be

* new (or an empty folder), or
* an earlier result of the same command, recognised by its marker; it is
  replaced whole.

Anything else is a one-line :class:`GslamError` before any work starts: a
file, a folder that is not a result of this command, the input itself, a
folder holding an input, a folder inside an input folder, a symbolic link,
or a place that cannot be written. ``force`` lets a command write into a
folder that is not its result: its files replace files of the same name,
nothing else there is touched or deleted, and no marker is written (so a
later run without ``force`` still refuses the folder). The input rules hold
even with ``force``.

*Atomic* commands (simulate, map, compare) build their result in a
temporary sibling ``.NAME.gslam-tmp-PID-HOST-XXXXXXXX/`` and rename it into
place at the end, so a killed run leaves a complete result or none. The
name carries the process id and a tag of the host that made it (so it is
recognisable from the moment it exists; ``.gslam-tmp.json`` inside says the
same for a reader), and a later run towards the same ``--out`` removes those
of this host whose process is gone. Nothing named otherwise is removed.

*Container* commands (ablate, demo) fill their folder in place, each part
atomically, so that an interrupted run resumes; :func:`open_container`
checks the folder and writes the marker first.

Everything is created with the permissions the umask allows (0644 files,
0755 folders under the usual umask), never the 0600/0700 of ``tempfile``.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import re
import secrets
import shutil
import socket
import time
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path

from slam.errors import GslamError

log = logging.getLogger(__name__)

RESULT_MARKER = ".gslam-result.json"
TEMP_MARKER = ".gslam-tmp.json"
TEMP_TAG = ".gslam-tmp-"


class Existing(Enum):
    """What ``--out`` is before the command runs."""

    NEW = "new"  # nothing there, or an empty folder
    SAME = "same"  # an earlier result of this command: replaced whole
    FORCED = "forced"  # a folder that is not such a result, with force: merged into


def result_command(folder: Path) -> str | None:
    """The command whose result ``folder`` is, or None if it is none."""
    try:
        data = json.loads((folder / RESULT_MARKER).read_text())
    except (OSError, ValueError):
        return None
    command = data.get("command") if isinstance(data, dict) else None
    return command if isinstance(command, str) else None


def write_marker(folder: Path, command: str) -> None:
    """Mark ``folder`` as a result of ``command``."""
    from slam import __version__

    data = {"command": command, "version": __version__, "created": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
    (folder / RESULT_MARKER).write_text(json.dumps(data, indent=2) + "\n")


# --- checks ------------------------------------------------------------------------


def _refuse(out: Path, why: str) -> GslamError:
    return GslamError(f"{out}: --out {why}")


def _check_inputs(out: Path, target: Path, inputs: Iterable[str | Path]) -> None:
    """``target`` must not be an input, hold one, or lie inside an input folder."""
    for given in inputs:
        path = Path(given)
        if not path.exists():
            continue
        p = path.resolve()
        if p == target:
            raise _refuse(out, "is the input; give a new folder name")
        if target in p.parents:
            raise _refuse(out, f"holds the input {given}; give a new folder name")
        if p.is_dir() and p in target.parents:
            raise _refuse(out, f"is inside the input folder {given}; give a folder elsewhere")


def classify(out: str | Path, command: str, inputs: Iterable[str | Path] = (), force: bool = False) -> Existing:
    """Check ``out`` against the rule of the module docstring, without
    writing anything; raise a one-line :class:`GslamError` if it is refused."""
    out = Path(out)
    if out.is_symlink():
        raise _refuse(out, "is a symbolic link; give the folder it points to, or a new name")
    target = out.resolve()
    if target.parent == target:
        raise _refuse(out, "is the file system root; give a new folder name")
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
        out, f"is a folder that is {what}; give a new folder name, or --force to write the {command} files "
        "into it (nothing else there is touched)"
    )


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


# --- temporary folders -------------------------------------------------------------------


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def host_tag() -> str:
    """8 hex digits naming this host in temporary names."""
    return hashlib.sha1(socket.gethostname().encode()).hexdigest()[:8]


def temp_name(target: Path, kind: str = "") -> Path:
    """A fresh temporary name beside ``target`` that says who made it."""
    return target.with_name(f".{target.name}{TEMP_TAG}{os.getpid()}-{host_tag()}-{kind}{secrets.token_hex(4)}")


def remove_stale_temps(target: Path) -> list[Path]:
    """Remove the temporary folders that killed runs left beside ``target``:
    named ``.NAME.gslam-tmp-PID-HOST-...`` by a process of this host that is
    gone. Anything else is left alone. Returns what was removed."""
    removed: list[Path] = []
    if not target.parent.is_dir():
        return removed
    pattern = re.compile(re.escape(f".{target.name}{TEMP_TAG}") + r"(\d+)-([0-9a-f]{8})-(?:old)?[0-9a-f]{8}")
    for p in target.parent.glob(f".{target.name}{TEMP_TAG}*"):
        owner = pattern.fullmatch(p.name)
        if owner is None or not p.is_dir() or p.is_symlink():
            continue
        if owner.group(2) != host_tag() or _process_alive(int(owner.group(1))):
            continue
        log.info("removing %s, left by a killed run", p)
        shutil.rmtree(p, ignore_errors=True)
        removed.append(p)
    return removed


def _make_temp(out: Path, target: Path, command: str) -> Path:
    """A new temporary folder beside ``target``, named as this process's."""
    for _ in range(100):
        tmp = temp_name(target)
        try:
            tmp.mkdir()
        except FileExistsError:
            continue
        except OSError as e:
            raise _refuse(out, f"cannot be written: {target.parent} ({e.strerror})") from None
        marker = {"host": socket.gethostname(), "pid": os.getpid(), "command": command, "target": str(target)}
        try:
            (tmp / TEMP_MARKER).write_text(json.dumps(marker) + "\n")
        except OSError as e:
            shutil.rmtree(tmp, ignore_errors=True)
            raise _refuse(out, f"cannot be written: {target.parent} ({e.strerror})") from None
        return tmp
    raise _refuse(out, f"cannot be written: no free temporary name in {target.parent}")


# --- atomic results ----------------------------------------------------------------


@dataclass
class ResultFolder:
    """A result being built: write into :attr:`tmp`; :meth:`publish` puts it
    at :attr:`target` by the rule of the module docstring."""

    out: Path
    target: Path
    command: str
    existing: Existing
    tmp: Path
    created: list[Path] = field(default_factory=list)

    @classmethod
    def prepare(cls, out: str | Path, command: str, inputs: Iterable[str | Path] = (), force: bool = False) -> "ResultFolder":
        """Every check, then the temporary folder (which proves ``out`` is
        writable); nothing of the user's is touched."""
        out = Path(out)
        existing = classify(out, command, inputs, force)
        target = out.resolve()
        created = _make_parents(out, target.parent)
        remove_stale_temps(target)
        try:
            tmp = _make_temp(out, target, command)
        except GslamError:
            _remove_empty(created)
            raise
        return cls(out, target, command, existing, tmp, created)

    def publish(self) -> Path:
        """Put the finished result in place; returns ``out``."""
        (self.tmp / TEMP_MARKER).unlink()
        if self.existing is Existing.FORCED:
            _merge(self.tmp, self.target)
            shutil.rmtree(self.tmp, ignore_errors=True)
            return self.out
        write_marker(self.tmp, self.command)
        if self.existing is Existing.SAME and result_command(self.target) == self.command:
            _replace(self.tmp, self.target)
        else:
            try:
                os.rename(self.tmp, self.target)  # also over an empty folder
            except OSError as e:
                raise _refuse(self.out, f"was filled by someone else while this command ran ({e.strerror})") from None
        return self.out

    def discard(self) -> None:
        """Remove the temporary folder and the parents this run created."""
        shutil.rmtree(self.tmp, ignore_errors=True)
        _remove_empty(self.created)


@contextmanager
def result_folder(
    out: str | Path, command: str, inputs: Iterable[str | Path] = (), force: bool = False
) -> Iterator[Path]:
    """``with result_folder(out, "map", [input]) as tmp:`` write into ``tmp``;
    on success the result is published at ``out``, on any error (or a kill)
    nothing of it remains."""
    folder = ResultFolder.prepare(out, command, inputs, force)
    try:
        yield folder.tmp
        folder.publish()
    finally:
        if folder.tmp.exists():
            folder.discard()


def _replace(new: Path, target: Path) -> None:
    """Swap ``new`` in for the earlier result ``target``; the old folder is
    renamed to a temporary name first, so a kill between the renames leaves
    it recognisable for the next run to remove."""
    old = temp_name(target, "old")
    os.rename(target, old)
    os.rename(new, target)
    shutil.rmtree(old, ignore_errors=True)


def _merge(src: Path, dst: Path) -> None:
    """Move every entry of ``src`` into ``dst``: files replace files of the
    same name, folders merge, and a subfolder that is a result of the same
    command as the one coming in is replaced whole."""
    for entry in sorted(src.iterdir()):
        there = dst / entry.name
        if not there.exists() and not there.is_symlink():
            os.rename(entry, there)
        elif entry.is_dir() and there.is_dir() and not there.is_symlink():
            incoming = result_command(entry)
            if incoming is not None and incoming == result_command(there):
                _replace(entry, there)
            else:
                _merge(entry, there)
        elif entry.is_file() and there.is_file() and not there.is_symlink():
            os.replace(entry, there)
        else:
            raise GslamError(f"{there}: in the way of the result (a file where a folder goes, or the reverse); "
                             f"the new result was not written there")


# --- containers --------------------------------------------------------------------


def open_container(out: str | Path, command: str, inputs: Iterable[str | Path] = (), force: bool = False) -> Path:
    """Check ``out`` for a command that fills its folder in place (ablate,
    demo), create it and mark it (unless forced into a foreign folder)."""
    out = Path(out)
    existing = classify(out, command, inputs, force)
    target = out.resolve()
    created = _make_parents(out, target.parent)
    if existing is Existing.NEW:
        try:
            target.mkdir(exist_ok=True)
            write_marker(target, command)
        except OSError as e:
            _remove_empty(created)
            raise _refuse(out, f"cannot be written ({e.strerror})") from None
    elif not os.access(target, os.W_OK | os.X_OK):
        raise _refuse(out, "cannot be written (permission denied)")
    return out


def result_file_mark(command: str) -> str:
    """The first line of a text file ``command`` wrote as its result."""
    return f"# gslam {command} result"


def _marked(path: Path, command: str) -> bool:
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            return f.readline().startswith(result_file_mark(command))
    except OSError:
        return False


def check_new_file(path: str | Path, inputs: Iterable[str | Path] = (), force: bool = False,
                   command: str | None = None) -> Path:
    """A single output file (``--config-out``, calibrate's ``--out``): new,
    an earlier result of ``command`` (its first line is
    :func:`result_file_mark`), or replaced with ``force``; never an input, a
    folder or a symbolic link."""
    path = Path(path)
    target = path.resolve()
    for given in inputs:
        if Path(given).exists() and Path(given).resolve() == target:
            raise GslamError(f"{path}: is the input; give a new file name")
    if path.is_symlink():
        raise GslamError(f"{path}: is a symbolic link; give the file it points to, or a new name")
    if path.is_dir():
        raise GslamError(f"{path}: is a folder; give a file name")
    if path.exists() and not force and not (command is not None and _marked(path, command)):
        what = f" and is not a gslam {command} result" if command is not None else ""
        raise GslamError(f"{path}: exists{what}; give a new file name, or --force to replace it")
    if not target.parent.is_dir():
        raise GslamError(f"{path}: no folder {target.parent}")
    return path
