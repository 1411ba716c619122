"""What gslam wrote into a folder: its result markers.

* ``.gslam-result.json``: the folder is a result of ``command``, ``input``
  names what it was made from (absolute; absent in older markers), and
  ``files`` lists every file it wrote there (paths relative to the folder;
  a marker of gslam 0.1 before the list has none: see :class:`Record`).
* ``.gslam-added.json``: files that commands wrote with ``--force`` into a
  folder that is not their result, per command.

A command replaces or removes only files that one of these lists as its
own; everything else in a folder is the user's (:func:`in_the_way`).
A marker is read from disk, so it is input like any other: a list that
names a path outside its folder (absolute, with ``..``, or through a link)
is refused with one line (:class:`BadMarker`), and a file is removed only
where no link lies on its way (:func:`inside`).
A single-file result (calibrate's config, inspect's starter) says whose it
is in its first line instead (:func:`file_mark`).
"""

from __future__ import annotations

import json
import os
import re
import stat
import time
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from slam.errors import GslamError
from validation.base.yamlio import unique_keys

RESULT_MARKER = ".gslam-result.json"
# A name read from a file that becomes a file or folder name (a scenario's,
# a variant's): one plain path part, never a way out of its folder.
PLAIN_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+-]{0,99}")
PLAIN_NAME_RULE = "ASCII letters and digits and _.+- (not starting with . or -), at most 100 characters"
ADDED_MARKER = ".gslam-added.json"
MARKERS = (RESULT_MARKER, ADDED_MARKER)


@dataclass(frozen=True)
class Record:
    """The files ``command`` wrote into a folder. ``files`` None: a marker
    of an older gslam without the list, whose files are taken to be those
    of the names the command writes (replaced, never removed)."""

    command: str
    files: frozenset[str] | None
    added: bool = False  # written with --force into a folder that is not its result
    input: str | None = None  # what the result was made from, where the marker says


class BadMarker(GslamError):
    """A marker gslam never writes (one that names a path outside its
    folder, an input that is no path): ``why`` says what is wrong."""

    def __init__(self, marker: Path, why: str):
        super().__init__(f"{marker}: {why}; gslam never writes such a marker, so nothing there is replaced or "
                         "removed: move the marker away and run again")


def _read_json(path: Path) -> dict | None:
    try:
        st = path.lstat()
        if not stat.S_ISREG(st.st_mode) or st.st_size > 64 * 2**20:
            return None
        data = json.loads(path.read_text(), object_pairs_hook=unique_keys)
    except (OSError, ValueError, RecursionError):  # RecursionError: JSON nested too deeply
        return None
    return data if isinstance(data, dict) else None


def plain_relative(name: object) -> bool:
    """True for a relative POSIX path whose every part is a plain name
    (no ``..``, ``.``, empty part, NUL or absolute start)."""
    if not isinstance(name, str) or not name or "\0" in name or name.startswith("/"):
        return False
    return all(part not in ("", ".", "..") for part in name.split("/"))


def _files(value, marker: Path) -> frozenset[str] | None:
    """The marker's list of files; None where it has none (a marker of
    gslam 0.1); :class:`BadMarker` for anything gslam never writes there."""
    if value is None:
        return None
    if not isinstance(value, list):
        raise BadMarker(marker, f"lists {value!r}, which is not a file inside the folder")
    for name in value:
        if not plain_relative(name):
            raise BadMarker(marker, f"lists {name!r}, which is not a file inside the folder")
    return frozenset(value)


def _input(value, marker: Path) -> str | None:
    """The marker's input; None where it names none (a marker of gslam 0.1)."""
    if value is None:
        return None
    if not isinstance(value, str) or not value:
        raise BadMarker(marker, f"its input {value!r} is not a path")
    return value


def _read_added(folder: Path) -> dict:
    """The ``--force`` record of ``folder`` ({} where there is none); a
    record that is there but not one gslam wrote is refused, never
    overwritten: it may be all that tells gslam's files from the user's."""
    path = Path(folder) / ADDED_MARKER
    data = _read_json(path)
    if data is None and (path.exists() or path.is_symlink()):
        raise BadMarker(path, "not a record gslam wrote (not a JSON object)")
    return data or {}


def result_command(folder: Path) -> str | None:
    """The command whose result ``folder`` is, or None if it is none."""
    data = _read_json(Path(folder) / RESULT_MARKER)
    command = data.get("command") if data is not None else None
    return command if isinstance(command, str) else None


def result_input(folder: Path) -> str | None:
    """What the result in ``folder`` was made from, where its marker says."""
    marker = Path(folder) / RESULT_MARKER
    data = _read_json(marker)
    return _input(data.get("input"), marker) if data is not None else None


