"""Where a result page came from: the command line, the package's version,
the git commit of the source it ran from, the input and the config.

A reader of ``report.html`` weeks later, without the terminal it was made
in, finds here what to run again. The commit is that of the source tree
gslam ran from (an editable install in a git checkout); an installed
package has none, nor a checkout without git: ``unknown``.
"""

from __future__ import annotations

import hashlib
import shlex
import subprocess
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

UNKNOWN = "unknown"
_DISTRIBUTION = "gated-slam"
_SOURCE_ROOT = Path(__file__).resolve().parents[2]  # the folder holding slam/ (a checkout, or site-packages)


@dataclass(frozen=True)
class Provenance:
    """``command``: the command line; ``version``: gated-slam's; ``commit``:
    the source's git commit or ``unknown``; ``input``: the input path as
    given and resolved; ``config``: the config path; ``config_sha256``:
    SHA-256 of the config as used (every default spelled out, as a result's
    ``config.yaml`` holds it)."""

    command: str
    version: str
    commit: str
    input: str
    config: str
    config_sha256: str

    def rows(self) -> list[tuple[str, str]]:
        """(label, value) pairs, in the order a page shows them."""
        return [
            ("command", self.command),
            ("gated-slam version", self.version),
            ("git commit", self.commit),
            ("input", self.input),
            ("config", self.config),
            ("config sha256", self.config_sha256),
        ]


def collect(input_path: str | Path, config_path: str | Path | None, config_text: str,
            command: str | None = None) -> Provenance:
    """The provenance of a result made from ``input_path`` with the config
    read from ``config_path`` (None: the built-in defaults) and used as
    ``config_text``; ``command``: the command line (default: this
    process's, :func:`command_line`)."""
    given = Path(input_path)
    shown = str(given) if given.is_absolute() else f"{given} ({given.resolve()})"
    return Provenance(
        command=command if command is not None else command_line(),
        version=package_version(),
        commit=git_commit(),
        input=shown,
        config=str(config_path) if config_path is not None else "built-in defaults",
        config_sha256=hashlib.sha256(config_text.encode("utf-8")).hexdigest(),
    )


def command_line(argv: Sequence[str] | None = None) -> str:
    """``argv`` (default ``sys.argv``) as a shell would take it back, the
    program by its name (``gslam``, not the path of its script)."""
    args = list(sys.argv if argv is None else argv)
    if not args:
        return UNKNOWN
    return shlex.join([Path(args[0]).name, *args[1:]])


def package_version() -> str:
    """gated-slam's installed version, ``unknown`` when it is not installed
    (run from a copy of the source)."""
    try:
        return metadata.version(_DISTRIBUTION)
    except metadata.PackageNotFoundError:
        return UNKNOWN


def git_commit(root: Path = _SOURCE_ROOT) -> str:
    """The commit checked out at ``root`` (with ``+ local changes`` when
    the tracked files differ from it), where ``root`` is the top of a git
    checkout of gated-slam; ``unknown`` otherwise (an installed package,
    no git, a folder inside someone else's repository)."""
    if not (root / "pyproject.toml").is_file() or not (root / ".git").exists():
        return UNKNOWN
    try:
        top = _git(root, "rev-parse", "--show-toplevel")
        if top is None or Path(top).resolve() != root.resolve():  # git found a repository further up
            return UNKNOWN
        head = _git(root, "rev-parse", "--verify", "HEAD")
        dirty = _git(root, "status", "--porcelain", "--untracked-files=no")
    except (OSError, subprocess.SubprocessError):
        return UNKNOWN
    if head is None:
        return UNKNOWN
    return f"{head} + local changes" if dirty else head


def _git(root: Path, *args: str) -> str | None:
    done = subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, timeout=10,
                          stdin=subprocess.DEVNULL)
    return done.stdout.strip() if done.returncode == 0 else None
