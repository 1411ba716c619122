"""The --out rule (slam/results/outdir.py): by itself, then for every command."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from slam.cli import main
from slam.errors import GslamError
from slam.results.atomic import write_text
from slam.results.outdir import (
    ADDED_MARKER, RESULT_MARKER, TEMP_MARKER, ResultFolder, host_tag, open_container, remove_stale_temps, result_folder,
)
from tests.conftest import REPO, TELEMAX_CONFIG


def listing(folder: Path) -> set[str]:
    return {p.name for p in folder.iterdir()}


def build(out: Path, command: str = "map", inputs=(), force: bool = False, files=("a.txt",)) -> None:
    with result_folder(out, command, inputs, force) as tmp:
        for name in files:
            (tmp / name).parent.mkdir(parents=True, exist_ok=True)
            (tmp / name).write_text(f"{name} by {command}\n")


# --- the rule ----------------------------------------------------------------------


def test_new_result_is_marked_and_leaves_nothing_beside_it(tmp_path):
    out = tmp_path / "deep" / "er" / "out"
    build(out)
    assert listing(out) == {"a.txt", RESULT_MARKER}
    assert json.loads((out / RESULT_MARKER).read_text())["command"] == "map"
    assert listing(out.parent) == {"out"}


def test_an_earlier_result_of_the_same_command_is_replaced_whole(tmp_path):
    out = tmp_path / "out"
    build(out, files=("a.txt", "old.txt"))
    build(out, files=("a.txt",))
    assert listing(out) == {"a.txt", RESULT_MARKER}
    assert json.loads((out / RESULT_MARKER).read_text())["files"] == ["a.txt"]
    assert listing(tmp_path) == {"out"}


def test_an_earlier_result_keeps_every_file_the_command_did_not_write(tmp_path):
    out = tmp_path / "out"
    build(out, files=("a.txt", "old.txt", "sub/b.txt", "gone/c.txt"))
    (out / "notes.txt").write_text("mine\n")
    (out / "sub" / "figure.png").write_bytes(b"my own figure")
    (out / "mine").mkdir()
    build(out, files=("a.txt", "sub/b.txt", "new.txt"))
    assert listing(out) == {"a.txt", "sub", "new.txt", "notes.txt", "mine", RESULT_MARKER}  # old.txt, gone/ removed
    assert listing(out / "sub") == {"b.txt", "figure.png"}
    assert (out / "notes.txt").read_text() == "mine\n" and (out / "sub" / "figure.png").read_bytes() == b"my own figure"
    assert (out / "a.txt").read_text() == "a.txt by map\n"
    assert json.loads((out / RESULT_MARKER).read_text())["files"] == ["a.txt", "new.txt", "sub/b.txt"]
    assert listing(tmp_path) == {"out"}


def test_a_file_of_the_users_where_the_result_goes_is_refused_before_anything_moves(tmp_path):
    out = tmp_path / "out"
    build(out, files=("a.txt",))
    (out / "b.txt").write_text("mine\n")  # b.txt: not written by the earlier run
    with pytest.raises(GslamError, match=r"out: --out holds b.txt, which gslam map would replace and did not write"):
        build(out, files=("a.txt", "b.txt"))
    assert (out / "b.txt").read_text() == "mine\n" and (out / "a.txt").read_text() == "a.txt by map\n"
    (out / "b.txt").unlink()
    (tmp_path / "elsewhere").write_text("precious\n")
    (out / "b.txt").symlink_to(tmp_path / "elsewhere")  # a link where a file goes: not gslam's either
    with pytest.raises(GslamError, match="holds b.txt"):
        build(out, files=("a.txt", "b.txt"))
    assert (tmp_path / "elsewhere").read_text() == "precious\n"
    assert listing(tmp_path) == {"out", "elsewhere"}


def test_a_legacy_marker_without_a_file_list_replaces_names_and_removes_nothing(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / RESULT_MARKER).write_text(json.dumps({"command": "map"}))
    (out / "a.txt").write_text("old a\n")
    (out / "notes.txt").write_text("mine\n")
    build(out, files=("a.txt",))
    assert (out / "a.txt").read_text() == "a.txt by map\n" and (out / "notes.txt").read_text() == "mine\n"


# --- a marker is input ----------------------------------------------------------------


def sentinels(tmp_path: Path) -> dict[Path, bytes]:
    """Files of the user's beside and above a result folder, with their bytes."""
    files = {tmp_path / "victim.txt": b"precious\n", tmp_path / "outside" / "v.txt": b"mine\n"}
    for path, data in files.items():
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)
    return files


