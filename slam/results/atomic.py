"""Atomic file writing: a killed run leaves a complete file or none.

The temporary file is named as :mod:`slam.results.tempfiles` says (recognisably
gslam's, with its process id, so a later run removes it if the process was
killed), beside its target, with the permissions the umask allows, as an
ordinary file would be.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

from slam.results.tempfiles import new_temp_file


@contextmanager
def atomic_path(path: str | Path, place: Callable[[Path, Path], None] = os.replace) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success ``place`` it at
    ``path`` (renamed over it by default), delete it on failure. Use for
    writers that want a file name (open3d, matplotlib)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp_path = new_temp_file(path)
    try:
        yield tmp_path
        place(tmp_path, path)
    except OSError as e:  # named as the file being written, not its temporary name
        if e.filename is not None and str(tmp_path) not in str(e.filename):
            raise
        raise OSError(e.errno, e.strerror, str(path)) from None
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def write_text(path: str | Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)
