"""The checks of the output rule (:mod:`slam.results.outdir`), made before
anything is written: the path itself, the command's inputs, what stands at
``--out`` and at the names the command writes, and the free space."""

from __future__ import annotations

import errno
import os
import stat
from collections.abc import Iterable
from enum import Enum
from pathlib import Path

from slam.errors import GslamError
from slam.results.tempfiles import NAME_MAX
from slam.results.records import MARKERS, RESULT_MARKER, Record, in_the_way, result_command, result_input
from validation.base.yamlio import special_file

_FULL = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)


class Existing(Enum):
    """What ``--out`` is before the command runs."""

    NEW = "new"  # nothing there, or an empty folder
    SAME = "same"  # an earlier result of this command
    FORCED = "forced"  # a folder that is not such a result, with force


# --- checks shared by every output -------------------------------------------------


def resolve_path(path: str | Path) -> Path:
    """``path`` made absolute with every link followed, as ``Path.resolve``
    does, but a loop of links (``a -> a``, a folder linked into itself) is
    a one-line :class:`GslamError` naming it instead of pathlib's
    RuntimeError (Python 3.13 raises OSError, said as one line too)."""
    try:
        return Path(path).resolve()
    except RuntimeError:
        raise GslamError(f"{path}: too many levels of symbolic links (a link that leads back to itself)") from None


def refuse(out: Path | str, why: str, flag: str = "--out") -> GslamError:
    return GslamError(f"{out}: {flag} {why}")


def check_out_path(out: str | Path, flag: str = "--out") -> Path:
    """The checks that need no command: not empty, not a symbolic link, a
    device, a pipe or a socket, not the root. Returns ``out`` as a path."""
    if isinstance(out, str) and not out.strip():
        raise GslamError(f"{flag} is empty; give a path (an unset shell variable?)")
    out = Path(out)
    _check_name_lengths(out, flag)
    _check_way_up(out, flag)
    try:
        mode = out.lstat().st_mode
    except OSError:
        mode = None
    if mode is not None and stat.S_ISLNK(mode):
        raise refuse(out, "is a symbolic link; give the place it points to, or a new name", flag)
    if mode is not None and special_file(mode):
        raise refuse(out, f"is {special_file(mode)}, not a regular file or folder; give a new name", flag)
    if resolve_path(out).parent == resolve_path(out):
        raise refuse(out, "is the file system root; give a new folder name", flag)
    return out


def _check_name_lengths(out: Path, flag: str) -> None:
    """Each name of the path within :data:`NAME_MAX` bytes: under a folder
    still to be made, a longer one was found only when the result was moved
    into place, after the work, and said '--out was filled by someone
    else'."""
    for part in out.parts:
        size = len(os.fsencode(part))
        if size > NAME_MAX:
            shown = part if len(part) <= 60 else f"{part[:40]}...{part[-12:]}"
            raise refuse(out, f"has a name of {size} bytes ({shown}); a file system takes at most {NAME_MAX}, give a "
                              "shorter one", flag)


def _check_way_up(out: Path, flag: str) -> None:
    """A ``..`` after a name that is no folder (``runs/typo/..``) leads
    nowhere the system can go, while ``Path.resolve`` reads it as the folder
    above: the output would be checked as new and found full only when it is
    moved into place, after the work. Such a path is refused first."""
    walked = Path(out.anchor)
    for part in out.parts[1 if out.anchor else 0:]:
        if part == ".." and not (walked or Path(".")).is_dir():
            raise refuse(out, f"goes up from {walked}, which is not a folder; give the path without '..'", flag)
        walked /= part


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def check_inputs(out: Path, target: Path, inputs: Iterable[str | Path], flag: str = "--out") -> None:
    """``target`` must not be an input, hold one, or lie inside an input folder."""
    for given in inputs:
        if given is None or str(given) == "":
            continue
        path = Path(given)
        if not path.exists():
            continue
        p = resolve_path(path)
        if p == target or _same_file(p, target):
            raise refuse(out, f"is the input {given}; give a new name", flag)
        if target in p.parents:
            raise refuse(out, f"holds the input {given}; give a new folder name", flag)
        if p.is_dir() and (p in target.parents or any(_same_file(p, a) for a in target.parents)):
            raise refuse(out, f"is inside the input folder {given}; give a place elsewhere", flag)


def classify(out: str | Path, command: str, inputs: Iterable[str | Path] = (), force: bool = False) -> Existing:
    """Check a result folder ``out`` against the rule of the module
    docstring, without writing anything; a one-line :class:`GslamError` if
    it is refused."""
    inputs = list(inputs)
    out = check_out_path(out)
    target = resolve_path(out)
    check_inputs(out, target, inputs)
    if not out.exists():
        return Existing.NEW
    if not out.is_dir():
        raise refuse(out, "exists and is not a folder; give a new folder name")
    found = result_command(out)
    if found == command:
        earlier, now = result_input(out), source_of(inputs)
        if earlier is not None and now is not None and earlier != now and not force:
            raise refuse(out, f"holds the gslam {command} result of {earlier}, not of {now}; give a new folder "
                               "name, or --force to replace it")
        return Existing.SAME
    if not any(out.iterdir()):
        return Existing.NEW
    if force:
        return Existing.FORCED
    if found:
        what = f"a gslam {found} result, not a {command} result"
    elif (out / RESULT_MARKER).exists():
        what = f"not a gslam {command} result (its {RESULT_MARKER} is not one gslam wrote)"
    else:
        what = f"not a gslam {command} result (no {RESULT_MARKER})"
    raise refuse(
        out, f"is a folder that is {what}; give a new folder name, or --force to add the {command} files "
        "to it (nothing of yours there is replaced)"
    )


def source_of(inputs: Iterable[str | Path]) -> str | None:
    """The input a result is made from, as its marker records it: the
    first of a command's inputs, as an absolute path."""
    for given in inputs:
        if given is None or str(given) == "":
            return None
        return str(resolve_path(given))
    return None


def check_free(out: Path, folder: Path, need_bytes: int | None) -> None:
    if not need_bytes:
        return
    try:
        st = os.statvfs(folder)
    except OSError:
        return
    if st.f_blocks == 0:  # a file system that does not say (proc, some network ones)
        return
    free = st.f_bavail * st.f_frsize
    if free < need_bytes:
        raise refuse(out, f"needs about {_mb(need_bytes)} and {folder} has {_mb(free)} free; free some space "
                           "or give a place on another disk")


def _mb(n: int) -> str:
    return f"{n / 2**20:.1f} MB" if n < 2**30 else f"{n / 2**30:.1f} GB"


def disk_full(e: OSError) -> bool:
    """The error of a full disk or quota (or a file size limit)."""
    return e.errno in _FULL


def make_parents(out: Path, folder: Path) -> list[Path]:
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
            remove_empty(missing)
            raise refuse(out, f"cannot be created: {p} ({e.strerror})") from None
    return missing


def remove_empty(folders: list[Path]) -> None:
    for p in folders:  # deepest first
        try:
            p.rmdir()
        except OSError:
            pass


def check_names(out: Path, target: Path, command: str, names: Iterable[str], record: Record | None,
                 what: str = "may write") -> None:
    names = [n for n in names if n not in MARKERS]
    blocked = in_the_way(target, names, record)
    if blocked is not None:
        raise refuse(out, f"holds {blocked}, which gslam {command} {what} and did not write; nothing was "
                           "written: move it, or give another folder")