def unchanged(files: dict[Path, bytes]) -> bool:
    return all(p.is_file() and not p.is_symlink() and p.read_bytes() == data for p, data in files.items())


@pytest.mark.parametrize("listed", ["../victim.txt", "{tmp}/victim.txt", "a/../../victim.txt", "./a.txt", "a//b.txt",
                                    "", 7])
@pytest.mark.parametrize("force", [False, True])
def test_a_marker_that_names_a_path_outside_its_folder_is_refused(tmp_path, listed, force):
    victims = sentinels(tmp_path)
    out = tmp_path / "out"
    build(out, files=("a.txt",))
    marker = json.loads((out / RESULT_MARKER).read_text())
    marker["files"].append(listed.format(tmp=tmp_path) if isinstance(listed, str) else listed)
    (out / RESULT_MARKER).write_text(json.dumps(marker))
    # A number in the list is refused too: only a marker without a list is an old gslam's.
    with pytest.raises(GslamError, match=r"\.gslam-result\.json: lists .* not a file inside the folder") as e:
        build(out, force=force, files=("b.txt",))
    assert "\n" not in str(e.value)
    assert unchanged(victims) and (out / "a.txt").exists()


def test_an_added_record_that_names_a_path_outside_its_folder_is_refused(tmp_path):
    victims = sentinels(tmp_path)
    out = tmp_path / "mine"
    out.mkdir()
    (out / ADDED_MARKER).write_text(json.dumps({"map": {"files": ["../victim.txt"]}}))
    with pytest.raises(GslamError, match=r"\.gslam-added\.json: lists '\.\./victim\.txt'"):
        build(out, force=True, files=("b.txt",))
    assert unchanged(victims)


def test_nothing_is_removed_through_a_linked_folder(tmp_path):
    victims = sentinels(tmp_path)
    out = tmp_path / "out"
    build(out, files=("a.txt", "sub/v.txt"))
    (out / "sub" / "v.txt").unlink()
    (out / "sub").rmdir()
    (out / "sub").symlink_to(tmp_path / "outside")  # sub/v.txt, as the marker lists it, is now the user's file
    for force in (False, True):
        build(out, force=force, files=("a.txt",))
        assert unchanged(victims)
    assert (out / "sub").is_symlink()


def test_replacing_the_result_of_another_input_needs_force(tmp_path):
    first, second = tmp_path / "a.bag", tmp_path / "b.bag"
    for path in (first, second):
        path.write_text("bag\n")
    out = tmp_path / "out"
    build(out, inputs=[first])
    assert json.loads((out / RESULT_MARKER).read_text())["input"] == str(first.resolve())
    build(out, inputs=[first])  # the same input: replaced
    with pytest.raises(GslamError, match=rf"--out holds the gslam map result of {first.resolve()}, not of "
                                         rf"{second.resolve()}; .*--force"):
        build(out, inputs=[second], files=("b.txt",))
    assert listing(out) == {"a.txt", RESULT_MARKER}
    build(out, inputs=[second], force=True, files=("b.txt",))
    assert listing(out) == {"b.txt", RESULT_MARKER}
    assert json.loads((out / RESULT_MARKER).read_text())["input"] == str(second.resolve())


def test_a_container_of_another_input_needs_force(tmp_path):
    first, second = tmp_path / "a.yaml", tmp_path / "b.yaml"
    for path in (first, second):
        path.write_text("name: x\n")
    out = open_container(tmp_path / "sweep", "ablate", [first])
    with pytest.raises(GslamError, match=f"ablate result of {first.resolve()}, not of {second.resolve()}"):
        open_container(out, "ablate", [second])
    open_container(out, "ablate", [second], force=True)
    assert open_container(out, "ablate", [second]) == out


def test_an_empty_folder_is_new(tmp_path):
    (tmp_path / "out").mkdir()
    build(tmp_path / "out")
    assert listing(tmp_path / "out") == {"a.txt", RESULT_MARKER}


