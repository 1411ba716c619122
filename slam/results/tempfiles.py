"""gslam's temporary files and folders, and removing those of killed runs.

Every result is built under a temporary name beside its place and renamed
into it (:mod:`slam.results.outdir`, :mod:`slam.results.atomic`). The name says who
made it from the moment it exists::

    .NAME.gslam-tmp-PID-HOST-XXXXXXXX[.SUFFIX]

(the process id, 8 hex digits naming the host, a random tag; a folder also
holds ``.gslam-tmp.json`` saying the same for a reader). A run that writes
into a folder first removes, from that folder, the temporary files and
folders of this host whose process is gone: what a killed run (SIGKILL, a
power cut) left. Nothing named otherwise is removed, nor anything of a live
process or another host.
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
from pathlib import Path

log = logging.getLogger(__name__)

TEMP_TAG = ".gslam-tmp-"
TEMP_MARKER = ".gslam-tmp.json"
_TEMP_NAME = re.compile(r"\..*" + re.escape(TEMP_TAG) + r"(\d+)-([0-9a-f]{8})-(?:old)?[0-9a-f]{8}(?:\.[^/]*)?", re.S)


def host_tag() -> str:
    """8 hex digits naming this host in temporary names."""
    return hashlib.sha1(socket.gethostname().encode()).hexdigest()[:8]


NAME_MAX = 255
"""The longest file name (bytes) of Linux's file systems."""


def temp_name(target: Path, kind: str = "", suffix: str = "") -> Path:
    """A fresh temporary name beside ``target`` that says who made it;
    ``kind`` is ``""`` or ``"old"`` (a replaced result on its way out).
    Within :data:`NAME_MAX` bytes: of a long ``target`` name (an --out of
    250 characters is a valid name) only the start is kept, else the
    temporary name alone would be too long and the result could not be
    written."""
    tag = f"{os.getpid()}-{host_tag()}-{kind}{secrets.token_hex(4)}"
    around = len(f".{TEMP_TAG}{tag}".encode()) + len(os.fsencode(suffix))
    name = os.fsencode(target.name)[: max(NAME_MAX - around, 1)]
    return target.with_name(f".{os.fsdecode(name)}{TEMP_TAG}{tag}{suffix}")


def new_temp_file(path: Path) -> Path:
    """Create an empty temporary file beside ``path`` (same suffix, for
    writers that choose a format by it), with the permissions the umask
    allows."""
    while True:
        tmp = temp_name(path, suffix=path.suffix)
        try:
            os.close(os.open(tmp, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666))
        except FileExistsError:
            continue
        return tmp


def make_temp_dir(target: Path, command: str) -> Path:
    """Create a temporary folder beside ``target`` with its marker; OSError
    if the parent cannot be written."""
    for _ in range(100):
        tmp = temp_name(target)
        try:
            tmp.mkdir()
        except FileExistsError:
            continue
        marker = {"host": socket.gethostname(), "pid": os.getpid(), "command": command, "target": str(target)}
        try:
            (tmp / TEMP_MARKER).write_text(json.dumps(marker) + "\n")
        except OSError:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        return tmp
    raise FileExistsError(f"no free temporary name in {target.parent}")


def is_temp_name(name: str) -> bool:
    """True for a name gslam gives its temporary files and folders."""
    return _TEMP_NAME.fullmatch(name) is not None


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def is_stale(path: Path) -> bool:
    """A temporary file or folder of this host whose process is gone."""
    owner = _TEMP_NAME.fullmatch(path.name)
    if owner is None or path.is_symlink():
        return False
    return owner.group(2) == host_tag() and not _process_alive(int(owner.group(1)))


def remove_stale_temps(folder: Path) -> list[Path]:
    """Remove from ``folder`` the temporary files and folders that killed
    runs of this host left (see the module docstring); returns them."""
    removed: list[Path] = []
    try:
        entries = list(folder.iterdir())
    except OSError:
        return removed
    for p in entries:
        if TEMP_TAG not in p.name or not is_stale(p):
            continue
        log.info("removing %s, left by a killed run", p)
        try:
            if p.is_dir():
                shutil.rmtree(p)
            else:
                p.unlink()
        except OSError as e:
            log.warning("%s: left by a killed run, cannot be removed (%s)", p, e.strerror)
            continue
        removed.append(p)
    return removed