def read_record(folder: Path, command: str) -> Record | None:
    """What ``command`` wrote into ``folder``, as its result or added with
    ``--force``; None if it wrote nothing there. :class:`BadMarker` if the
    marker names a path outside ``folder``."""
    folder = Path(folder)
    data = _read_json(folder / RESULT_MARKER)
    if data is not None and data.get("command") == command:
        marker = folder / RESULT_MARKER
        return Record(command, _files(data.get("files"), marker), input=_input(data.get("input"), marker))
    added = _read_added(folder)
    entry = added.get(command)
    if isinstance(entry, dict):
        return Record(command, _files(entry.get("files"), folder / ADDED_MARKER) or frozenset(), added=True)
    return None


def inside(folder: Path, name: str) -> Path | None:
    """``folder / name`` if every folder on its way there is a real folder
    (no link, nothing outside ``folder``); None otherwise."""
    if not plain_relative(name):
        return None
    node = folder
    for part in name.split("/")[:-1]:
        node = node / part
        try:
            if not stat.S_ISDIR(node.lstat().st_mode):
                return None
        except OSError:
            return None
    return folder / name


def _stamp() -> dict:
    from slam import __version__

    return {"version": __version__, "created": time.strftime("%Y-%m-%dT%H:%M:%S%z")}


def _write_json(path: Path, data: dict) -> None:
    from slam.results.atomic import write_text

    write_text(path, json.dumps(data, indent=2) + "\n")


def write_result_marker(folder: Path, command: str, files: set[str] | frozenset[str] | None,
                        source: str | None = None) -> None:
    """Mark ``folder`` as a result of ``command`` made from ``source``
    holding ``files`` (None: a container, filled over several runs)."""
    data = {"command": command, **_stamp()}
    if source is not None:
        data["input"] = source
    if files is not None:
        data["files"] = sorted(files)
    _write_json(folder / RESULT_MARKER, data)


def write_added_record(folder: Path, command: str, files: set[str] | frozenset[str]) -> None:
    """Record that ``command`` added ``files`` to ``folder`` with --force."""
    data = _read_added(folder)
    data[command] = {**_stamp(), "files": sorted(files)}
    _write_json(folder / ADDED_MARKER, data)


def list_files(folder: Path, skip: tuple[str, ...] = ()) -> set[str]:
    """Every file and symbolic link under ``folder`` (relative POSIX paths),
    without the top-level names in ``skip``."""
    found: set[str] = set()
    for root, dirs, files in os.walk(folder):
        rel = PurePosixPath(Path(root).relative_to(folder).as_posix())
        for name in files + [d for d in dirs if (Path(root) / d).is_symlink()]:
            path = (rel / name).as_posix()
            if path not in skip:
                found.add(path)
        dirs[:] = [d for d in dirs if not (Path(root) / d).is_symlink()]
    return found


def only_gslams(folder: Path, record: Record) -> bool:
    """True if everything in ``folder`` is listed in ``record`` (or is a
    marker): replacing the folder whole loses nothing of the user's."""
    if record.files is None:
        return False
    for root, dirs, files in os.walk(folder):
        rel = Path(root).relative_to(folder)
        for name in files:
            path = (rel / name).as_posix()
            if path not in record.files and path not in MARKERS:
                return False
            if not stat.S_ISREG((Path(root) / name).lstat().st_mode):
                return False
        for d in dirs:
            prefix = (rel / d).as_posix() + "/"
            if (Path(root) / d).is_symlink() or not any(f.startswith(prefix) for f in record.files):
                return False
    return True


def in_the_way(target: Path, names, record: Record | None) -> str | None:
    """The first of ``names`` (relative paths of files, or of folders
    ending in ``/``) that ``target`` holds as something gslam may not
    replace: a file (or folder, link, device...) that ``record`` does not
    list as the command's own, or a file where a folder goes and the
    reverse. None if every name is free."""
    mine = record.files if record is not None else frozenset()
    legacy = record is not None and record.files is None
    for name in sorted(names):
        is_dir = name.endswith("/")
        parts = PurePosixPath(name.rstrip("/")).parts
        node = target
        for i, part in enumerate(parts):
            node = node / part
            try:
                mode = node.lstat().st_mode
            except FileNotFoundError:
                break
            except OSError:
                return "/".join(parts[: i + 1])
            last = i == len(parts) - 1
            rel = "/".join(parts[: i + 1])
            if not last or is_dir:
                if not stat.S_ISDIR(mode):
                    return rel
                continue
            if not stat.S_ISREG(mode) or not (legacy or rel in mine):
                return rel
    return None