@pytest.mark.parametrize("force", [False, True])
def test_a_file_is_refused_even_with_force(tmp_path, force):
    (tmp_path / "out").write_text("precious\n")
    with pytest.raises(GslamError, match="exists and is not a folder"):
        build(tmp_path / "out", force=force)
    assert (tmp_path / "out").read_text() == "precious\n" and listing(tmp_path) == {"out"}


def test_a_foreign_folder_is_refused_and_force_adds_the_commands_files(tmp_path):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("mine\n")
    with pytest.raises(GslamError, match=r"mine: --out is a folder that is not a gslam map result .*--force"):
        build(out)
    build(out, force=True, files=("a.txt", "b.txt"))
    assert listing(out) == {"notes.txt", "a.txt", "b.txt", ADDED_MARKER}  # no result marker: still not a map result
    assert json.loads((out / ADDED_MARKER).read_text())["map"]["files"] == ["a.txt", "b.txt"]
    with pytest.raises(GslamError, match="not a gslam map result"):
        build(out)
    build(out, force=True, files=("a.txt",))  # its own files, as recorded: replaced, b.txt removed
    assert listing(out) == {"notes.txt", "a.txt", ADDED_MARKER}
    assert (out / "notes.txt").read_text() == "mine\n"


def test_force_replaces_nothing_of_the_users(tmp_path):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "a.txt").write_text("my a\n")
    with pytest.raises(GslamError, match=r"mine: --out holds a.txt, which gslam map may write and did not write"):
        ResultFolder.prepare(out, "map", force=True, names=["a.txt", "b.txt"])  # refused before any work
    with pytest.raises(GslamError, match=r"holds a.txt, which gslam map would replace"):
        build(out, force=True, files=("a.txt", "b.txt"))  # and when it was not foreseen: before anything moves
    assert listing(out) == {"a.txt"} and (out / "a.txt").read_text() == "my a\n"
    assert listing(tmp_path) == {"mine"}


def test_a_result_of_another_command_is_refused(tmp_path):
    build(tmp_path / "run", command="simulate")
    with pytest.raises(GslamError, match="is a folder that is a gslam simulate result, not a map result"):
        build(tmp_path / "run")


@pytest.mark.parametrize("force", [False, True])
def test_the_input_is_never_the_output(tmp_path, force):
    run = tmp_path / "runs" / "lab"
    run.mkdir(parents=True)
    (run / "truth.json").write_text("{}")
    cases = {run: "is the input", tmp_path / "runs": "holds the input", tmp_path: "holds the input",
             run / "maps": "is inside the input folder"}
    for out, message in cases.items():
        with pytest.raises(GslamError, match=message):
            build(out, inputs=[run], force=force)
    assert listing(run) == {"truth.json"} and listing(tmp_path / "runs") == {"lab"}


def test_unwritable_places_are_refused_before_any_work(tmp_path):
    (tmp_path / "f").write_text("x")
    with pytest.raises(GslamError, match="cannot be written: /proc"):
        build(Path("/proc/gslam-out"))
    with pytest.raises(GslamError, match=r"cannot be written: .*/f \(Not a directory\)"):
        build(tmp_path / "f" / "out")
    (tmp_path / "target").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "target")
    with pytest.raises(GslamError, match="symbolic link"):
        build(tmp_path / "link")
    assert listing(tmp_path) == {"f", "target", "link"}


def test_a_failing_command_leaves_nothing(tmp_path):
    with pytest.raises(RuntimeError):
        with result_folder(tmp_path / "new" / "out", "map") as tmp:
            (tmp / "half.txt").write_text("half")
            raise RuntimeError("disk full")
    assert listing(tmp_path) == set()  # the parents it created are gone too


def temp_left_by(target: Path, host: str, pid: int) -> Path:
    folder = target.with_name(f".{target.name}.gslam-tmp-{pid}-{host}-{os.urandom(4).hex()}")
    folder.mkdir()
    (folder / TEMP_MARKER).write_text(json.dumps({"pid": pid}))
    (folder / "trajectory.tum").write_text("half")
    return folder


def dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def test_only_recognisable_leftovers_of_dead_processes_are_removed(tmp_path):
    target = tmp_path / "out"
    dead = temp_left_by(target, host_tag(), dead_pid())
    alive = temp_left_by(target, host_tag(), os.getpid())
    elsewhere = temp_left_by(target, "0badc0de" if host_tag() != "0badc0de" else "00000000", dead_pid())
    unmarked = tmp_path / ".out.gslam-tmp-unmarked"
    unmarked.mkdir()
    other_name = temp_left_by(tmp_path / "other", host_tag(), dead_pid())  # another result's, same parent
    dead_file = tmp_path / f".cal.yaml.gslam-tmp-{dead_pid()}-{host_tag()}-0123abcd.yaml"  # an atomic write's
    dead_file.write_text("half")
    users = tmp_path / "notes.gslam-tmp-1-00000000-00000000"  # not hidden: not a gslam name
    users.write_text("mine")
    assert sorted(remove_stale_temps(tmp_path)) == sorted([dead, other_name, dead_file])
    assert {p.name for p in (alive, elsewhere, unmarked, users) if p.exists()} == {
        alive.name, elsewhere.name, unmarked.name, users.name}


def test_a_run_removes_the_leftovers_of_killed_runs_beside_it(tmp_path):
    left = temp_left_by(tmp_path / "earlier", host_tag(), dead_pid())
    build(tmp_path / "out")
    assert listing(tmp_path) == {"out"} and not left.exists()


@pytest.mark.parametrize("umask, file_mode, dir_mode", [(0o022, 0o644, 0o755), (0o077, 0o600, 0o700)])
def test_results_follow_the_umask(tmp_path, umask, file_mode, dir_mode):
    old = os.umask(umask)
    try:
        out = tmp_path / "out"
        with result_folder(out, "map") as tmp:
            (tmp / "sub").mkdir()
            write_text(tmp / "sub" / "atomic.txt", "x")
            (tmp / "plain.txt").write_text("x")
    finally:
        os.umask(old)
    assert out.stat().st_mode & 0o777 == dir_mode
    assert (out / "sub").stat().st_mode & 0o777 == dir_mode
    for f in (out / "sub" / "atomic.txt", out / "plain.txt", out / RESULT_MARKER):
        assert f.stat().st_mode & 0o777 == file_mode, f


def test_containers_are_marked_first_and_reopened(tmp_path):
    out = open_container(tmp_path / "sweep", "ablate")
    assert json.loads((out / RESULT_MARKER).read_text())["command"] == "ablate"
    (out / "jobs").mkdir()
    assert open_container(out, "ablate") == out  # resumed, nothing touched
    assert listing(out) == {RESULT_MARKER, "jobs"}
    with pytest.raises(GslamError, match="a gslam ablate result, not a demo result"):
        open_container(out, "demo")


# --- a killed run --------------------------------------------------------------------


def _processes_naming(path) -> list[int]:
    """Live processes whose command line names ``path`` (Linux /proc)."""
    found = []
    for cmdline in Path("/proc").glob("[0-9]*/cmdline"):
        try:
            text = cmdline.read_bytes().decode(errors="replace")
            state = (cmdline.parent / "stat").read_text().split(")")[-1].split()[0]
        except OSError:
            continue
        if str(path) in text and state != "Z":
            found.append(int(cmdline.parent.name))
    return found


@pytest.mark.slow
def test_a_killed_map_leaves_a_temp_folder_the_next_run_removes(short_run, tmp_path, capsys):
    out = tmp_path / "map"
    argv = ["map", str(short_run.run_dir), "--config", str(TELEMAX_CONFIG), "--out", str(out)]
    proc = subprocess.Popen([sys.executable, "-m", "slam.cli", "-q", *argv], cwd=REPO,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    while not list(tmp_path.glob(".map.gslam-tmp-*")) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    while len(_processes_naming(out)) < 2 and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)  # the scan matcher's process has started
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    left = list(tmp_path.glob(".map.gslam-tmp-*"))
    assert left and not out.exists()  # killed mid-run: no result, a marked temporary folder
    deadline = time.monotonic() + 10
    while _processes_naming(out) and time.monotonic() < deadline:  # its helper processes end with it
        time.sleep(0.05)
    assert not _processes_naming(out)
    assert main(["-q", *argv]) == 0
    capsys.readouterr()
    assert listing(tmp_path) == {"map"}


# --- every command -------------------------------------------------------------------


def run(capsys, *argv) -> tuple[int, str]:
    code = main(["-q", *map(str, argv)])
    _, err = capsys.readouterr()
    return code, err


