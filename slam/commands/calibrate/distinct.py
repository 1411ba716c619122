"""The runs a calibration is given, each recording once: a recording given
twice would count its steps twice and halve each false alarm's weight in
silence. Two runs are one recording when their paths lead to the same
file or folder (another spelling, a link, a hard link, a run folder and
its ``bag/``), or when their recordings hold the same bytes (a copy).
"""

from __future__ import annotations

import hashlib
import logging
from collections.abc import Sequence
from pathlib import Path

from slam.readers.read import is_run_folder, run_recording

log = logging.getLogger(__name__)


def _recording(path: Path) -> Path:
    """The recording a run path reads: a run folder's ``bag/`` (or the one file in it)."""
    return run_recording(path) if is_run_folder(path) else path


def _identity(path: Path) -> tuple:
    """The file or folder ``path`` leads to (device, inode); a path that
    cannot be looked at is its own identity (its reader says why)."""
    try:
        st = _recording(path).stat()
    except OSError:
        return ("path", str(path))
    return ("file", st.st_dev, st.st_ino)


def _files(recording: Path) -> list[Path]:
    """The regular files a recording is made of, in a fixed order."""
    if recording.is_file():
        return [recording]
    return sorted(p for p in recording.rglob("*") if p.is_file() and not p.is_symlink())


def _size(path: Path) -> int | None:
    try:
        return sum(f.stat().st_size for f in _files(_recording(path)))
    except OSError:
        return None


def _digest(path: Path) -> str | None:
    """A hash of the recording's files (names within it and bytes); None if one cannot be read."""
    recording = _recording(path)
    h = hashlib.sha256()
    try:
        for f in _files(recording):
            h.update(str(f.relative_to(recording) if f != recording else "").encode() + b"\0")
            with open(f, "rb") as data:
                for block in iter(lambda: data.read(1 << 20), b""):
                    h.update(block)
    except OSError:
        return None
    return h.hexdigest()


def distinct_runs(runs: Sequence[str | Path]) -> list[str | Path]:
    """``runs`` with every recording kept once, in the order given (module
    docstring), and one warning line naming the repeats. Only recordings
    of the same size are read to compare their bytes."""
    kept: dict[tuple, str | Path] = {}
    repeats: list[str] = []
    for run in runs:
        key = _identity(Path(run))
        if key in kept:
            repeats.append(f"{run} (the recording of {kept[key]})")
        else:
            kept[key] = run
    sizes = {run: _size(Path(run)) for run in kept.values()}
    seen: dict[str, str | Path] = {}
    copies: set[str | Path] = set()
    for run, size in sizes.items():
        if size is None or list(sizes.values()).count(size) < 2:
            continue
        digest = _digest(Path(run))
        if digest is None:
            continue
        if digest in seen:
            repeats.append(f"{run} (a copy of the recording of {seen[digest]})")
            copies.add(run)
        else:
            seen[digest] = run
    if repeats:
        log.warning("%d of the %d runs given repeat a recording; each recording is learnt from once: %s",
                    len(repeats), len(runs), "; ".join(repeats))
    return [run for run in kept.values() if run not in copies]
