"""Atomic file writing: a killed run leaves a complete file or none.

The temporary file is ``.NAME.gslam-tmp-XXXXXXXX.SUFFIX`` beside its target
(recognisably ours, see :mod:`slam.io.outdir`), created with the permissions
the umask allows, as an ordinary file would be.
"""

from __future__ import annotations

import os
import secrets
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

from slam.io.outdir import TEMP_TAG


def _new_temp_file(path: Path) -> Path:
    while True:
        tmp = path.with_name(f".{path.stem}{TEMP_TAG}{secrets.token_hex(4)}{path.suffix}")
        try:
            os.close(os.open(tmp, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666))
        except FileExistsError:
            continue
        return tmp


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it over ``path`` on
    success, delete it on failure. Use for writers that want a file name
    (open3d, matplotlib)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp_path = _new_temp_file(path)
    try:
        yield tmp_path
        os.replace(tmp_path, path)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def write_text(path: str | Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)
