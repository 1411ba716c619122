"""Where matplotlib keeps its settings and font cache while gslam runs.

matplotlib keeps them in the user's ``~/.config/matplotlib`` and
``~/.cache/matplotlib`` (``$XDG_CONFIG_HOME``, ``$XDG_CACHE_HOME``),
creating every missing folder on the way. Where those cannot be made in
the user's home (``HOME`` naming a folder that does not exist, a file, a
folder that cannot be written), it created the missing folders wherever
``HOME`` pointed, or said so in two warning lines and left a folder of its
own in the temporary folder (gslam ends without the exit handler that
removes it). gslam then gives it a temporary folder of its own, removed
when the command ends; a home that holds or can hold them is used as every
matplotlib program uses it, and ``MPLCONFIGDIR`` set by the user is kept
where it can hold them (the temporary folder stands in for one that names a
file, a folder beneath a file, or a folder that cannot be written). In the
temporary folder matplotlib builds its font cache afresh each run and, on
a busy machine where that takes over 5 s, says so in a warning line: gslam's
own doing, so that line alone is not shown.
"""

from __future__ import annotations

import logging
import os
import shutil
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

__all__ = ["plot_home"]


def _can_make(folder: Path, levels: int = 2) -> bool:
    """``folder`` is a folder that can be written, or can be made by making
    at most ``levels`` folders (``.config/matplotlib`` in a home) in one
    that can: never a home made from nothing, never beneath a file."""
    place = folder
    for _ in range(levels):
        if place.exists():
            break
        place = place.parent
    return place.is_dir() and os.access(place, os.W_OK | os.X_OK)


def _defaults_usable() -> bool:
    try:
        home = Path.home()
    except (KeyError, RuntimeError):  # no HOME and no password entry
        return False
    if not sys.platform.startswith(("linux", "freebsd")):
        return _can_make(home / ".matplotlib", levels=1)
    config = Path(os.environ.get("XDG_CONFIG_HOME") or home / ".config")
    cache = Path(os.environ.get("XDG_CACHE_HOME") or home / ".cache")
    return _can_make(config / "matplotlib") and _can_make(cache / "matplotlib")


@contextmanager
def plot_home() -> Iterator[None]:
    """While the command runs (and its worker processes, which inherit the
    environment), matplotlib's folders are the user's if they can be, else
    a temporary folder removed at the end; and ``MPLBACKEND`` is unset:
    gslam draws its figures into files, never in a window, and a backend
    matplotlib does not know (a typo) ended its import with a traceback."""
    backend = os.environ.pop("MPLBACKEND", None)
    try:
        with _settings_folder():
            yield
    finally:
        if backend is not None:
            os.environ["MPLBACKEND"] = backend


@contextmanager
def _settings_folder() -> Iterator[None]:
    given = os.environ.get("MPLCONFIGDIR")
    if (_can_make(Path(given)) if given else _defaults_usable()):
        yield
        return
    # A home, or an MPLCONFIGDIR, that cannot hold them (a file, beneath a
    # file, read-only): matplotlib said so in two lines and left a folder in
    # the temporary folder.
    folder = tempfile.mkdtemp(prefix="gslam-matplotlib-")
    os.environ["MPLCONFIGDIR"] = folder
    fonts = logging.getLogger("matplotlib.font_manager")
    fonts.addFilter(_no_cache_notice)
    try:
        yield
    finally:
        fonts.removeFilter(_no_cache_notice)
        if given:
            os.environ["MPLCONFIGDIR"] = given
        else:
            del os.environ["MPLCONFIGDIR"]
        shutil.rmtree(folder, ignore_errors=True)


def _no_cache_notice(record: logging.LogRecord) -> bool:
    """Not matplotlib's notice that it is building its font cache."""
    return "building the font cache" not in record.getMessage()