@pytest.fixture
def commands(short_run, short_scenario_yaml, tmp_path):
    """Each command with a quick valid invocation, given ``--out`` last."""
    spec = tmp_path / "spec.yaml"
    spec.write_text(yaml.safe_dump({
        "name": "one", "config": str(TELEMAX_CONFIG),
        "inputs": {"scenarios": [{"path": str(short_scenario_yaml), "seeds": [1]}]},
        "variants": {"ungated": {"validation.mode": "off"}},
    }))
    quick = ["--set", "output.plots=false"]
    return {
        "simulate": ["simulate", short_scenario_yaml, "--out"],
        "map": ["map", short_run.run_dir, "--config", TELEMAX_CONFIG, *quick, "--out"],
        "compare": ["compare", short_run.run_dir, "--config", TELEMAX_CONFIG, "--only", "ungated", *quick, "--out"],
        "demo": ["demo", "--scenario", short_scenario_yaml, "--only", "ungated", "--out"],
        "ablate": ["ablate", spec, "--workers", "1", "--out"],
        "inject": ["inject", short_run.run_dir, "--fault", "gyro_bias@2:4", "--out"],
    }


def with_other_input(argv: list, folder: Path) -> list:
    """``argv`` with its input (the first argument, or demo's --scenario)
    copied into ``folder``: the same content, another input."""
    i = argv.index("--scenario") + 1 if "--scenario" in argv else 1
    source = Path(argv[i])
    folder.mkdir(exist_ok=True)
    copy = folder / source.name
    if not copy.exists():
        (shutil.copytree if source.is_dir() else shutil.copy)(source, copy)
    return [*argv[:i], copy, *argv[i + 1:]]


@pytest.mark.slow
@pytest.mark.parametrize("command", ["simulate", "map", "compare", "demo", "ablate", "inject", "calibrate", "inspect"])
def test_every_writing_command_creates_the_missing_folders_to_its_output(command, commands, short_run, tmp_path,
                                                                         capsys):
    """One rule for every command that writes: the missing folders on the way
    to ``--out`` (calibrate's file, inspect's ``--config-out``) are created,
    and nothing beside that path is touched (docs/three_commands.md writes
    into a runs/ folder that does not exist yet)."""
    files = {"calibrate": ["calibrate", short_run.run_dir, "--config", TELEMAX_CONFIG, "--clean", "0:10", "--out"],
             "inspect": ["inspect", short_run.run_dir, "--config-out"]}
    argv = files.get(command) or commands[command]
    root = tmp_path / "fresh"
    root.mkdir()
    out = root / "runs" / "new" / ("x.yaml" if command in files else "x")
    code, err = run(capsys, *argv, out)
    assert code == 0, err
    assert out.is_file() if command in files else (out / RESULT_MARKER).is_file()
    assert listing(root) == {"runs"} and listing(root / "runs") == {"new"}
    assert listing(root / "runs" / "new") == {out.name}


