"""Every shell command in the README and docs/*.md runs as written.

The commands are read from the pages' fenced ``bash``/``console`` blocks.
Quick: every ``gslam`` command parses with gslam's own argument parser and
names configs that exist, and the commands too long for a test run their
``--help`` form. Slow: each page's blocks run verbatim, in order, in a
fresh folder (``../shared/data`` beside it is the data root), and write
nothing outside the paths they name. Two stand-ins: ``my_robot.bag`` is the
Husky bag of the data root, ``/path/to/data`` the data root itself.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from slam.cli import build_parser
from slam.readers.datasets import data_root
from slam.resources import resolve_config_path

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
SHELLS = {"bash", "sh", "shell", "console"}
HUSKY = "rosbag/test1_husky_2015.bag"

# Commands a test does not run whole: the prefix, the form run instead
# (None: none) and why.
NOT_RUN = {
    "python3 -m venv": (None, "creates a virtual environment and installs gslam from the package index"),
    "gslam ablate configs/ablations/gating_policy.yaml": (
        "gslam ablate --help", "330 jobs: 3 scenarios x 10 seeds x 11 variants"),
    "python -m scripts.bench all": ("python -m scripts.bench all --help", "every bench, about 30 minutes"),
    "python -m scripts.bench gating": ("python -m scripts.bench gating --help", "a whole bench over 10 seeds"),
}


@dataclass(frozen=True)
class Command:
    page: Path
    line: int  # 1-based, in the page
    text: str  # as written (console: without the prompt)

    def __str__(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.line}: {self.text}"

    def argv(self) -> list[str]:
        env = {"GSLAM_DATA": str(data_root())}
        return [re.sub(r"\$(\w+)", lambda m: env.get(m.group(1), m.group(0)), w)
                for w in shlex.split(self.text, comments=True)]

    def instead(self) -> tuple[str | None, str] | None:
        return next((v for k, v in NOT_RUN.items() if self.text.startswith(k)), None)


@dataclass(frozen=True)
class Block:
    page: Path
    lang: str
    commands: tuple[Command, ...]
    output: str  # console: what the page shows the commands print


def blocks(page: Path) -> list[Block]:
    text = page.read_text()
    found = []
    for m in re.finditer(r"^```(\w*)[^\n]*\n(.*?)^```", text, flags=re.S | re.M):
        if m.group(1) not in SHELLS:
            continue
        first = text.count("\n", 0, m.start(2)) + 1
        commands, output = [], []
        for i, line in enumerate(m.group(2).splitlines()):
            if m.group(1) == "console":
                if line.startswith("$ "):
                    commands.append(Command(page, first + i, line[2:].strip()))
                else:
                    output.append(line)
            elif line.strip() and not line.lstrip().startswith("#"):
                commands.append(Command(page, first + i, line.strip()))
        found.append(Block(page, m.group(1), tuple(commands), "\n".join(output)))
    return found


ALL = [c for page in PAGES for b in blocks(page) for c in b.commands]


def test_the_pages_have_commands_and_every_exception_is_still_on_them():
    assert len(ALL) > 30
    for prefix in NOT_RUN:
        assert any(c.text.startswith(prefix) for c in ALL), f"NOT_RUN names a command no page has: {prefix}"


@pytest.mark.parametrize("command", [c for c in ALL if c.text.startswith("gslam ")], ids=str)
def test_every_gslam_command_parses_and_names_configs_that_exist(command, capsys):
    argv = command.argv()
    try:
        args = build_parser().parse_args(argv[1:])
    except SystemExit:
        pytest.fail(f"{command}: {capsys.readouterr().err.strip()}")
    for word in argv[1:]:
        if word.startswith("configs/"):
            assert resolve_config_path(word).is_file(), f"{command}: no shipped {word}"
    assert args.func is not None


@pytest.mark.parametrize("command", [c for c in ALL if not c.text.startswith("gslam ") and c.instead()
                                     and c.instead()[0]], ids=str)
def test_the_long_commands_run_in_their_help_form(command):
    done = _shell(command.instead()[0], ROOT)
    assert done.returncode == 0 and "usage" in done.stdout, f"{command}: {done.stderr[-2000:]}"


def _shell(script: str, cwd: Path, env: dict | None = None, timeout: float = 900) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", "-c", script], cwd=cwd, env=env or _env(), capture_output=True, text=True,
                          timeout=timeout, stdin=subprocess.DEVNULL)


def _env() -> dict:
    """gslam and python of this environment first on the PATH; GSLAM_DATA
    set, as docs/datasets.md's first block sets it for the others."""
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env["GSLAM_DATA"] = str(data_root())
    return env