@pytest.mark.slow
@pytest.mark.parametrize("command", ["simulate", "map", "compare", "demo", "ablate", "inject"])
def test_out_rule_for_every_command(command, commands, tmp_path, capsys):
    argv = commands[command]
    out = tmp_path / "out"
    # 1. new: written and marked
    code, err = run(capsys, *argv, out)
    assert code == 0, err
    assert json.loads((out / RESULT_MARKER).read_text())["command"] == command
    first = listing(out)
    # 2. again into its own result: replaced (simulate, map, compare) or resumed (demo, ablate)
    code, err = run(capsys, *argv, out)
    assert code == 0, err
    assert listing(out) == first
    # 2b. a marker naming files outside the folder (a marker is input): refused, nothing outside touched
    victims = sentinels(tmp_path)
    poisoned = 0
    for marker in out.rglob(RESULT_MARKER):
        data = json.loads(marker.read_text())
        if isinstance(data.get("files"), list):
            data["files"] += ["../../victim.txt", str(tmp_path / "outside" / "v.txt")]
            marker.write_text(json.dumps(data))
            poisoned += 1
    code, err = run(capsys, *argv, out)
    if command != "ablate":  # a resumed sweep rewrites no finished job: it reads no job's list
        assert poisoned and code == 1 and err.count("\n") == 1 and "not a file inside the folder" in err, err
    assert unchanged(victims)
    shutil.rmtree(out)
    code, err = run(capsys, *argv, out)
    assert code == 0, err
    # 2c. the result of another input: refused, naming the earlier one
    other = tmp_path / "other"
    other_argv = with_other_input(argv, other)
    code, err = run(capsys, *other_argv, out)
    assert code == 1 and err.count("\n") == 1 and f"result of {Path(argv[argv.index('--scenario') + 1] if command == 'demo' else argv[1]).resolve()}, not of" in err, err
    assert listing(out) == first and unchanged(victims)
    # 3. a file, a foreign folder, another command's result: refused, untouched
    (tmp_path / "file").write_text("precious\n")
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("mine\n")
    other = "map" if command != "map" else "simulate"
    for target, says in ((tmp_path / "file", "not a folder"), (mine, f"not a gslam {command} result"),
                         (out, None)):
        if target == out:  # make it another command's result
            (out / RESULT_MARKER).write_text(json.dumps({"command": other}))
            says = f"a gslam {other} result, not a {command} result"
        before = {p.name: p.read_bytes() for p in target.iterdir() if p.is_file()} if target.is_dir() else None
        code, err = run(capsys, *argv, target)
        assert code == 1 and err.count("\n") == 1 and says in err, err
        if before is not None:
            assert {p.name: p.read_bytes() for p in target.iterdir() if p.is_file()} == before
    assert (tmp_path / "file").read_text() == "precious\n"
    # 4. --force into the foreign folder: the command's files join the user's
    code, err = run(capsys, *argv[:-1], "--force", "--out", mine)
    assert code == 0, err
    assert (mine / "notes.txt").read_text() == "mine\n"
    assert not (mine / RESULT_MARKER).exists() and len(listing(mine)) > 1
    # 5. nothing temporary left anywhere
    assert not [p for p in tmp_path.rglob("*") if ".gslam-tmp-" in p.name]


def test_inspect_config_out(short_run, tmp_path, capsys):
    """inspect's --config-out: new, or an earlier starter (replaced); never
    a file of the user's, even with --force."""
    target = tmp_path / "starter.yaml"
    code, err = run(capsys, "inspect", short_run.run_dir, "--config-out", target)
    assert code == 0, err
    assert target.read_text().startswith("# gslam inspect result: a starter config")
    code, err = run(capsys, "inspect", short_run.run_dir, "--config-out", target)
    assert code == 0, err  # its own earlier result
    target.write_text("mine\n")
    for force in ([], ["--force"]):
        code, err = run(capsys, "inspect", short_run.run_dir, "--config-out", target, *force)
        assert code == 1 and "exists and is not a gslam inspect result" in err, err
    assert target.read_text() == "mine\n"


@pytest.mark.slow
def test_calibrate_out_rule(short_run, tmp_path, capsys):
    """calibrate's --out is one file: new, or an earlier calibrate result
    (its first line), replaced; a result of another gslam command only with
    --force; never a file of the user's, a folder, a symbolic link or the
    config."""
    argv = ["calibrate", short_run.run_dir, "--config", TELEMAX_CONFIG, "--clean", "0:10", "--out"]
    out = tmp_path / "cal.yaml"
    code, err = run(capsys, *argv, out)
    assert code == 0, err
    first = out.read_bytes()
    code, err = run(capsys, *argv, out)
    assert code == 0 and out.read_bytes() == first, err
    mine = tmp_path / "mine.yaml"
    mine.write_text("precious\n")
    link = tmp_path / "link.yaml"
    link.symlink_to(out)
    starter = tmp_path / "starter.yaml"
    assert run(capsys, "inspect", short_run.run_dir, "--config-out", starter)[0] == 0
    for target, says in ((mine, "is not a gslam calibrate result"), (link, "symbolic link"), (tmp_path, "is a folder"),
                         (starter, "is a gslam inspect result, not a calibrate result")):
        code, err = run(capsys, *argv, target)
        assert code == 1 and err.count("\n") == 1 and says in err, err
    code, err = run(capsys, *argv[:-1], "--force", "--out", mine)
    assert code == 1 and "is not a gslam calibrate result" in err, err
    assert mine.read_text() == "precious\n" and out.read_bytes() == first
    code, err = run(capsys, *argv[:-1], "--force", "--out", starter)
    assert code == 0 and starter.read_bytes() == first, err
    assert not [p for p in tmp_path.rglob("*") if ".gslam-tmp-" in p.name]


def copy_of(run_dir: Path, where: Path) -> Path:
    import shutil

    shutil.copytree(run_dir, where)
    return where


@pytest.mark.parametrize("force", [[], ["--force"]])
def test_no_file_of_an_input_is_written_even_with_force(short_run, tmp_path, capsys, force):
    run_dir = copy_of(short_run.run_dir, tmp_path / "run")
    config = tmp_path / "c.yaml"
    config.write_text("validation: {mode: \"off\"}\nbackend: {factors: {gps: {enabled: false}}}\n")
    before = {p: p.read_bytes() for p in run_dir.rglob("*") if p.is_file()}
    cases = [
        ("calibrate", run_dir, "--config", TELEMAX_CONFIG, "--clean", "0:10", "--out", run_dir / "truth.json"),
        ("calibrate", run_dir, "--config", TELEMAX_CONFIG, "--out", run_dir / "bag" / "new.yaml"),
        ("inspect", run_dir, "--config-out", run_dir / "bag" / "metadata.yaml"),
        ("inspect", run_dir, "--config-out", run_dir / "scenario.yaml"),
        ("map", run_dir, "--config", config, "--out", run_dir / "bag"),
        ("map", run_dir / "bag", "--config", config, "--out", run_dir),
        ("compare", run_dir, "--config", config, "--out", tmp_path),
        ("calibrate", run_dir, "--config", config, "--out", config),
    ]
    for argv in cases:
        code, err = run(capsys, *argv, *force)
        assert code == 1 and err.count("\n") == 1 and "input" in err, (argv, err)
    assert {p: p.read_bytes() for p in run_dir.rglob("*") if p.is_file()} == before


def test_a_hard_link_of_the_input_is_the_input(short_run, tmp_path, capsys):
    config = tmp_path / "c.yaml"
    config.write_text("keyframes: {period_s: 0.5}\n")
    os.link(config, tmp_path / "alias.yaml")
    code, err = run(capsys, "calibrate", short_run.run_dir, "--config", config, "--force", "--out", tmp_path / "alias.yaml")
    assert code == 1 and "is the input" in err, err
    assert config.read_text() == "keyframes: {period_s: 0.5}\n"


@pytest.mark.parametrize("kind", ["fifo", "socket", "device"])
def test_no_device_pipe_or_socket_is_replaced_even_with_force(short_run, commands, tmp_path, capsys, kind):
    import socket

    if kind == "fifo":
        target = tmp_path / "pipe"
        os.mkfifo(target)
    elif kind == "socket":
        target = tmp_path / "sock"
        sock = socket.socket(socket.AF_UNIX)
        sock.bind(str(target))
    else:
        target = Path("/dev/null")
    before = os.stat(target)
    others = (("inspect", short_run.run_dir, "--config-out"),
              ("calibrate", short_run.run_dir, "--config", TELEMAX_CONFIG, "--out"))
    for argv in (*commands.values(), *others):
        code, err = run(capsys, *argv, target, "--force")
        assert code == 1 and f"is a {'named pipe' if kind == 'fifo' else kind}, not a regular file or folder" in err, err
    after = os.stat(target)
    assert (after.st_ino, after.st_mode, after.st_rdev) == (before.st_ino, before.st_mode, before.st_rdev)


@pytest.mark.parametrize("command", ["map", "simulate", "compare", "ablate", "calibrate", "inspect", "inject", "demo"])
def test_an_empty_out_is_refused(command, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    flag = "--config-out" if command == "inspect" else "--out"
    argv = {"map": ["map", "x", "--config", "c"], "simulate": ["simulate", "s"], "compare": ["compare", "x", "--config", "c"],
            "ablate": ["ablate", "s"], "calibrate": ["calibrate", "x", "--config", "c"], "inspect": ["inspect", "x"],
            "inject": ["inject", "x"], "demo": ["demo"]}[command]
    with pytest.raises(SystemExit) as e:
        main([*argv, flag, ""])
    assert e.value.code == 2
    assert f"argument {flag}: is empty" in capsys.readouterr().err
    assert listing(tmp_path) == set()
    with pytest.raises(GslamError, match="--out is empty"):
        result_folder("", "map").__enter__()