def _script(block: Block) -> str:
    """The block as one script, the commands as written, the ones NOT_RUN
    replaced by their short form; the two stand-ins filled in."""
    lines = ["set -e"]
    for c in block.commands:
        instead = c.instead()
        text = c.text if instead is None else instead[0]
        if text is not None:
            lines.append(text.replace("/path/to/data", str(data_root())))
    return "\n".join(lines) + "\n"


def _outputs(block: Block) -> set[str]:
    """The paths a block's commands write (--out, --config-out)."""
    out = set()
    for c in block.commands:
        if c.text.startswith("gslam ") and c.instead() is None:
            argv = c.argv()
            out |= {argv[i + 1] for i, w in enumerate(argv[:-1]) if w in ("--out", "--config-out")}
    return out


def _tree(folder: Path) -> dict[str, tuple]:
    return {str(p.relative_to(folder)): (p.stat().st_mtime_ns, p.stat().st_size)
            for p in folder.rglob("*") if p.is_file()}


@pytest.mark.slow
@pytest.mark.parametrize("page", [p for p in PAGES if any(b.commands for b in blocks(p))], ids=lambda p: p.name)
def test_every_page_runs_as_written(page, tmp_path):
    data = data_root()
    if not (data / HUSKY).is_file():
        pytest.skip(f"real data not found: {data / HUSKY} (set GSLAM_DATA to the data folder); the pages' commands "
                    "read it, and my_robot.bag stands for it")
    work = tmp_path / "work"
    work.mkdir()
    (tmp_path / "shared").mkdir()
    (tmp_path / "shared" / "data").symlink_to(data.resolve())
    (work / "my_robot.bag").symlink_to(data.resolve() / HUSKY)
    data_before = _tree(data)
    written: set[str] = set()
    for block in blocks(page):
        if not block.commands:
            continue
        # Commands of the repository's own scripts run from its root, as the pages say.
        cwd = ROOT if all(c.text.startswith(("python ", "export ")) for c in block.commands) else work
        done = _shell(_script(block), cwd)
        assert done.returncode == 0, f"{page.name}: the block of line {block.commands[0].line} failed:\n" \
                                     f"{_script(block)}{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
        for shown in re.findall(r"^wrote (\S+?)[:,]?(?:\s|$)", block.output, flags=re.M):
            assert re.search(rf"^wrote {re.escape(shown)}(?=[\s:,]|$)", done.stdout, flags=re.M), \
                f"{page.name}: the page shows 'wrote {shown}', the command printed:\n{done.stdout[-3000:]}"
        if cwd == work:
            written |= _outputs(block)
    # Nothing outside the paths the commands name: the first folders of
    # those paths, and nothing beside them.
    assert {p.name for p in tmp_path.iterdir()} == {"work", "shared"}
    expected = {Path(p).parts[0] for p in written} | {"my_robot.bag"}
    assert {p.name for p in work.iterdir()} <= expected
    for top in {Path(p).parts[0] for p in written if len(Path(p).parts) >= 2}:
        inside = {Path(p).parts[1] for p in written if Path(p).parts[0] == top}
        assert {p.name for p in (work / top).iterdir()} == inside
    assert _tree(data) == data_before
