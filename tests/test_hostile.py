"""The second corpus of hostile input: the classes a hostile but realistic
user finds after the first (tests/test_fuzz.py), built for the classes:

* the output rule: paths inside an input (files of a run folder, the
  config's model, hard links), devices, pipes and sockets, empty paths,
  files of the user's that a result would replace, a variant named like a
  comparison's own file;
* inputs that are not regular files (a named pipe would hang the reader);
* physics on what is read: laser ranges, field of view, beam angles,
  stamps that go back, jump or sit on another clock, time offsets, voxel
  and window sizes the data do not allow, a laser that returns nothing;
* configs: a key given twice, no factor left; scenarios whose route runs
  into an obstacle; ablation specs of more jobs than can run, or whose
  seeds are wrong;
* messages that must name the real culprit (a pause, a Latin-1 byte, the
  stamps a repair moved);
* lines with more values than their counts say, a key given twice on the
  command line, faults that would change nothing, a result file written by
  someone else meanwhile, a home matplotlib cannot use;
* a YAML truth value inside a list of numbers (a waypoint, seeds), names
  YAML reads as no text (a variant named ``yes`` or ``~``), variant names
  that break a table, keys holding characters that show as others or as
  nothing (a zero-width or no-break space, a right-to-left override, a
  Cyrillic letter), NaN beam angles, a data root (GSLAM_DATA) that names
  no folder;
* the ninth attack: a byte-order mark inside a text log (two files
  joined), control characters in a sweep's title or a recorded input's
  name, text of the user's in report.html, one fault or one variant
  given twice and faults of one kind that overlap, a sweep value given
  twice on one axis, a summary metric no job writes, a value starting
  with '-' and '-' as an output, NaN range limits in a LaserScan, bytes
  of a CARMEN log that are no ASCII written back by inject, truth.json
  faults lasting past the data;
* the tenth attack: numbers in a text log that Python reads and C's strtod
  does not (a '_' between digits, digits of another script); a libRSF
  header of column names or a number spelled as a word, a bag's
  metadata.yaml naming another storage, a compression not applied, counts,
  topics, a format or a version the database does not hold; output paths
  through /proc and /sys; walls and legs of no length, waypoints a
  nanometre apart, scientific notation and -0.0; and kinds already answered, kept so that none regresses: alias
  bombs and deep nesting in every YAML input, NaN on keys of every type,
  NUL bytes and lines of millions of values in text logs, ``-`` as a path.

Error cases run as tests/test_fuzz.py's do (exit 1 or 2, one error line
saying what the case expects, nothing of the user's changed, no traceback,
no hang). Warning cases must map, simulate, inject or ablate with one warning line saying
what the case expects, write the result, and change nothing else. No case
may let a Python warning (numpy's overflow) through. Signals and full
disks are at the end, as real processes.
"""

from __future__ import annotations

import gzip
import json
import logging
import math
import os
import resource
import shutil
import signal
import socket
import subprocess
import sys
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import yaml

from slam.cli import main
from slam.processes.signals import STOPS
from tests.bagfactory import driving_bag
from tests.conftest import CONFIGS, REPO, TELEMAX_CONFIG
from tests.test_fuzz import (  # noqa: F401 - world is a fixture
    YAML_BOMB, Case, World, both, broad_mat, check_error_output, copy_run, data, expand, prepare, scenario, set_in, spec,
    text, time_limit, world,
)

pytestmark = pytest.mark.slow  # end to end: pytest -m 'not slow' leaves it out

TIME_LIMIT_S = 60
LONGEST_LINE = 2000  # characters of an error line: what it echoes of the input is cut to its start and end
MAP = ("map", "{run}", "--config", "{cfg}")
QUICK = ("--set", "output.plots=false")


# --- input builders ----------------------------------------------------------------


def checksums(*roots: Path) -> dict[str, str]:
    """Every file, folder, link, pipe and socket under ``roots`` with its
    content's hash or its kind (a pipe is never opened: that would block)."""
    import hashlib
    import stat

    out = {}
    for root in roots:
        for p in sorted(root.rglob("*")):
            mode = p.lstat().st_mode
            if stat.S_ISLNK(mode):
                out[str(p)] = "->" + os.readlink(p)
            elif stat.S_ISREG(mode):
                out[str(p)] = hashlib.sha1(p.read_bytes()).hexdigest()
            else:
                out[str(p)] = f"mode {stat.S_IFMT(mode):o} inode {p.lstat().st_ino}"
    return out


def _room_ranges(x: float, angles: np.ndarray) -> np.ndarray:
    """Ranges from (x, 0), heading east, to the walls of a room x -2..12, y -3..3."""
    c, s = np.cos(angles), np.sin(angles)
    with np.errstate(divide="ignore"):
        tx = np.where(c > 0, (12 - x) / c, np.where(c < 0, (-2 - x) / c, np.inf))
        ty = np.where(s > 0, 3 / s, np.where(s < 0, -3 / s, np.inf))
    return np.minimum(tx, ty)


def carmen(n: int = 40, ranges: Callable[[np.ndarray, int], np.ndarray] | None = None,
           stamp: Callable[[int], float] | None = None, theta: float = 0.0, head: str = "",
           name: str = "c.log", robotlaser: tuple[float, float, float] | None = None,
           encoding: Callable[[str], bytes] = str.encode) -> Callable[[Path, World], None]:
    """A CARMEN log of a robot driving 0.1 m per scan along a room: FLASER
    (or ROBOTLASER1 with ``robotlaser`` = start, fov, resolution in rad)
    lines with the corrected pose, each followed by ODOM lines (the repeat,
    then the next pose); ``ranges(r, k)`` and ``stamp(k)`` change scan k."""

    def make(d: Path, world: World) -> None:
        beams = 181
        angles = np.radians(np.linspace(-90, 90, beams))
        lines = [head] if head else []
        for k in range(n):
            x, t = 0.1 * k, stamp(k) if stamp is not None else 1000.0 + 0.5 * k
            r = _room_ranges(x, angles)
            r = ranges(r, k) if ranges is not None else r
            values = " ".join(f"{v:.6g}" for v in r)
            pose = f"{x:.3f} 0 {theta:g}"
            if robotlaser is None:
                lines.append(f"FLASER {beams} {values} {pose} {pose} {t:.6f} host {t:.6f}")
            else:
                start, fov, res = robotlaser
                lines.append(f"ROBOTLASER1 0 {start:g} {fov:g} {res:g} 50 0.01 0 {beams} {values} 0 "
                             f"0 0 0 {pose} 0 0 0 0 0 {t:.6f} host {t:.6f}")
            lines.append(f"ODOM {pose} 0 0 0 {t:.6f} host {t:.6f}")
            lines.append(f"ODOM {0.1 * (k + 1):.3f} 0 {theta:g} 0 0 0 {t + 0.25:.6f} host {t + 0.25:.6f}")
        (d / name).write_bytes(encoding("\n".join(lines) + "\n"))

    return make


CARMEN = ("map", "{d}/c.log", "--config", str(CONFIGS / "datasets" / "carmen.yaml"), *QUICK, "--out", "{d}/o")
BLIND = (*CARMEN[:-2], "--set", "loops.enabled=false", *CARMEN[-2:])  # loops in the submaps need scans


def bag(change: Callable | None = None, name: str = "b") -> Callable[[Path, World], None]:
    """The driving bag of tests/bagfactory.py (2 s, every default topic) as
    a ROS 2 bag at ``{d}/b``, its messages changed by ``change(bag)``."""

    def make(d: Path, world: World) -> None:
        b = driving_bag(ros=2, duration_s=4.0)
        if change is not None:
            change(b)
        b.write(d / name)

    return make


def truncated_mcap(fraction: float, bare: bool = False) -> Callable[[Path, World], None]:
    """The driving bag as a ROS 2 MCAP bag at ``{d}/m`` cut off after
    ``fraction`` of its bytes (a copy that stopped, a recorder killed before
    its index); ``bare``: the cut .mcap file alone at ``{d}/m.mcap``."""

    def make(d: Path, world: World) -> None:
        folder = driving_bag(ros=2, duration_s=4.0).write(d / "full", storage="mcap")
        (file,) = folder.glob("*.mcap")
        data = file.read_bytes()[: int(file.stat().st_size * fraction)]
        if bare:
            (d / "m.mcap").write_bytes(data)
        else:
            shutil.copytree(folder, d / "m")
            (d / "m" / file.name).write_bytes(data)
        shutil.rmtree(folder)

    return make


def truncated_ros1(fraction: float) -> Callable[[Path, World], None]:
    """The driving bag as a ROS 1 bag at ``{d}/r.bag`` cut off after
    ``fraction`` of its bytes: its index, written last, is gone."""

    def make(d: Path, world: World) -> None:
        bag = driving_bag(ros=1, duration_s=4.0).write(d / "full.bag")
        (d / "r.bag").write_bytes(bag.read_bytes()[: int(bag.stat().st_size * fraction)])
        bag.unlink()

    return make


def each(topic: str, fn: Callable[[float, object], None]) -> Callable:
    """A bag change: ``fn(t, msg)`` on every message of ``topic``."""

    def change(b) -> None:
        for i, (log_ns, order, t, msgtype, msg) in enumerate(b._messages):
            if t == topic:
                fn(log_ns / 1e9, msg)

    return change


def restamp(topic: str, shift: Callable[[int], float]) -> Callable:
    """A bag change: header stamp of message k of ``topic`` moved by ``shift(k)`` s."""

    def change(b) -> None:
        k = 0
        for i, (log_ns, order, t, msgtype, msg) in enumerate(b._messages):
            if t == topic:
                ns = log_ns + int(round(shift(k) * 1e9))
                msg.header.stamp.sec, msg.header.stamp.nanosec = ns // 10**9, ns % 10**9
                k += 1

    return change


def from_message(topic: str, first: int, fn: Callable[[object], None]) -> Callable:
    """A bag change: ``fn(msg)`` on message ``first`` of ``topic`` and every one after it."""

    def change(b) -> None:
        k = 0
        for i, (log_ns, order, t, msgtype, msg) in enumerate(b._messages):
            if t == topic:
                if k >= first:
                    fn(msg)
                k += 1

    return change


BAG = ("map", "{d}/b", "--config", "{cfg}", *QUICK, "--out", "{d}/o")


def config(change: Callable[[dict], None], name: str = "c.yaml") -> Callable[[Path, World], None]:
    """configs/telemax.yaml with ``change`` applied (its model made absolute) at ``{d}/c.yaml``."""

    def make(d: Path, world: World) -> None:
        tree = yaml.safe_load(TELEMAX_CONFIG.read_text())
        tree["validation"]["model"] = str(CONFIGS / "validation" / "telemax_model.yaml")
        change(tree)
        (d / name).write_text(yaml.safe_dump(tree, sort_keys=False))

    return make


def relation(index: int, **values) -> Callable[[dict], None]:
    def change(tree: dict) -> None:
        tree["validation"]["observers"]["relations"][index].update(values)

    return change


def every_factor(enabled: bool, **but) -> Callable[[dict], None]:
    def change(tree: dict) -> None:
        for name, f in tree["backend"]["factors"].items():
            f["enabled"] = but.get(name, enabled)

    return change


def fifo(name: str) -> Callable[[Path, World], None]:
    def make(d: Path, world: World) -> None:
        (d / name).parent.mkdir(parents=True, exist_ok=True)
        os.mkfifo(d / name)

    return make


def unix_socket(name: str) -> Callable[[Path, World], None]:
    def make(d: Path, world: World) -> None:
        sock = socket.socket(socket.AF_UNIX)
        sock.bind(str(d / name))
        sock.close()  # the socket file stays

    return make


def hard_link(name: str, to: str) -> Callable[[Path, World], None]:
    def make(d: Path, world: World) -> None:
        os.link(d / to, d / name)

    return make


def result_with(command: str, name: str, files: dict[str, str | None]) -> Callable[[Path, World], None]:
    """A folder marked as ``command``'s result listing ``files``; a None
    content makes a folder of the user's where that file goes."""

    def make(d: Path, world: World) -> None:
        folder = d / name
        folder.mkdir()
        (folder / ".gslam-result.json").write_text(json.dumps({"command": command, "files": []}))
        for f, content in files.items():
            if content is None:
                (folder / f).mkdir(parents=True)
            else:
                (folder / f).write_text(content)

    return make


def raw(name: str, content: bytes) -> Callable[[Path, World], None]:
    return data(name, content)


def spec_in(d: Path, world: World, **changes) -> None:
    spec(**changes)(d, world)


def spec_text(body: str) -> Callable[[Path, World], None]:
    """``{d}/spec.yaml``: the one-job spec's name, config and scenario input, then ``body``."""

    def make(d: Path, world: World) -> None:
        (d / "spec.yaml").write_text(f"name: x\nconfig: {TELEMAX_CONFIG}\n"
                                     f"inputs: {{scenarios: [{{path: {world.scenario}, seeds: [1]}}]}}\n{body}")

    return make


def scenario_waypoints(points) -> Callable[[Path, World], None]:
    return scenario(set_in("robot", "waypoints", points))


def _rewritten(name: str, change: Callable[[bytes], bytes]) -> Callable[[Path, World], None]:
    """``{d}/name``'s bytes replaced by ``change(bytes)``."""

    def make(d: Path, world: World) -> None:
        (d / name).write_bytes(change((d / name).read_bytes()))

    return make


def unreadable(name: str) -> Callable[[Path, World], None]:
    """``{d}/name`` a link to /proc/self/mem, which no process reads at offset 0 (EIO), root included."""

    def make(d: Path, world: World) -> None:
        (d / name).symlink_to("/proc/self/mem")

    return make


def _truth_with(section: str, key: str, value: float) -> Callable[[Path], None]:
    """A run folder change: truth.json's ``section.key`` set to ``value``."""

    def change(run: Path) -> None:
        truth = json.loads((run / "truth.json").read_text())
        truth[section][key] = value
        (run / "truth.json").write_text(json.dumps(truth))

    return change


def _an_hour_long(tree: dict) -> None:
    """The short scenario made about 50 minutes long: a pause of 3000 s at its second waypoint."""
    tree["robot"]["waypoints"][1] = [*tree["robot"]["waypoints"][1][:2], 3000.0]


def link_loop(name: str) -> Callable[[Path, World], None]:
    """A link ``{d}/name`` to itself."""

    def make(d: Path, world: World) -> None:
        (d / name).symlink_to(d / name)

    return make


def finished_sweep(metrics: str) -> Callable[[Path, World], None]:
    """The one-job sweep run into ``{d}/o``, its job's metrics.json then
    replaced by ``metrics`` (as an edit, or a tool other than gslam, does)."""

    def make(d: Path, world: World) -> None:
        assert main(["-q", "ablate", str(world.spec), "--out", str(d / "o")]) == 0
        (job,) = (d / "o" / "jobs").iterdir()
        (job / "metrics.json").write_text(metrics)

    return make


def earlier_result(command: str) -> Callable[[Path, World], None]:
    """``gslam map`` or ``compare`` (ungated) of the run into ``{d}/r``."""

    def make(d: Path, world: World) -> None:
        only = ("--only", "ungated") if command == "compare" else ()
        assert main(["-q", command, str(world.run), "--config", str(TELEMAX_CONFIG), *only, *QUICK, "--out",
                     str(d / "r")]) == 0

    return make


def librsf_with(loops: str, groundtruth: str | None = None) -> Callable[[Path, World], None]:
    """A libRSF log of 10 s (odom2 lines, a turn in the middle), ``loops``
    lines after them, and ``groundtruth`` as its X_GT.txt if given."""

    def make(d: Path, world: World) -> None:
        rows = "".join(f"odom2 {0.1 * k:.1f} 0.5 0 {0.3 if 20 <= k < 30 else 0.0} 0.01 0.01 0.01\n" for k in range(100))
        (d / "X_Input.txt").write_text(rows + loops + "\n")
        if groundtruth is not None:
            (d / "X_GT.txt").write_text(groundtruth)

    return make


def _listing(files: Callable[[Path], list[str]]) -> Callable[[Path], None]:
    """A run folder change: its bag's metadata.yaml lists ``files(bag)``."""

    def change(run: Path) -> None:
        meta = yaml.safe_load((run / "bag" / "metadata.yaml").read_text())
        meta["rosbag2_bagfile_information"]["relative_file_paths"] = files(run / "bag")
        (run / "bag" / "metadata.yaml").write_text(yaml.safe_dump(meta))

    return change


def _covariance(variance: float) -> Callable[[float, object], None]:
    def change(t: float, msg) -> None:
        msg.position_covariance[0] = msg.position_covariance[4] = variance
        msg.position_covariance_type = 2

    return change


def _second_scan_a_beam_short(log: str) -> bytes:
    """The log with its second FLASER line (line 4) one range and one beam short."""
    lines = log.split("\n")
    parts = lines[3].split(" ")
    lines[3] = " ".join(["FLASER", str(int(parts[1]) - 1), *parts[3:]])
    return "\n".join(lines).encode()


LIBRSF = ("map", "{d}/X_Input.txt", "--config", str(CONFIGS / "datasets" / "librsf_corridor.yaml"), *QUICK, "--out", "{d}/o")
MAG_BAG = ("map", "{d}/b", "--config", "{cfg}", "--set", "input.compass.source=magnetic_field", *QUICK, "--out", "{d}/o")


# --- the error corpus -------------------------------------------------------------


RUN = ("{d}/run",)
CAL = ("calibrate", "{d}/run", "--config", "{cfg}", "--clean", "0:10")

ERRORS: list[Case] = [
    # -- the output rule: inside an input, with or without --force --
    Case("calibrate-out-truth-json-force", (*CAL, "--out", "{d}/run/truth.json", "--force"),
         "is inside the input folder", copy_run()),
    Case("calibrate-out-new-file-in-run", (*CAL, "--out", "{d}/run/model.yaml"), "is inside the input folder", copy_run()),
    Case("inspect-config-out-bag-metadata-force", ("inspect", "{d}/run", "--config-out", "{d}/run/bag/metadata.yaml", "--force"),
         "is inside the input folder", copy_run()),
    Case("inspect-config-out-scenario-yaml", ("inspect", "{d}/run", "--config-out", "{d}/run/scenario.yaml"),
         "is inside the input folder", copy_run()),
    Case("map-out-inside-the-bag-force", ("map", "{d}/run", "--config", "{cfg}", "--out", "{d}/run/bag/m", "--force"),
         "is inside the input folder", copy_run()),
    Case("inject-out-inside-the-run-force", ("inject", "{d}/run", "--fault", "gyro_bias@2:4", "--out", "{d}/run/x", "--force"),
         "is inside the input folder", copy_run()),
    Case("compare-out-holds-the-run-force", ("compare", "{d}/run", "--config", "{cfg}", "--out", "{d}", "--force"),
         "holds the input", copy_run()),
    Case("simulate-out-holds-the-scenario-force", ("simulate", "{d}/s/s.yaml", "--out", "{d}/s", "--force"),
         "holds the input", lambda d, w: (d / "s").mkdir() or shutil.copy(w.scenario, d / "s" / "s.yaml")),
    Case("calibrate-out-is-the-model-force", ("calibrate", "{run}", "--config", "{d}/c.yaml", "--out", "{d}/m.yaml", "--force"),
         "is the input", both(text("m.yaml", (CONFIGS / "validation" / "telemax_model.yaml").read_text()),
                              config(lambda t: t["validation"].update(model="m.yaml")))),
    Case("calibrate-out-hard-link-of-the-config", ("calibrate", "{run}", "--config", "{d}/c.yaml", "--out", "{d}/l.yaml",
                                                   "--force"), "is the input", both(config(lambda t: None), hard_link("l.yaml", "c.yaml"))),
    Case("map-out-is-the-model-folder", ("map", "{run}", "--config", "{d}/c.yaml", "--out", "{d}/mdl"),
         "holds the input", both(text("mdl/m.yaml", (CONFIGS / "validation" / "telemax_model.yaml").read_text()),
                                 config(lambda t: t["validation"].update(model="mdl/m.yaml")))),
    # -- devices, pipes, sockets, empty paths --
    Case("inspect-config-out-dev-null-force", ("inspect", "{run}", "--config-out", "/dev/null", "--force"), "is a device"),
    Case("calibrate-out-dev-null-force", (*CAL[:2], "--config", "{cfg}", "--out", "/dev/null", "--force"), "is a device"),
    Case("map-out-fifo-force", (*MAP, "--out", "{d}/p", "--force"), "is a named pipe", fifo("p")),
    Case("simulate-out-fifo", ("simulate", "{scen}", "--out", "{d}/p"), "is a named pipe", fifo("p")),
    Case("calibrate-out-socket-force", ("calibrate", "{run}", "--config", "{cfg}", "--out", "{d}/s", "--force"),
         "is a socket", unix_socket("s")),
    Case("map-out-empty", (*MAP, "--out", ""), "argument --out: is empty", code=2),
    Case("simulate-out-blank", ("simulate", "{scen}", "--out", "  "), "argument --out: is empty", code=2),
    Case("calibrate-out-empty", ("calibrate", "{run}", "--config", "{cfg}", "--out", ""), "argument --out: is empty", code=2),
    Case("inspect-config-out-empty", ("inspect", "{run}", "--config-out", ""), "argument --config-out: is empty", code=2),
    # -- files of the user's: never replaced, even with --force --
    Case("inspect-config-out-users-file-force", ("inspect", "{run}", "--config-out", "{d}/mine.yaml", "--force"),
         "exists and is not a gslam inspect result", text("mine.yaml", "# mine\n")),
    Case("calibrate-out-users-file-force", ("calibrate", "{run}", "--config", "{cfg}", "--out", "{d}/mine.yaml", "--force"),
         "exists and is not a gslam calibrate result", text("mine.yaml", "# gslam said nothing\n")),
    Case("map-force-users-trajectory", (*MAP, *QUICK, "--out", "{d}/mine", "--force"), "holds trajectory.tum",
         both(text("mine/trajectory.tum", "mine\n"), text("mine/notes.txt", "mine\n"))),
    Case("map-force-link-where-metrics-go", (*MAP, *QUICK, "--out", "{d}/mine", "--force"), "holds metrics.json",
         both(text("elsewhere.json", "{}\n"), text("mine/notes.txt", "mine\n"),
              lambda d, w: (d / "mine" / "metrics.json").symlink_to(d / "elsewhere.json"))),
    Case("map-rerun-users-folder-where-a-file-goes", (*MAP, *QUICK, "--out", "{d}/m"), "holds config.yaml",
         result_with("map", "m", {"config.yaml": None})),
    Case("map-rerun-users-file-not-in-the-list", (*MAP, *QUICK, "--out", "{d}/m"), "holds metrics.json",
         result_with("map", "m", {"metrics.json": "the user's own\n"})),
    Case("compare-force-users-comparison", ("compare", "{run}", "--config", "{cfg}", "--only", "ungated", *QUICK,
                                            "--out", "{d}/mine", "--force"), "holds comparison.md",
         text("mine/comparison.md", "mine\n")),
    Case("simulate-force-users-truth", ("simulate", "{scen}", "--out", "{d}/mine", "--force"), "holds truth.json",
         text("mine/truth.json", "{}\n")),
    Case("ablate-force-users-summary", ("ablate", "{spec}", "--out", "{d}/mine", "--force"), "holds summary.md",
         text("mine/summary.md", "mine\n")),
    Case("inject-force-users-file-named-bag", ("inject", "{run}", "--fault", "gyro_bias@2:4", "--out", "{d}/mine", "--force"),
         "holds bag", text("mine/bag", "mine\n")),
    # -- a variant named like the comparison's own files or a path --
    Case("compare-variant-named-comparison-md", ("compare", "{run}", "--config", "{cfg}", "--variants", "{d}/v.yaml",
                                                 "--out", "{d}/o"), "variant 'comparison.md'",
         text("v.yaml", "comparison.md: {validation.mode: \"off\"}\n")),
    Case("compare-variant-named-a-path", ("compare", "{run}", "--config", "{cfg}", "--variants", "{d}/v.yaml",
                                          "--out", "{d}/o"), "variant '../up'", text("v.yaml", "../up: {}\n")),
    Case("compare-variant-hidden", ("compare", "{run}", "--config", "{cfg}", "--variants", "{d}/v.yaml", "--out", "{d}/o"),
         "variant '.gslam-result.json'", text("v.yaml", ".gslam-result.json: {}\n")),
    # -- names whose folders are one where the file system ignores case --
    Case("compare-variants-differ-in-case", ("compare", "{run}", "--config", "{cfg}", "--variants", "{d}/v.yaml",
                                             "--out", "{d}/o"), "variants 'Gated' and 'gated' differ only in case",
         text("v.yaml", "Gated: {validation.mode: 'on'}\ngated: {validation.mode: 'off'}\n")),
    Case("compare-variant-named-report-in-capitals", ("compare", "{run}", "--config", "{cfg}", "--variants",
                                                      "{d}/v.yaml", "--out", "{d}/o"), "variant 'REPORT.html'",
         text("v.yaml", "REPORT.html: {validation.mode: 'off'}\n")),
    # -- inputs that are not regular files: refused, never read (no hang) --
    Case("config-is-a-named-pipe", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"), "it is a named pipe", fifo("c.yaml")),
    Case("config-is-dev-zero", (*MAP[:2], "--config", "/dev/zero", "--out", "{d}/o"), "it is a device"),
    Case("scenario-is-a-named-pipe", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), "it is a named pipe", fifo("s.yaml")),
    Case("spec-is-a-named-pipe", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), "it is a named pipe", fifo("spec.yaml")),
    Case("variants-is-a-named-pipe", ("compare", "{run}", "--config", "{cfg}", "--variants", "{d}/v.yaml", "--out", "{d}/o"),
         "it is a named pipe", fifo("v.yaml")),
    Case("model-is-a-named-pipe", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"), "it is a named pipe",
         both(fifo("m.yaml"), config(lambda t: t["validation"].update(model="m.yaml")))),
    Case("recording-bag-is-a-named-pipe", ("map", "{d}/r.bag", "--config", "{cfg}", "--out", "{d}/o"), "it is a named pipe",
         fifo("r.bag")),
    Case("recording-log-is-a-named-pipe", ("inspect", "{d}/c.log"), "it is a named pipe", fifo("c.log")),
    Case("run-truth-json-is-a-named-pipe", ("map", "{d}/run", "--config", "{cfg}", "--out", "{d}/o"), "it is a named pipe",
         copy_run(lambda r: (r / "truth.json").unlink() or os.mkfifo(r / "truth.json"))),
    Case("run-db3-is-a-named-pipe", ("map", "{d}/run", "--config", "{cfg}", "--out", "{d}/o"), "it is a named pipe",
         copy_run(lambda r: (r / "bag" / "bag.db3").unlink() or os.mkfifo(r / "bag" / "bag.db3"))),
    # -- configs: a key given twice, no factor left --
    Case("config-duplicate-section", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"),
         "line 3: key 'backend' given twice (first on line 1)",
         text("c.yaml", "backend: {optimizer: isam2}\nkeyframes: {period_s: 0.5}\nbackend: {optimizer: batch}\n")),
    Case("config-duplicate-nested-key", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"),
         "line 4: key 'sigma_yaw_deg' given twice (first on line 3)",
         text("c.yaml", "backend:\n  factors:\n    compass: {sigma_yaw_deg: 3,\n      sigma_yaw_deg: 30}\n")),
    Case("config-duplicate-key-in-one-flow-mapping", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"),
         "line 3: key 'sigma_xy_m' given twice (earlier on the same line)",
         text("c.yaml", "backend:\n  factors:\n    gps: {sigma_xy_m: 0.03, sigma_xy_m: 300}\n")),
    Case("set-duplicate-key-in-a-flow-mapping", (*MAP, "--out", "{d}/o", "--set",
                                                 "backend.factors.gps={{sigma_xy_m: 0.03, sigma_xy_m: 300}}"),
         "key 'sigma_xy_m' given twice"),
    Case("scenario-duplicate-key-in-one-flow-mapping", ("simulate", "{d}/s.yaml", "--out", "{d}/o"),
         "key 'x' given twice (earlier on the same line)",
         lambda d, w: (d / "s.yaml").write_text(w.scenario.read_text() + "start: {x: 1.0, y: 2.0, x: 3.0}\n")),
    Case("scenario-duplicate-key", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), "key 'seed' given twice",
         lambda d, w: (d / "s.yaml").write_text(w.scenario.read_text() + "seed: 5\n")),
    Case("spec-duplicate-key", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), "key 'name' given twice",
         lambda d, w: (d / "spec.yaml").write_text(w.spec.read_text() + "name: twice\n")),
    Case("variants-duplicate-key", ("compare", "{run}", "--config", "{cfg}", "--variants", "{d}/v.yaml", "--out", "{d}/o"),
         "line 2: key 'gated' given twice", text("v.yaml", "gated: {validation.mode: on}\ngated: {validation.mode: off}\n")),
    Case("model-duplicate-key", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"), "key 'components' given twice",
         both(text("m.yaml", (CONFIGS / "validation" / "telemax_model.yaml").read_text() + "components: []\n"),
              config(lambda t: t["validation"].update(model="m.yaml")))),
    Case("config-every-factor-disabled", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"),
         "backend.factors: no factor left (every one is disabled)", config(every_factor(False))),
    Case("set-every-factor-disabled", (*MAP, "--out", "{d}/o", *(a for f in ("odometry", "gyro", "compass", "scan_matching", "gps")
                                                                 for a in ("--set", f"backend.factors.{f}.enabled=false"))),
         "no factor left"),
    Case("config-scan-matching-without-frontend", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"),
         "scan_matching is the only one enabled and frontend.enabled is false",
         config(lambda t: every_factor(False, scan_matching=True)(t) or t["frontend"].update(enabled=False))),
    Case("config-only-gps-run-without-fixes", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"),
         "no factor left: the config enables gps, whose streams the recording lacks", config(every_factor(False, gps=True))),
    # -- time offsets, voxels and windows the data do not allow --
    Case("time-offset-1e9", (*MAP, "--out", "{d}/o", "--set", "input.time_offsets_s.gyro=1e9"),
         "input.time_offsets_s.gyro +1e+09 s is as long as the recording"),
    Case("time-offset-minus-a-day", (*MAP, "--out", "{d}/o", "--set", "input.time_offsets_s.odometry=-86400"),
         "input.time_offsets_s.odometry -86400 s"),
    Case("voxel-0.001", (*MAP, "--out", "{d}/o", "--set", "frontend.voxel_size_m=0.001"),
         "frontend.voxel_size_m 0.001 is 1/"),
    Case("voxel-90", (*MAP, "--out", "{d}/o", "--set", "frontend.voxel_size_m=90"), "frontend.voxel_size_m 90 is"),
    Case("voxel-1e-9", (*MAP, "--out", "{d}/o", "--set", "frontend.voxel_size_m=1e-9"),
         "frontend.voxel_size_m: 1e-09 m is below 0.001 m"),
    Case("voxel-1000", (*MAP, "--out", "{d}/o", "--set", "frontend.voxel_size_m=1000"),
         "frontend.voxel_size_m: 1000 m is above 100 m"),
    Case("frontend-min-above-max-range", (*MAP, "--out", "{d}/o", "--set", "frontend.min_range_m=50"),
         "min_range_m 50 is not below max_range_m 30"),
    Case("validation-rate-0.01", (*MAP, "--out", "{d}/o", "--gating", "on", "--set", "validation.rate_hz=0.01"),
         "validation.rate_hz 0.01 gives fewer than 2 validation steps"),
    Case("validation-rate-1e-6", (*MAP, "--out", "{d}/o", "--gating", "on", "--set", "validation.rate_hz=1e-6"),
         "validation.rate_hz: 1e-06 Hz is below 0.001 Hz"),
    Case("relation-window-longer-than-the-run", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o", "--gating", "on"),
         "validation.observers.relations.yaw_compass_gyro.window_s 10000 s is longer than the run",
         config(relation(0, window_s=1e4))),
    Case("relation-window-under-two-steps", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o", "--gating", "on"),
         "window_s 0.001 s holds fewer than 2 validation steps", config(relation(2, window_s=0.001))),
    # -- scenarios --
    Case("scenario-waypoint-inside-an-obstacle", ("simulate", "{d}/s.yaml", "--out", "{d}/o"),
         "robot.waypoints.1 (3, 3) lies inside world.obstacles.0",
         scenario(lambda t: t["world"].update(obstacles=[[[2, 2], [4, 2], [4, 4], [2, 4]]])
                  or t["robot"]["waypoints"].__setitem__(1, [3.0, 3.0]))),
    Case("scenario-start-inside-an-obstacle", ("simulate", "{d}/s.yaml", "--out", "{d}/o"),
         "robot.waypoints.0", scenario(lambda t: t["world"]["obstacles"].append(
             [[t["robot"]["waypoints"][0][0] - 0.2, t["robot"]["waypoints"][0][1] - 0.2],
              [t["robot"]["waypoints"][0][0] + 0.2, t["robot"]["waypoints"][0][1] - 0.2],
              [t["robot"]["waypoints"][0][0] + 0.2, t["robot"]["waypoints"][0][1] + 0.2],
              [t["robot"]["waypoints"][0][0] - 0.2, t["robot"]["waypoints"][0][1] + 0.2]]))),
    Case("scenario-pause-of-1e6-s", ("simulate", "{d}/s.yaml", "--out", "{d}/o"),
         "robot.waypoints: waypoint 1's pause (third value) 1e+06 s is above 14400 s",
         scenario(lambda t: t["robot"]["waypoints"].__setitem__(1, [*t["robot"]["waypoints"][1][:2], 1e6]))),
    Case("scenario-pause-of-4-h", ("simulate", "{d}/s.yaml", "--out", "{d}/o"),
         "most of it the pause of 14400 s at robot.waypoints.1",
         scenario(lambda t: t["robot"]["waypoints"].__setitem__(1, [*t["robot"]["waypoints"][1][:2], 14400.0]))),
    Case("scenario-utf16", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), "UTF-16 text",
         lambda d, w: (d / "s.yaml").write_bytes(w.scenario.read_text().encode("utf-16"))),
    Case("config-latin1-byte-named", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"),
         "line 2: byte 0xE9 is not UTF-8 text (a Latin-1 character?)",
         raw("c.yaml", b"keyframes: {period_s: 0.5}\n# r\xe9glages\n")),
    # -- ablation specs: job counts and seeds --
    Case("ablate-seed-count-1e6", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"),
         "1,000,000 jobs, more than 10,000; inputs.scenarios.0 alone",
         lambda d, w: spec_in(d, w, inputs={"scenarios": [{"path": str(w.scenario), "seeds": {"count": 10**6}}]})),
    Case("ablate-random-samples-1e6", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), "sweep.random.samples 1,000,000",
         spec(sweep={"random": {"samples": 10**6, "params": {"gating.inflation": {"uniform": [1, 5]}}}})),
    Case("ablate-grid-product", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), "100,000 sweep points",
         spec(sweep={"grid": {f"backend.factors.{f}.sigma_yaw_deg": list(range(1, 11))
                              for f in ("odometry", "gyro", "compass", "scan_matching")} | {
             "gating.inflation": list(range(1, 11))}})),
    Case("ablate-max-jobs", ("ablate", "{d}/spec.yaml", "--out", "{d}/o", "--max-jobs", "3"), "5 jobs, more than 3",
         lambda d, w: spec_in(d, w, inputs={"scenarios": [{"path": str(w.scenario), "seeds": {"count": 5}}]})),
    Case("ablate-seed-count-0", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"),
         "inputs.scenarios.0.seeds.count: 0 is below 1: a sweep of no point or seed runs nothing",
         lambda d, w: spec_in(d, w, inputs={"scenarios": [{"path": str(w.scenario), "seeds": {"count": 0}}]})),
    Case("ablate-seed-first-negative", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), "seeds.first",
         lambda d, w: spec_in(d, w, inputs={"scenarios": [{"path": str(w.scenario), "seeds": {"first": -3, "count": 2}}]})),
    Case("ablate-max-jobs-zero", ("ablate", "{spec}", "--out", "{d}/o", "--max-jobs", "0"), "expected 1 or more", code=2),
    # -- CARMEN logs: time, angles, field of view --
    Case("carmen-two-logs-concatenated", CARMEN, "time goes back by",
         carmen(n=60, stamp=lambda k: 1000.0 + 0.5 * (k % 30))),
    Case("carmen-clock-reset", CARMEN, "c.log:", carmen(n=40, stamp=lambda k: 1000.0 + 0.5 * k - (500 if k >= 20 else 0))),
    Case("carmen-stamps-jump-a-day", CARMEN, "stamps jump forward by 86400",
         carmen(n=40, stamp=lambda k: 1000.0 + 0.5 * k + (86400 if k >= 20 else 0))),
    Case("carmen-pose-1e300", CARMEN, "beyond 1e+07 m of its origin",
         carmen(encoding=lambda s: s.replace(" 2.000 0 0 ", " 1e300 0 0 ").encode())),
    Case("carmen-pose-teleports-1e7-m", CARMEN, "m from the one before; no robot moves more than 1000 m",
         carmen(encoding=lambda s: s.replace(" 2.000 0 0 ", " 1e7 0 0 ").encode())),
    Case("carmen-pose-nan", CARMEN, "c.log:",
         carmen(encoding=lambda s: s.replace(" 2.000 0 0 ", " nan 0 0 ").encode())),
    Case("carmen-fov-720", CARMEN, "PARAM laser_front_laser_fov 720", carmen(head="PARAM laser_front_laser_fov 720")),
    Case("carmen-fov-0", CARMEN, "PARAM laser_front_laser_fov 0", carmen(head="PARAM laser_front_laser_fov 0")),
    Case("carmen-theta-1e6", CARMEN, "pose angles reach 1e+06", carmen(theta=1e6)),
    Case("carmen-robotlaser-no-turn", CARMEN, "two at the same angle", carmen(robotlaser=(-1.57, 3.14, 0.0))),
    Case("carmen-robotlaser-fov-in-degrees", CARMEN, "span 1800 deg", carmen(robotlaser=(-90, 180, 10.0 * math.pi / 180))),
    # -- ROS bags: beam angles, rotations, clocks, jumps --
    Case("bag-angle-increment-0", BAG, "two at the same angle", bag(each("/scan", lambda t, m: setattr(m, "angle_increment", 0.0)))),
    Case("bag-angle-increment-in-degrees", BAG, "a 2D laser sees at most 360 deg",
         bag(each("/scan", lambda t, m: setattr(m, "angle_increment", 100.0)))),
    Case("bag-angle-min-1e6", BAG, "beam angles reach 1e+06 rad", bag(each("/scan", lambda t, m: setattr(m, "angle_min", 1e6)))),
    Case("bag-odometry-zero-quaternion", BAG, "pose.orientation at message 0 is not a rotation",
         bag(each("/odom", lambda t, m: setattr(m.pose.pose.orientation, "w", 0.0)))),
    Case("bag-imu-orientation-zero", ("map", "{d}/b", "--config", "{cfg}", "--set", "input.compass.source=imu_orientation",
                                      "--set", "input.topics.compass=/imu/data", *QUICK, "--out", "{d}/o"),
         "orientation at message 0 is not a rotation",
         bag(each("/imu/data", lambda t, m: [setattr(m.orientation, k, 0.0) for k in "xyzw"]))),
    Case("bag-gps-latitude-1000", BAG, "fix 0 at latitude 1000, longitude 11: expected degrees",
         bag(each("/gps/fix", lambda t, m: setattr(m, "latitude", 1000.0)))),
    Case("bag-gyro-rate-in-the-millions", BAG, "gyro rate 0 is 1e+06 rad/s; no gyroscope measures more than 1000 rad/s",
         bag(each("/imu/data", lambda t, m: setattr(m.angular_velocity, "z", 1e6)))),
    Case("validation-rate-1e9", (*MAP, "--out", "{d}/o", "--gating", "on", "--set", "validation.rate_hz=1e9"),
         "validation.rate_hz: 1e+09 Hz is above 10000 Hz"),
    Case("validation-rate-10-khz-over-20-minutes", (*CARMEN[:-2], "--gating", "on", "--set", "validation.rate_hz=10000",
                                                    *CARMEN[-2:]),
         "validation.rate_hz 10000 makes 1.2e+07 validation steps", carmen(n=41, stamp=lambda k: 1000.0 + 30.0 * k)),
    Case("config-declination-1000-deg", (*MAP, "--out", "{d}/o", "--set", "input.compass.declination_deg=1000"),
         "input.compass.declination_deg: Input should be less than or equal to 180"),
    Case("config-datum-latitude-100", (*MAP, "--out", "{d}/o", "--set", "input.gps.datum_lat_deg=100",
                                       "--set", "input.gps.datum_lon_deg=11"), "input.gps.datum_lat_deg"),
    Case("bag-gyro-on-another-clock", BAG, "gyro stamps", bag(restamp("/imu/data", lambda k: -1e9))),
    Case("bag-gyro-nanosec-3e9", BAG, "gyro topic '/imu/data': header stamp at message 0 has nanosec 3000000000, beyond "
         "999999999: not a ROS time", bag(each("/imu/data", lambda t, m: setattr(m.header.stamp, "nanosec", 3_000_000_000)))),
    Case("bag-scan-nanosec-1.5e9", BAG, "scan topic '/scan': header stamp at message 0 has nanosec 1500000000",
         bag(each("/scan", lambda t, m: setattr(m.header.stamp, "nanosec", 1_500_000_000)))),
    Case("run-truth-t0-of-another-recording", ("map", "{d}/run", "--config", "{cfg}", *QUICK, "--out", "{d}/o"),
         "s after t0 1e+300 lies outside the recording", copy_run(lambda r: (r / "truth.json").write_text(
             json.dumps({**json.loads((r / "truth.json").read_text()), "t0": 1e300})))),
    Case("bag-odometry-jumps-a-day", BAG, "odometry stamps jump forward by 86400",
         bag(restamp("/odom", lambda k: 86400.0 if k >= 40 else 0.0))),
    # -- other formats --
    Case("librsf-stamps-jump", ("map", "{d}/X_Input.txt", "--config", str(CONFIGS / "datasets" / "librsf_corridor.yaml"),
                                *QUICK, "--out", "{d}/o"), "stamps jump forward by",
         text("X_Input.txt", "".join(f"odom2 {t} 0.5 0 0.01 0.01 0.01 0.01\n"
                                     for t in [0.1 * k for k in range(50)] + [1e7 + 0.1 * k for k in range(50)]))),
    Case("broad-sampling-rate-1e9", ("map", "{d}/t.mat", "--config", "{cfg}", "--out", "{d}/o"), "sampling_rate",
         broad_mat(sampling_rate=[[1e9]])),
    Case("broad-sampling-rate-1e-3", ("map", "{d}/t.mat", "--config", "{cfg}", "--out", "{d}/o"), "sampling_rate",
         broad_mat(sampling_rate=[[1e-3]])),
    Case("broad-quaternion-not-a-rotation", ("map", "{d}/t.mat", "--config", "{cfg}", "--out", "{d}/o"),
         "opt_quat at sample 0 is not a rotation", broad_mat(opt_quat=np.tile([2.0, 0, 0, 0], (50, 1)))),
    # -- physics bounds on config keys (validation/base/bounds.py): one line, the key, the bound --
    *(Case(f"config-{key.replace('.', '-')}-{value}", (*MAP, "--out", "{d}/o", "--set", f"{key}={value}"), says)
      for key, value, says in (
          ("output.map_voxel_m", "1e-9", "output.map_voxel_m: 1e-09 m is below 0.001 m"),
          ("output.map_voxel_m", "1e6", "output.map_voxel_m: 1e+06 m is above 100 m"),
          ("output.grid_resolution_m", "1e6", "output.grid_resolution_m: 1e+06 m is above 10 m"),
          ("output.grid_resolution_m", "1e-9", "output.grid_resolution_m: 1e-09 m is below 0.005 m"),
          ("submaps.resolution_m", "1e6", "submaps.resolution_m: 1e+06 m is above 10 m"),
          ("frontend.min_motion_m", "100", "min_motion_m 100 m is not below max_range_m 30 m"),
          ("frontend.min_motion_m", "1e9", "frontend.min_motion_m: 1e+09 m is above 1000 m"),
          ("keyframes.period_s", "1e-300", "keyframes.period_s: 1e-300 s is below 0.0001 s"),
          ("keyframes.period_s", "1e9", "keyframes.period_s: 1e+09 s is above 3600 s"),
          ("keyframes.distance_m", "1e-300", "keyframes.distance_m: 1e-300 m is below 0.001 m"),
          ("keyframes.yaw_deg", "1e-300", "keyframes.yaw_deg: 1e-300 deg is below 0.001 deg"),
          ("evaluation.max_time_offset_s", "1e9", "evaluation.max_time_offset_s: 1e+09 s is above 10 s"),
          ("validation.oracle_k_sigma", "1e-300", "oracle_k_sigma: 1e-300 sigmas is below 0.5 sigmas"),
          ("validation.oracle_k_sigma", "1e9", "oracle_k_sigma: 1e+09 sigmas is above 100 sigmas"),
          ("backend.factors.odometry.sigma_xy_m", "1e-300", "backend.factors.odometry.sigma_xy_m: 1e-300 m is below 0.0001 m"),
          ("backend.factors.odometry.sigma_xy_m", "1e300", "backend.factors.odometry.sigma_xy_m: 1e+300 m is above 1e+06 m"),
          ("backend.factors.odometry.sigma_yaw_deg", "1e-300", "odometry.sigma_yaw_deg: 1e-300 deg is below 0.001 deg"),
          ("backend.factors.gyro.sigma_yaw_deg", "1e-300", "backend.factors.gyro.sigma_yaw_deg: 1e-300 deg is below"),
          ("backend.factors.compass.sigma_yaw_deg", "1e-300", "backend.factors.compass.sigma_yaw_deg: 1e-300 deg"),
          ("backend.factors.compass.sigma_yaw_deg", "1e300", "compass.sigma_yaw_deg: 1e+300 deg is above 10000 deg"),
          ("backend.factors.scan_matching.sigma_xy_m", "1e-300", "scan_matching.sigma_xy_m: 1e-300 m is below"),
          ("backend.factors.scan_matching.sigma_yaw_deg", "1e-300", "scan_matching.sigma_yaw_deg: 1e-300 deg"),
          ("backend.factors.gps.sigma_floor_m", "1e-300", "backend.factors.gps.sigma_floor_m: 1e-300 m is below"),
          ("backend.factors.gps.max_time_offset_s", "1e9", "gps.max_time_offset_s: 1e+09 s is above 10 s"),
          ("backend.initial_sigma_xy_m", "1e-300", "backend.initial_sigma_xy_m: 1e-300 m is below 0.0001 m"),
          ("backend.initial_sigma_yaw_deg", "1e-300", "backend.initial_sigma_yaw_deg: 1e-300 deg is below"),
          ("submaps.local.sigma_xy_m", "1e-300", "submaps.local.sigma_xy_m: 1e-300 m is below 0.0001 m"),
      )),
    # -- a YAML truth value where a number belongs: a slip, never the number 1 or 0 --
    *(Case(f"config-{key.replace('.', '-')}-{value}", (*MAP, "--out", "{d}/o", "--set", f"{key}={value}"), says)
      for key, value, says in (
          ("backend.max_iterations", "true", "max_iterations: expected a number, not true"),
          ("submaps.search_depth", "false", "search_depth: expected a number, not false"),
          ("backend.factors.odometry.sigma_xy_m", "true", "sigma_xy_m: expected a number, not true"),
          ("validation.oracle_k_sigma", "false", "oracle_k_sigma: expected a number, not false"),
      )),
    Case("config-relation-threshold-true", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"),
         "threshold: expected a number, not true", config(relation(1, threshold=True))),
    Case("scenario-laser-rate-true", ("simulate", "{d}/s.yaml", "--out", "{d}/o"),
         "rate_hz: expected a number, not true", scenario(set_in("sensors", "laser", "rate_hz", True))),
    Case("config-relation-sigma-floor-1e-300", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"),
         "sigma_floor: 1e-300 (m or rad) is below 1e-12 (m or rad)", config(relation(1, sigma_floor=1e-300))),
    # -- physics bounds on scenarios --
    *(Case(f"scenario-{'-'.join(path[1:])}-{value:g}", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), says,
           scenario(set_in(*path, value)))
      for *path, value, says in (
          ("sensors", "laser", "min_range_m", 20.0, "sensors.laser: min_range_m 20 is not below max_range_m 10"),
          ("sensors", "odometry", "distance_scale_error", -2.0,
           "sensors.odometry.distance_scale_error: -2 is below -0.5: the odometry would report less than half"),
          ("sensors", "odometry", "rotation_overreport", 5.0, "sensors.odometry.rotation_overreport: 5 is above 1"),
          ("sensors", "gyro", "bias_initial_rad_s", 1e6, "sensors.gyro.bias_initial_rad_s: 1e+06 rad/s is above 0.5 rad/s"),
          ("sensors", "gyro", "bias_initial_rad_s", -1e6, "sensors.gyro.bias_initial_rad_s: -1e+06 rad/s is below -0.5"),
          ("sensors", "gyro", "noise_rad_s", 1e6, "sensors.gyro.noise_rad_s: 1e+06 rad/s is above 1 rad/s"),
          ("sensors", "magnetometer", "noise_T", 1.0, "sensors.magnetometer.noise_T: 1 T is above 0.0001 T"),
          ("environment", "declination_deg", 1e6, "environment.declination_deg: 1e+06 deg is above 180 deg"),
          ("environment", "field_strength_T", 1.0, "environment.field_strength_T: 1 T is above 0.001 T"),
          ("environment", "field_strength_T", 1e-12, "environment.field_strength_T: 1e-12 T is below 1e-06 T"),
          # noise, rates and reach of the simulated sensors, the thresholds of the true faults
          ("sensors", "laser", "range_noise_m", 1e300, "sensors.laser.range_noise_m: 1e+300 m is above 1 m"),
          ("sensors", "laser", "rate_hz", 1e-300, "sensors.laser.rate_hz: 1e-300 Hz is below 0.001 Hz"),
          ("sensors", "laser", "max_range_m", 1e300, "sensors.laser.max_range_m: 1e+300 m is above 1000 m"),
          ("sensors", "gyro", "bias_walk_rad_s_sqrt_s", 1e300, "sensors.gyro.bias_walk_rad_s_sqrt_s: 1e+300"),
          ("sensors", "odometry", "distance_noise_m_sqrt_m", 1e300, "sensors.odometry.distance_noise_m_sqrt_m: 1e+300"),
          ("sensors", "odometry", "yaw_noise_rad_sqrt_rad", 1e300, "sensors.odometry.yaw_noise_rad_sqrt_rad: 1e+300"),
          ("sensors", "odometry", "turn_slip_per_rad_s", 1e300, "sensors.odometry.turn_slip_per_rad_s: 1e+300 s/rad"),
          ("sensors", "gps", "sigma_m", 1e300, "sensors.gps.sigma_m: 1e+300 m is above 1e+06 m"),
          ("sensors", "gps", "sigma_m", 1e-300, "sensors.gps.sigma_m: 1e-300 m is below 0.0001 m"),
          ("sensors", "gps", "multipath_max_m", 1e300, "sensors.gps.multipath_max_m: 1e+300 m is above 1000 m"),
          ("sensors", "gps", "altitude_m", 1e300, "sensors.gps.altitude_m: 1e+300 m is above 10000 m"),
          ("sensors", "magnetometer", "mounting_height_m", 1e300, "sensors.magnetometer.mounting_height_m: 1e+300 m"),
          ("robot", "max_turn_rate_deg_s", 1e300, "robot.max_turn_rate_deg_s: 1e+300 deg/s is above 2000 deg/s"),
          ("robot", "max_accel_m_s2", 1e-300, "the mission would take about 1.25e+296 h"),
          ("faults", "gps_sigmas", 1e300, "faults.gps_sigmas: 1e+300 sigmas is above 100 sigmas"),
          ("faults", "compass_error_deg", 1e-300, "faults.compass_error_deg: 1e-300 deg is below 0.01 deg"),
      )),
    # -- physics bounds on what the readers read --
    Case("carmen-fov-1e-9", CARMEN, "no 2D laser resolves a thousandth of a degree",
         carmen(head="PARAM laser_front_laser_fov 1e-9")),
    Case("bag-angle-increment-1e-12", BAG, "no 2D laser resolves a thousandth of a degree",
         bag(each("/scan", lambda t, m: setattr(m, "angle_increment", 1e-12)))),
    *(Case(f"librsf-{name}", ("map", "{d}/X_Input.txt", "--config", str(CONFIGS / "datasets" / "librsf_corridor.yaml"),
                              *QUICK, "--out", "{d}/o"), says,
           text("X_Input.txt", "".join(f"odom2 {0.1 * k:.1f} {row if k == 7 else '0.5 0 0.01 0.01 0.01 0.01'}\n"
                                       for k in range(50))))
      for name, row, says in (
          ("negative-variance", "0.5 0 0.01 -0.01 0.01 0.01", "odom2 line #8: var_vx -0.01 is negative"),
          ("negative-yaw-variance", "0.5 0 0.01 0.01 0.01 -1", "odom2 line #8: var_wz -1 is negative"),
          ("speed-1e9", "1e9 0 0.01 0.01 0.01 0.01", "odom2 line #8: speed 1e+09 m/s"),
      )),
    *(Case(f"set-{key}-{value}", (*MAP, "--out", "{d}/o", "--set", f"validation.observers.{key}={value}"), says)
      for key, value, says in (
          ("scan_ceiling.settle_s", "1e300", "scan_ceiling.settle_s: 1e+300 s is above 86400 s"),
          ("scan_ceiling.fill_s", "1e300", "scan_ceiling.fill_s: 1e+300 s is above 86400 s"),
          ("gps.max_sigma_m", "1e-300", "gps.max_sigma_m: 1e-300 m is below 0.0001 m"),
      )),
    # -- counts bounded before they reach C++ (KISS-ICP, GTSAM) or size an array --
    *(Case(f"set-{key}-{value}", (*MAP, "--out", "{d}/o", "--set", f"{key}={value}"), f"--set {key}={value}: {key}: {says}")
      for key, value, says in (
          ("frontend.max_points_per_voxel", "100000000000000000000", "1e+20 is above 1e+06"),
          ("frontend.max_iterations", "100000000000000000000", "1e+20 iterations is above 100000 iterations"),
          ("frontend.threads", "100000000000000000000", "1e+20 threads is above 1024 threads"),
          ("backend.max_iterations", str(10**25), "1e+25 iterations is above 100000 iterations"),
          ("loops.registration.max_iterations", "100000000000000000000", "1e+20 iterations is above"),
          ("submaps.refine.max_points", "100000000000000000000", "1e+20 is above 1e+06"),
          ("submaps.recognition.rings", "100000000000000000000", "1e+20 is above 1e+06"),
          ("backend.max_iterations", "1e300", "Input should be a valid integer"),
      )),
    # -- search windows and the grids they pad --
    *(Case(f"set-{key}-{value}", (*MAP, "--out", "{d}/o", "--set", f"{key}={value}"), f"--set {key}={value}: {says}")
      for key, value, says in (
          ("submaps.local.linear_window_m", "1e5", "submaps.local.linear_window_m: 100000 m is above 100 m"),
          ("submaps.constraints.max_linear_window_m", "1e5", "submaps.constraints.max_linear_window_m: 100000 m is above"),
          ("submaps.recognition.linear_window_m", "1e5", "submaps.recognition.linear_window_m: 100000 m is above"),
          ("loops.descriptor.linear_window_m", "1e5", "loops.descriptor.linear_window_m: 100000 m is above"),
          ("submaps.constraints.max_linear_window_m", "90", "submaps: constraints.max_linear_window_m 90 m at resolution_m 0.1 m "
           "pads each submap's search grid by 3,600 cells per axis (at most 2,000)"),
          ("submaps.local.max_linear_window_m", "0.1", "submaps.local: linear_window_m 0.6 m is above max_linear_window_m 0.1 m"),
          ("submaps.constraints.angular_window_deg", "1e5", "submaps.constraints.angular_window_deg"),
      )),
    # -- injected faults outside physics or outside the recording --
    *(Case(f"inject-{fault}", ("inject", "{run}", "--fault", fault, "--out", "{d}/o"), says)
      for fault, says in (
          ("laser_cut@2:4,range_m=1e-9", "--fault laser_cut@2:4,range_m=1e-9: range_m: 1e-09 m is below 0.01 m"),
          ("laser_cut@2:4,range_m=1e9", "--fault laser_cut@2:4,range_m=1e9: range_m: 1e+09 m is above 1000 m"),
          ("slip@2:4,scale=1e9", "--fault slip@2:4,scale=1e9: scale: 1e+09 is above 10"),
          ("slip@2:4,yaw_scale=1e9", "--fault slip@2:4,yaw_scale=1e9: yaw_scale: 1e+09 is above 10"),
          ("gyro_bias@2:4,bias_deg_s=1e300", "--fault gyro_bias@2:4,bias_deg_s=1e300: bias_deg_s: 1e+300 deg/s is above 2000 deg/s"),
          ("gyro_bias@4:2", "--fault gyro_bias@4:2: the interval 4:2 must end after it starts"),
          ("gyro_bias@2:1e6", "--fault gyro_bias@2:1e+06,bias_deg_s=2.0,label_deg_s=0.57: ends at 1e+06 s, after "
           "the recording ends (24.0 s)"),
          ("gyro_bias@2:1e300", "--fault gyro_bias@2:1e300: end_s: 1e+300 s is above 4.29497e+09 s"),
          ("gyro_bias@1000:2000", "--fault gyro_bias@1000:2000,bias_deg_s=2.0,label_deg_s=0.57: starts after the recording ends"),
          ("multipath@2:4,label_sigmas=1e300", "label_sigmas: 1e+300 sigmas is above 100 sigmas"),
          ("multipath@2:4,label_sigmas=1e-300", "label_sigmas: 1e-300 sigmas is below 0.5 sigmas"),
          ("multipath@2:4,bias_m=1e300", "bias_m: 1e+300 m is above 1000 m"),
          ("multipath@2:4,azimuth_deg=1e300", "azimuth_deg: 1e+300 deg is above 360 deg"),
          ("dipole@2:4,label_deg=1e-300", "label_deg: 1e-300 deg is below 0.01 deg"),
          ("dipole@2:4,moment_A_m2=1e300", "moment_A_m2: 1e+300 A m^2 is above 1e+06 A m^2"),
          ("dipole@2:4,distance_m=1e-300", "distance_m: 1e-300 m is below 0.01 m"),
          ("dipole@2:4,height_m=1e300", "height_m: 1e+300 m is above 1000 m"),
          ("dipole@2:4,earth_horizontal_uT=1e300", "earth_horizontal_uT: 1e+300 uT is above 100 uT"),
          ("gyro_bias@2:4,label_deg_s=1e-300", "label_deg_s: 1e-300 deg/s is below 0.001 deg/s"),
          ("slip@2:4,label_slip=1e300", "label_slip: 1e+300 is above 10"),
          ("laser_cut@2:4,label_min_eigenvalue=1e300", "label_min_eigenvalue: 1e+300 is above 1"),
      )),
    # -- sigmas and observer parameters outside sense --
    *(Case(f"set-{key}-{value}", (*MAP, "--out", "{d}/o", "--set", f"{key}={value}"), f"--set {key}={value}: {says}")
      for key, value, says in (
          ("backend.factors.odometry.sigma_xy_per_m", "1e300", "backend.factors.odometry.sigma_xy_per_m: 1e+300 is above 100"),
          ("backend.factors.gyro.sigma_yaw_per_s_deg", "1e300", "backend.factors.gyro.sigma_yaw_per_s_deg: 1e+300 is above 100"),
          ("backend.factors.gps.sigma_scale", "1e-300", "backend.factors.gps.sigma_scale: 1e-300 is below 0.001"),
          ("backend.factors.gps.sigma_scale", "1e300", "backend.factors.gps.sigma_scale: 1e+300 is above 1000"),
          ("backend.factors.odometry.sigma_xy_m", "1e-300", "backend.factors.odometry.sigma_xy_m: 1e-300 m is below 0.0001 m"),
          ("validation.observers.magnetometer.hold_s", "1e12", "validation.observers.magnetometer.hold_s: 1e+12 s is above 86400 s"),
          ("submaps.refine.max_sigma_m", "1e-300", "submaps.refine.max_sigma_m: 1e-300 m is below 0.0001 m"),
          ("submaps.refine.max_sigma_m", "1e300", "submaps.refine.max_sigma_m: 1e+300 m is above 1e+06 m"),
          ("loops.file.sigma_m", "1e-300", "loops.file.sigma_m: 1e-300 m is below 0.0001 m"),
          ("loops.file.sigma_m", "1e300", "loops.file.sigma_m: 1e+300 m is above 1e+06 m"),
          ("submaps.refine.information_scale", "1e-300", "submaps.refine.information_scale: 1e-300 is below 1e-06"),
          ("loops.information_scale", "1e300", "loops.information_scale: 1e+300 is above 1e+06"),
          ("backend.robust_param", "1e-300", "backend.robust_param: 1e-300 sigmas is below 0.01 sigmas"),
          ("backend.factors.gps.robust_param", "1e300", "backend.factors.gps.robust_param: 1e+300 sigmas is above 100"),
          ("loops.robust_param", "1e-300", "loops.robust_param: 1e-300 sigmas is below 0.01 sigmas"),
          ("submaps.constraints.robust_scale", "1e-300", "submaps.constraints.robust_scale: 1e-300 sigmas is below"),
          ("backend.fallback_inflation", "1e300", "backend.fallback_inflation: 1e+300 is above 1000"),
      )),
    *(Case(f"relation-{name}", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"), says, config(relation(i, **values)))
      for name, i, values, says in (
          ("boundary-1e9", 0, {"boundary": 1e9}, "relations.0.boundary: 1e+09 (stream units per s) is above 1000"),
          ("boundary-negative", 0, {"boundary": -1.0}, "relations.0.boundary: Input should be greater than 0"),
          ("k-sigma-1e300", 5, {"k_sigma": 1e300}, "relations.5.k_sigma: 1e+300 sigmas is above 100 sigmas"),
          ("k-sigma-1e-300", 5, {"k_sigma": 1e-300}, "relations.5.k_sigma: 1e-300 sigmas is below 0.5 sigmas"),
          ("sigma-rel-1e300", 5, {"sigma_rel": 1e300}, "relations.5.sigma_rel: 1e+300 is above 1000"),
          ("sigma-floor-1e-300", 5, {"sigma_floor": 1e-300}, "relations.5.sigma_floor: 1e-300 (m or rad) is below"),
      )),
    *(Case(f"relation-window-{value}", (*MAP[:2], "--config", "{d}/c.yaml", "--gating", "on", "--out", "{d}/o"),
           says, config(relation(0, window_s=value)))
      for value, says in ((1e-9, "relations.0.window_s: 1e-09 s is below 0.001 s"),
                          (1e9, "relations.0.window_s: 1e+09 s is above 86400 s"))),
    Case("set-integer-of-5000-digits", (*MAP, "--out", "{d}/o", "--set", "backend.max_iterations=" + "9" * 5000),
         "an integer of 5,000 digits; no setting needs more than 30"),
    Case("config-integer-of-5000-digits", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"),
         "c.yaml: line 2: invalid YAML (an integer of 5,000 digits", text("c.yaml", "backend:\n  max_iterations: " + "9" * 5000 + "\n")),
    Case("relation-threshold-1e12", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"),
         "relations.0.threshold: 1e+12 is above 1e+06", config(relation(0, threshold=10**12, max_counter=None))),
    *(Case(f"broad-{name}", ("map", "{d}/t.mat", "--config", "{cfg}", "--out", "{d}/o"), says, broad_mat(**fields))
      for name, fields, says in (
          ("no-gravity", {"imu_acc": np.zeros((50, 3))}, "imu_acc: median magnitude 0 m/s^2, expected gravity"),
          ("acceleration-in-g", {"imu_acc": np.tile([0.0, 0.0, 1.0], (50, 1))}, "imu_acc: median magnitude 1 m/s^2"),
          ("no-field", {"imu_mag": np.zeros((50, 3))}, "imu_mag: median magnitude 0 uT, expected the Earth's field"),
          ("field-of-1-tesla", {"imu_mag": np.tile([0.0, 1e6, 0.0], (50, 1))}, "imu_mag: median magnitude 1e+06 uT"),
          ("gyro-1e6-rad-s", {"imu_gyr": np.vstack([np.zeros((10, 3)), [[1e6, 0.0, 0.0]], np.zeros((39, 3))])},
           "imu_gyr at sample 10 is 1e+06 rad/s"),
      )),
    # -- distances, reaches and tolerances a run cannot use (validation/base/bounds.py) --
    *(Case(f"set-{key}-{value}", (*MAP, "--out", "{d}/o", "--set", f"{key}={value}"), f"--set {key}={value}: {key}: {says}")
      for key, value, says in (
          ("frontend.max_range_m", "1e300", "1e+300 m is above 1000 m"),
          ("frontend.initial_threshold_m", "1e300", "1e+300 m is above 100 m"),
          ("frontend.initial_threshold_m", "1e-300", "1e-300 m is below 0.001 m"),
          ("backend.relative_error_tol", "1e300", "1e+300 is above 1"),
          ("backend.relative_error_tol", "1e-300", "1e-300 is below 1e-15"),
          ("evaluation.sm_fault_window_s", "1e-300", "1e-300 s is below 0.01 s"),
          ("evaluation.sm_fault_trans_m", "1e300", "1e+300 m is above 100 m"),
          ("output.grid_no_return_m", "1e300", "1e+300 m is above 1000 m"),
          ("submaps.refine.kernel_m", "1e-300", "1e-300 m is below 0.001 m"),
          ("submaps.refine.max_distance_m", "1e300", "1e+300 m is above 100 m"),
          ("loops.registration.kernel_m", "1e-300", "1e-300 m is below 0.001 m"),
      )),
    # -- the gating section's multiples and spans --
    *(Case(f"set-{key}-{value}", (*MAP, "--gating", "on", "--out", "{d}/o", "--set", f"{key}={value}"),
           f"--set {key}={value}: {key}: {says}")
      for key, value, says in (
          ("gating.inflation", "1e300", "1e+300 is above 1000"),
          ("gating.holdoff_s", "1e300", "1e+300 s is above 86400 s"),
          ("gating.lookback_s", "1e300", "1e+300 s is above 86400 s"),
          ("gating.recheck_window_s", "1e300", "1e+300 s is above 86400 s"),
          ("gating.keep_k_sigma", "1e-300", "1e-300 sigmas is below 0.5 sigmas"),
      )),
    # -- the observers' fields, windows and geometry --
    *(Case(f"set-{key}-{value}", (*MAP, "--gating", "on", "--out", "{d}/o", "--set", f"validation.observers.{key}={value}"),
           f"validation.observers.{key}: {says}")
      for key, value, says in (
          ("magnetometer.strength_T", "1.0", "1 T is above 0.001 T"),
          ("magnetometer.tolerance_T", "1e300", "1e+300 T is above 0.001 T"),
          ("magnetometer.tolerance_dip_deg", "1e300", "1e+300 deg is above 180 deg"),
          ("max_gap_s", "1e300", "1e+300 s is above 86400 s"),
          ("gps_speed_window_s", "1e-300", "1e-300 s is below 0.001 s"),
          ("scan.min_eigenvalue", "1e300", "1e+300 is above 1"),
          ("scan_ceiling.max_ceiling_m", "1e300", "1e+300 m is above 1000 m"),
          ("gps_course_min_speed_mps", "1e300", "1e+300 m/s is above 100 m/s"),
      )),
    # -- a system model's errors name its file, not the config or a --set that did not touch it --
    *(Case(f"model-{name}", (*MAP[:2], "--config", "{d}/c.yaml", *extra, "--out", "{d}/o"), f"m.yaml: validation.{says}",
           both(text("m.yaml", change((CONFIGS / "validation" / "telemax_model.yaml").read_text())),
                config(lambda t: t["validation"].update(model="m.yaml"))))
      for name, extra, change, says in (
          ("prior-1-with-gating-on", ("--gating", "on"), lambda m: m.replace("LOOP: 0.05", "LOOP: 1.0"),
           "model.priors: prior of 'LOOP' must be in [1e-09, 1), got 1"),
          ("prior-negative", (), lambda m: m.replace("LOOP: 0.05", "LOOP: -0.5"), "model.priors: prior of 'LOOP'"),
          ("prior-1e-300", ("--gating", "on"), lambda m: m.replace("LOOP: 0.05", "LOOP: 1.0e-300"),
           "model.priors: prior of 'LOOP' must be in [1e-09, 1), got 1e-300"),
          ("false-alarm-1e-300", ("--gating", "on"), lambda m: m.replace("priors:", "false_alarm: {yaw_compass_gyro: 1.0e-300}\npriors:"),
           "model: false_alarm.yaw_compass_gyro must be in [1e-09, 1), got 1e-300"),
          ("component-propagates-to-itself", ("--gating", "on"),
           lambda m: m.replace("fault_propagation: []", "fault_propagation: [[IMU_YAW, IMU_YAW]]"),
           "model: fault_propagation.0: a rule needs two different components, not 'IMU_YAW' twice"),
          ("relation-of-one-component", ("--gating", "on"),
           lambda m: m.replace("yaw_compass_gyro: [IMU_YAW, IMU_GYRO]   #", "yaw_compass_gyro: [IMU_YAW, IMU_YAW]   #"),
           "model: relations.yaw_compass_gyro: a relation needs two different components"),
          ("masking-probability-2", ("--set", "validation.mode=on"), lambda m: m.replace(
              "failure_masking: []", "failure_masking:\n  - {relation: yaw_compass_gyro, corr: true, masking_prob: 2.0}"),
           "model.failure_masking.0.masking_prob: Input should be less than 1"),
      )),
    # -- result markers and a sweep's own files, read back as input --
    Case("marker-json-nested-100000-deep", (*MAP, *QUICK, "--out", "{d}/m"),
         "--out is a folder that is not a gslam map result (its .gslam-result.json is not one gslam wrote)",
         text("m/.gslam-result.json", "[" * 100_000 + "]" * 100_000)),
    Case("marker-input-a-number", (*MAP, *QUICK, "--out", "{d}/m"), "its input 123 is not a path",
         text("m/.gslam-result.json", json.dumps({"command": "map", "files": ["metrics.json"], "input": 123}))),
    Case("marker-input-empty", (*MAP, *QUICK, "--out", "{d}/m"), "its input '' is not a path",
         text("m/.gslam-result.json", json.dumps({"command": "map", "files": ["metrics.json"], "input": ""}))),
    Case("added-record-not-json-force", (*MAP, *QUICK, "--out", "{d}/m", "--force"),
         ".gslam-added.json: not a record gslam wrote (not a JSON object)",
         both(text("m/notes.txt", "mine"), text("m/.gslam-added.json", "{not json"))),
    Case("added-record-a-list-force", (*MAP, *QUICK, "--out", "{d}/m", "--force"),
         ".gslam-added.json: not a record gslam wrote (not a JSON object)",
         both(text("m/notes.txt", "mine"), text("m/.gslam-added.json", "[]"))),
    Case("marker-files-hold-numbers", (*MAP, *QUICK, "--out", "{d}/m"), "lists 1, which is not a file inside the folder",
         text("m/.gslam-result.json", json.dumps({"command": "map", "files": [1, 2]}))),
    Case("marker-files-is-a-path", (*MAP, *QUICK, "--out", "{d}/m"), "lists '../x', which is not a file inside the folder",
         text("m/.gslam-result.json", json.dumps({"command": "map", "files": "../x"}))),
    *(Case(f"ablate-resumed-{name}", ("ablate", "{spec}", "--out", "{d}/o"),
           f"metrics.json: expected the JSON object gslam writes, found {says}", finished_sweep(content))
      for name, content, says in (
          ("metrics-cut-short", '{"ate_rmse_m": ', "invalid JSON (Expecting value: line 1 column 16"),
          ("metrics-a-list", "[1, 2]", "a JSON list"),
          ("metrics-nested-100000-deep", "[" * 100_000, "JSON nested too deeply"),
      )),
    # -- a loop of links, above --out or as the input --
    *(Case(f"{command}-out-under-a-link-loop", (*argv, "{d}/a/x"), "a/x: too many levels of symbolic links", link_loop("a"))
      for command, argv in (
          ("map", (*MAP, *QUICK, "--out")),
          ("simulate", ("simulate", "{scen}", "--out")),
          ("compare", ("compare", "{run}", "--config", "{cfg}", "--out")),
          ("inject", ("inject", "{run}", "--fault", "gyro_bias@2:4", "--out")),
          ("calibrate", (*CAL, "--out")),
          ("inspect", ("inspect", "{run}", "--config-out")),
          ("demo", ("demo", "--out")),
          ("ablate", ("ablate", "{spec}", "--out")),
      )),
    Case("ablate-scenario-a-link-loop", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), "a: too many levels of symbolic links",
         both(link_loop("a"), lambda d, w: spec_in(d, w, inputs={"scenarios": [{"path": str(d / "a"), "seeds": [1]}]}))),
    Case("map-input-a-link-loop", ("map", "{d}/a", "--config", "{cfg}", "--out", "{d}/o"),
         "a: too many levels of symbolic links", link_loop("a")),
    Case("inspect-input-a-link-loop", ("inspect", "{d}/a"), "a: too many levels of symbolic links", link_loop("a")),
    Case("calibrate-input-a-dangling-link", ("calibrate", "{d}/a", "--config", "{cfg}", "--clean", "0:10", "--out", "{d}/c.yaml"),
         "a: a symbolic link to ", lambda d, w: (d / "a").symlink_to(d / "nowhere")),
    Case("config-model-a-link-loop", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"),
         "m.yaml: cannot read YAML file (Too many levels of symbolic links)",
         both(link_loop("m.yaml"), text("c.yaml", "validation: {model: m.yaml}\n"))),
    # -- command-line values no run can use --
    Case("ablate-workers-1e11", ("ablate", "{spec}", "--out", "{d}/o", "--workers", "100000000000"),
         "argument --workers: expected at most 1024, got 1e+11", code=2),
    Case("compare-only-empty", ("compare", "{run}", "--config", "{cfg}", "--only", "", "--out", "{d}/o"),
         "argument --only: expected comma-separated variant names, got ''", code=2),
    Case("compare-only-an-empty-name", ("compare", "{run}", "--config", "{cfg}", "--only", "gated,,ungated", "--out", "{d}/o"),
         "argument --only: expected comma-separated variant names, got 'gated,,ungated'", code=2),
    Case("demo-only-blank", ("demo", "--only", " ", "--out", "{d}/o"), "argument --only: expected comma-separated", code=2),
    # -- configs of the wrong YAML shape --
    Case("config-merge-key-brings-its-anchor", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"), "unknown config key 'base'",
         text("c.yaml", "base: &b {period_s: 0.5}\nkeyframes: {<<: *b}\n")),
    Case("config-key-a-number", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"), "c.yaml: 1: Keys should be strings",
         text("c.yaml", "1: 2\n")),
    Case("config-two-documents", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"),
         "line 2: invalid YAML (but found another document)", text("c.yaml", "keyframes: {period_s: 0.5}\n---\nbackend: {}\n")),
    Case("config-tab-indented", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"), "line 2: invalid YAML",
         text("c.yaml", "keyframes:\n\tperiod_s: 0.5\n")),
    Case("config-date-for-a-period", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"),
         "keyframes.period_s: Input should be a valid number", text("c.yaml", "keyframes: {period_s: 2024-01-01}\n")),
    Case("scenario-wall-of-words", ("simulate", "{d}/s.yaml", "--out", "{d}/o"),
         "world.walls.0.0.0: Input should be a valid number", scenario(set_in("world", "walls", [[["a", "b"], [1, 2]]]))),
    # -- a reader told the wrong format, and values each reader already refuses --
    Case("map-run-folder-read-as-carmen", (*MAP, *QUICK, "--set", "input.format=carmen", "--out", "{d}/o"),
         "bag: expected a CARMEN log file, got a directory"),
    Case("map-carmen-log-read-as-a-bag", ("map", "{d}/c.log", "--config", str(CONFIGS / "datasets" / "carmen.yaml"), *QUICK,
                                          "--set", "input.format=rosbag", "--out", "{d}/o"),
         "c.log: not a readable ROS bag", carmen()),
    Case("carmen-robotlaser-fov-nan", CARMEN, "c.log:1: expected finite numbers in ROBOTLASER1",
         carmen(robotlaser=(-1.57, math.nan, 0.0174))),
    Case("broad-positions-1e300", ("map", "{d}/t.mat", "--config", "{cfg}", "--out", "{d}/o"),
         "groundtruth pose 0 (t = 0.000 s) is at (1e+300, 1e+300) m, beyond 1e+07 m", broad_mat(opt_pos=np.full((50, 3), 1e300))),
    Case("broad-quaternion-1e-300", ("map", "{d}/t.mat", "--config", "{cfg}", "--out", "{d}/o"),
         "opt_quat at sample 0 is not a rotation", broad_mat(opt_quat=np.tile([1e-300, 0, 0, 0], (50, 1)))),
    Case("scenario-door-1e300-wide", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), "world.doors.0.width_m: 1e+300 m is above 100 m",
         scenario(lambda t: t["world"].update(doors=[{"center": [0, 0], "width_m": 1e300}]))),
    # -- physics of what the readers read --
    Case("bag-gps-covariance-1e300", BAG, "gps fix 0 has a sigma of 1e+150 m; one beyond 1e+06 m says nothing",
         bag(each("/gps/fix", _covariance(1e300)))),
    Case("bag-magnetic-field-of-1-tesla", MAG_BAG, "compass: median field 1e+06 uT, expected the Earth's",
         bag(each("/imu/mag", lambda t, m: setattr(m.magnetic_field, "x", 1.0)))),
    Case("bag-magnetic-field-zero", MAG_BAG, "compass: median field 0 uT, expected the Earth's",
         bag(each("/imu/mag", lambda t, m: [setattr(m.magnetic_field, k, 0.0) for k in "xyz"]))),
    Case("broad-sampling-rate-a-word", ("map", "{d}/t.mat", "--config", "{cfg}", "--out", "{d}/o"),
         "sampling_rate: expected an IMU's rate in Hz (1 to 100000; BROAD's is 285.7), got 'fast'",
         broad_mat(sampling_rate="fast")),
    Case("broad-magnetometer-nan", ("map", "{d}/t.mat", "--config", "{cfg}", "--out", "{d}/o"),
         "imu_gyr/imu_acc/imu_mag: expected finite samples", broad_mat(imu_mag=np.full((50, 3), np.nan))),
    *(Case(f"librsf-{name}", LIBRSF, says, librsf_with(loop)) for name, loop, says in (
        ("loop-weight-1e300", "loop 9.0 1.0 1e300", "loop line #1: weight 1e+300; expected 0 to 1e+06"),
        ("loop-weight-negative", "loop 9.0 1.0 -1", "loop line #1: weight -1; expected 0 to 1e+06"),
        ("loop-after-the-log", "loop 9.0 1e6 1", "loop line #1: t_other 1e+06 s is outside the odom2 lines' 0 to 9.9 s"),
        ("loop-from-a-pose-to-itself", "loop 9.0 1.0 1\nloop 5.0 5.0 1",
         "loop line #2: t and t_other are both 5 s, a pose joined to itself"),
        ("loop-weight-nan", "loop 9.0 1.0 nan", "X_Input.txt:101: expected loop t t_other weight"),
    )),
    Case("librsf-ground-truth-goes-back", LIBRSF, "X_GT.txt: point2 line #51: expected increasing times",
         librsf_with("loop 9.0 1.0 1", "".join(f"point2 {0.1 * (k % 50):.1f} {0.05 * k} 0 0.1 0 0 0.1\n" for k in range(100)))),
    Case("carmen-a-billion-beams", CARMEN, "c.log:1: expected FLASER n r_1..r_n", text("c.log", "FLASER 1000000000 1 2 3 "
                                                                                        "0 0 0 0 0 0 1.0 host 1.0\n")),
    Case("carmen-negative-beam-count", CARMEN, "c.log:1: expected a positive beam count",
         text("c.log", "FLASER -3 1 2 3 0 0 0 0 0 0 1.0 host 1.0\n")),
    # -- a world whose size makes the simulation compute for hours (slam/sim/budget.py's check_work) --
    *(Case(f"scenario-{name}", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), f"simulating would compute for about {says}",
           scenario(lambda t, change=change: _an_hour_long(t) or change(t)))
      for name, change, says in (
          ("20000-walls-in-the-lasers-range", lambda t: t["world"]["walls"].append(
              [[float(x), 5.0 + 0.1 * (k % 2)] for k, x in enumerate(np.linspace(0.0, 8.0, 20_001))]),
           "1.9 h, most of it ray casting 30,290 scans (sensors.laser.rate_hz 10 over about 3029 s) of 541 beams"),
          ("15000-steel-structures-at-1-khz", lambda t: t["world"].update(disturbers=[
              {"name": f"d{k}", "position": [100.0, 100.0, 0.5], "moment_A_m2": 10.0} for k in range(15_000)])
           or t["robot"].update(truth_rate_hz=1000.0) or t["sensors"]["magnetometer"].update(rate_hz=1000.0),
           "1.6 h, most of it the field of 15,000 steel structures (world.disturbers)"),
          ("25000-doors-in-25000-walls", lambda t: t["world"].update(
              doors=[{"center": [1000.0 + k, 1000.0], "width_m": 0.5} for k in range(25_000)])
           or t["world"]["walls"].append([[float(x), 500.0] for x in np.linspace(0.0, 100.0, 25_001)]),
           "1.6 h, most of it cutting 25,000 doors (world.doors) into 25,0"),
      )),
    # -- a run folder's truth.json read as input: the physics of its reference and datum --
    *(Case(f"truth-{name}", ("map", "{d}/run", "--config", "{cfg}", *QUICK, "--out", "{d}/o"), f"truth.json: {says}",
           copy_run(_truth_with(section, key, value)))
      for name, section, key, value, says in (
          ("field-negative", "magnetic_reference", "strength_T", -48e-6,
           "magnetic_reference.strength_T: -4.8e-05 T is below 1e-06 T"),
          ("field-of-1-tesla", "magnetic_reference", "strength_T", 1.0, "magnetic_reference.strength_T: 1 T is above 0.001 T"),
          ("dip-10-rad", "magnetic_reference", "dip_rad", 10.0, "magnetic_reference.dip_rad: 10 rad is above 1.5708 rad"),
          ("declination-1e6-rad", "magnetic_reference", "declination_rad", 1e6,
           "magnetic_reference.declination_rad: 1e+06 rad is above 3.14159 rad"),
          ("datum-latitude-100", "gps_datum", "lat_deg", 100.0, "gps_datum.lat_deg: 100 deg is above 90 deg"),
      )),
    # -- a scenario's coordinates and its legs' speeds: a site, driven by a ground robot --
    *(Case(f"scenario-{name}", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), says, scenario(change))
      for name, change, says in (
          ("steel-at-1e300-m", lambda t: t["world"]["disturbers"].append(
              {"name": "far", "position": [1e300, 1.0, 0.0], "moment_A_m2": 10.0}),
           "world.disturbers.2.position.0: 1e+300 m is above 1e+06 m: a scenario's world is a site within 1000 km"),
          ("wall-to-1e300-m", lambda t: t["world"]["walls"].append([[1e300, 0.0], [-1e300, 0.0]]),
           "world.walls.7.0.0: 1e+300 m is above 1e+06 m"),
          ("region-corner-at-minus-1e300-m", lambda t: t["world"]["regions"][0]["polygon"].__setitem__(0, [-1e300, 0.0]),
           "world.regions.0.polygon.0.0: -1e+300 m is below -1e+06 m"),
          ("waypoint-at-1e300-m", lambda t: t["robot"]["waypoints"].__setitem__(1, [1e300, 1.2]),
           "robot.waypoints: waypoint 1 at (1e+300, 1.2) m lies beyond 1e+06 m of the origin"),
          ("leg-speed-1e300", lambda t: t["robot"]["waypoints"].__setitem__(1, [1.0, 1.2, 0.0, 1e300]),
           "robot.waypoints: waypoint 1's leg speed (fourth value) 1e+300 m/s is above 50 m/s"),
          ("leg-speed-1e-300", lambda t: t["robot"]["waypoints"].__setitem__(1, [1.0, 1.2, 0.0, 1e-300]),
           "s.yaml: the mission would take about 3.89e+296 h, most of it the 1.4 m leg to robot.waypoints.1 at its "
           "speed 1e-300 m/s (its fourth value)"),
      )),
    # -- command-line values that say nothing, or say one thing twice --
    *(Case(f"inject-{name}", ("inject", "{run}", "--fault", fault, "--out", "{d}/o"), f"--fault {fault}: {says}")
      for name, fault, says in (
          ("param-given-twice", "gyro_bias@2:4,bias_deg_s=1,bias_deg_s=50", "'bias_deg_s' given twice"),
          ("start-given-as-a-param", "gyro_bias@2:4,start_s=3", "'start_s' given twice (KIND@T0:T1 gives it)"),
      )),
    *(Case(f"calibrate-false-alarm-{value}", ("calibrate", "{run}", "--config", "{cfg}", "--false-alarm", value, "--out",
                                              "{d}/c.yaml"), f"--false-alarm {says}: expected a share of steps from 1e-06")
      for value, says in (("1e-300", "1e-300"), ("0.9", "0.9"))),
    # -- ablation specs that sweep nothing --
    Case("ablate-grid-axis-empty", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"),
         "spec.yaml: sweep.grid.gating.inflation: List should have at least 1 item", spec(sweep={"grid": {"gating.inflation": []}})),
    Case("ablate-input-grid-axis-empty", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), "sweep.grid.1.gating.inflation: List",
         spec(sweep={"grid": [{"gating.inflation": [2.0]}, {"gating.inflation": []}]})),
    Case("ablate-name-empty", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), "spec.yaml: name: String should have at least 1",
         spec(name="")),
    # -- BROAD fields MATLAB stored as something other than one real array of the trial's length --
    *(Case(f"broad-{name}", ("map", "{d}/t.mat", "--config", "{cfg}", "--out", "{d}/o"), f"t.mat: {says}", broad_mat(**fields))
      for name, fields, says in (
          ("gyro-complex", {"imu_gyr": np.zeros((50, 3)) + 1j}, "imu_gyr: expected real numbers, got complex numbers"),
          ("acceleration-text", {"imu_acc": "abc"}, "imu_acc: expected real numbers, got text"),
          ("sampling-rate-two-values", {"sampling_rate": np.array([[100.0, 200.0]])},
           "sampling_rate: expected one IMU rate in Hz (BROAD's is 285.7), got 2 values"),
          ("positions-of-two-columns", {"opt_pos": np.zeros((50, 2))}, "opt_pos: expected shape (50, 3), got (50, 2)"),
      )),
    *(Case(f"broad-{name}", ("map", "{d}/t.mat", "--config", "{cfg}", "--set", "keyframes.period_s=0.05", "--out", "{d}/o"),
           f"t.mat: opt_quat/opt_pos: no sample has a tracked pose (finite opt_quat and opt_pos) with the pitch within 60 deg",
           broad_mat(**fields))
      for name, fields in (
          ("positions-all-nan", {"opt_pos": np.full((50, 3), np.nan)}),
          ("truth-pitched-beyond-60-deg", {"opt_quat": np.tile([np.cos(0.7), 0.0, np.sin(0.7), 0.0], (50, 1))}),
      )),
    # -- text in a wide encoding, named as such (UTF-8 is expected) --
    Case("config-utf32", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"), "c.yaml: UTF-32 text; expected a YAML config",
         raw("c.yaml", "keyframes: {period_s: 0.5}\n".encode("utf-32"))),
    Case("config-utf16-without-a-bom", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"), "c.yaml: UTF-16 text; expected",
         raw("c.yaml", "keyframes: {period_s: 0.5}\n".encode("utf-16-le"))),
    Case("carmen-utf16", CARMEN, "c.log: cannot read: UTF-16 text; expected a CARMEN text log in ASCII or UTF-8",
         carmen(encoding=lambda s: s.encode("utf-16"))),
    Case("librsf-utf16-without-a-bom", LIBRSF, "X_Input.txt: cannot read: UTF-16 text; expected a libRSF text file",
         raw("X_Input.txt", "".join(f"odom2 {0.1 * k:.1f} 0.5 0 0 1 1 1\n" for k in range(50)).encode("utf-16-be"))),
    # -- an output path that goes up from a name that is no folder, or a file named like a folder --
    *(Case(f"{command}-out-up-from-a-missing-folder", (*argv, "{d}/typo/.."),
           "typo/..: --out goes up from", text("mine.txt", "mine\n"))
      for command, argv in (
          ("map", (*MAP, *QUICK, "--out")),
          ("simulate", ("simulate", "{scen}", "--out")),
          ("inject", ("inject", "{run}", "--fault", "gyro_bias@2:4", "--out")),
          ("calibrate", ("calibrate", "{run}", "--config", "{cfg}", "--out")),
      )),
    Case("calibrate-out-ends-in-a-slash", ("calibrate", "{run}", "--config", "{cfg}", "--out", "{d}/c.yaml/"), "c.yaml/: --out ends in '/', which names a folder"),
    Case("inspect-config-out-ends-in-a-slash", ("inspect", "{run}", "--config-out", "{d}/c.yaml/"),
         "c.yaml/: --config-out ends in '/', which names a folder"),
    Case("scenario-laser-field-of-view-1e-9-deg", ("simulate", "{d}/s.yaml", "--out", "{d}/o"),
         "sensors.laser: fov_deg 1e-09 over beams 541 puts the beams 1.85e-12 deg apart; no 2D laser resolves",
         scenario(lambda t: t.setdefault("sensors", {}).setdefault("laser", {}).update(fov_deg=1e-9))),
    # -- the fourth attack's kinds each reader and command already answers in one line, kept so that none
    # -- turns into a traceback later: unreadable inputs (/proc/self/mem fails to read even for root, where
    # -- chmod 000 hides nothing), NaN and infinity in fields no case had, folders where files go, --set forms
    *(Case(f"{name}-unreadable", argv, f"{file}: cannot read{says}", unreadable(file))
      for name, argv, file, says in (
          ("config", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"), "c.yaml", " config (Input/output error)"),
          ("scenario", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), "s.yaml", " scenario (Input/output error)"),
          ("spec", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), "spec.yaml", " ablation spec (Input/output error)"),
          ("variants", ("compare", "{run}", "--config", "{cfg}", "--variants", "{d}/v.yaml", "--out", "{d}/o"), "v.yaml",
           " variants file (Input/output error)"),
          ("carmen-log", CARMEN, "c.log", " (Input/output error)"),
          ("librsf-log", LIBRSF, "X_Input.txt", " (Input/output error)"),
          ("ros1-bag", ("map", "{d}/r.bag", "--config", "{cfg}", "--out", "{d}/o"), "r.bag", " (Input/output error)"),
          ("broad-trial", ("map", "{d}/t.mat", "--config", "{cfg}", "--out", "{d}/o"), "t.mat",
           " as a MATLAB v5 file ([Errno 5] Input/output error)"),
          ("inspect-mcap", ("inspect", "{d}/r.mcap"), "r.mcap", " (Input/output error)"),
          ("inject-carmen-log", ("inject", "{d}/c.log", "--fault", "slip@1:2", "--out", "{d}/o"), "c.log",
           " (Input/output error)"),
      )),
    Case("truth-json-unreadable", ("map", "{d}/run", "--config", "{cfg}", "--out", "{d}/o"),
         "truth.json: cannot read truth.json sidecar (Input/output error)",
         copy_run(lambda r: (r / "truth.json").unlink() or (r / "truth.json").symlink_to("/proc/self/mem"))),
    *(Case(f"carmen-{name}", CARMEN, says, carmen(encoding=lambda s, old=old, new=new: s.replace(old, new, 1).encode()))
      for name, old, new, says in (
          ("stamp-inf", " 1000.000000 host 1000.000000", " inf host inf", "c.log:1: expected finite numbers in FLASER"),
          ("odometry-theta-inf", "ODOM 0.000 0 0", "ODOM 0.000 0 inf", "c.log:2: expected finite numbers in ODOM"),
          # fields the reader does not use are a corrupt line all the same, and the error names the field
          ("odometry-velocity-nan", "ODOM 0.000 0 0 0 0 0", "ODOM 0.000 0 0 nan 0 0",
           "c.log:2: expected finite numbers in ODOM x y theta tv rv accel ts host logger_ts; tv is nan"),
          ("odometry-rotation-rate-inf", "ODOM 0.100 0 0 0 0 0", "ODOM 0.100 0 0 0 -inf 0", "c.log:3: expected finite "
           "numbers in ODOM x y theta tv rv accel ts host logger_ts; rv is -inf"),
          ("odometry-stamp-nan", "0 0 0 1000.250000 host", "0 0 0 NaN host", "c.log:3: expected finite numbers in ODOM "
           "x y theta tv rv accel ts host logger_ts; ts is NaN"),
          ("range-nan-named", "FLASER 181 ", "FLASER 181 nan ", "c.log:1: expected finite numbers in FLASER n r_1..r_n x "
           "y theta odom_x odom_y odom_theta ts host logger_ts; r_1 is nan"),
      )),
    Case("carmen-robotlaser-accuracy-nan", CARMEN, "c.log:1: expected finite numbers in ROBOTLASER1 type start fov "
         "resolution max_range accuracy mode n r_1..r_n m rem_1..rem_m poses ... ts; accuracy is nan",
         carmen(robotlaser=(-1.57, 3.14, 0.0174), encoding=lambda s: s.replace(" 50 0.01 0 181", " 50 nan 0 181").encode())),
    Case("librsf-variance-inf", LIBRSF, "X_Input.txt:6: expected odom2 t vx vy wz var_vx var_vy var_wz",
         text("X_Input.txt", "".join(f"odom2 {0.1 * k:.1f} 0.5 0 0.01 {'inf' if k == 5 else '0.01'} 0.01 0.01\n"
                                     for k in range(50)))),
    *(Case(f"bag-{name}", argv, says, bag(each(topic, change)))
      for name, argv, topic, change, says in (
          ("odometry-position-nan", BAG, "/odom", lambda t, m: setattr(m.pose.pose.position, "x", math.nan),
           "odometry topic '/odom': non-finite pose.position at message 0"),
          ("gyro-rate-nan", BAG, "/imu/data", lambda t, m: setattr(m.angular_velocity, "z", math.nan),
           "gyro topic '/imu/data': non-finite angular_velocity.z at message 0"),
          ("magnetic-field-nan", MAG_BAG, "/imu/mag", lambda t, m: setattr(m.magnetic_field, "x", math.nan),
           "compass topic '/imu/mag': non-finite magnetic_field at message 0"),
      )),
    Case("truth-fault-ends-at-1e400", ("map", "{d}/run", "--config", "{cfg}", "--out", "{d}/o"),
         "truth.json: faults.GPS.0.1: Input should be a finite number", copy_run(lambda r: (r / "truth.json").write_text(
             json.dumps({**json.loads((r / "truth.json").read_text()), "faults": {"GPS": [[1, "end"]]}}).replace('"end"', "1e400")))),
    *(Case(f"{name}-a-folder", argv, says, text(f"{file}/keep", ""))
      for name, argv, file, says in (
          ("librsf-log", LIBRSF, "X_Input.txt", "X_Input.txt: expected exactly one *_Input.txt in the folder, found none"),
          ("carmen-log", CARMEN, "c.log", "c.log: expected a CARMEN log file, got a directory"),
      )),
    Case("model-a-folder", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"),
         "m.yaml: cannot read YAML file (a folder; expected a file)",
         both(text("m.yaml/keep", ""), config(lambda t: t["validation"].update(model="m.yaml")))),
    Case("truth-json-a-folder", ("map", "{d}/run", "--config", "{cfg}", "--out", "{d}/o"),
         "truth.json: cannot read truth.json sidecar (a folder; expected a file)",
         copy_run(lambda r: (r / "truth.json").unlink() or (r / "truth.json").mkdir())),
    *(Case(f"set-{name}", (*MAP, "--out", "{d}/o", "--set", expr), f"--set {shown}: {says}")
      for name, expr, shown, says in (
          ("double-equals", "backend.optimizer==isam2", "backend.optimizer==isam2", "backend.optimizer: Input should be"),
          ("a-section-to-a-number", "backend=3", "backend=3", "backend: Input should be a valid dictionary"),
          ("a-section-to-null", "backend.factors=null", "backend.factors=null", "backend.factors: Input should be"),
          ("a-python-tag", "backend.optimizer=!!python/name:os.system", "backend.optimizer=!!python/name:os.system",
           "could not determine a constructor"),
          ("a-newline-in-the-key", "backend\n.optimizer=isam2", "backend .optimizer=isam2", "unknown config key 'backend '"),
      )),
    *(Case(f"carmen-gz-{name}", ("map", "{d}/c.log.gz", "--config", str(CONFIGS / "datasets" / "carmen.yaml"), "--out", "{d}/o"),
           f"c.log.gz: {says}", data("c.log.gz", gzip.compress(content)))
      for name, content, says in (
          ("of-nothing", b"", "no FLASER or ROBOTLASER1 scans"),
          ("of-binary", bytes(range(256)) * 20, "cannot read: not a CARMEN text log (binary content)"),
      )),
    *(Case(f"marker-{name}", (*MAP, *QUICK, "--out", "{d}/m"), says, make)
      for name, make, says in (
          ("input-nan", text("m/.gslam-result.json", '{"command": "map", "files": [], "input": NaN}'), "its input nan is not a path"),
          ("binary", data("m/.gslam-result.json", bytes(range(256))), "is not one gslam wrote"),
          ("a-named-pipe", fifo("m/.gslam-result.json"), "is not one gslam wrote"),
      )),
    Case("map-input-path-with-a-newline-missing", ("map", "{d}/x\ny.log", "--config", "{cfg}", "--out", "{d}/o"),
         "x y.log: no such file"),
    Case("inject-fault-times-in-hex", ("inject", "{run}", "--fault", "gyro_bias@0x2:0x4", "--out", "{d}/o"),
         "--fault gyro_bias@0x2:0x4: start_s: Input should be a valid number"),
    Case("simulate-seed-1.5", ("simulate", "{scen}", "--seed", "1.5", "--out", "{d}/o"),
         "argument --seed: expected a whole number, got '1.5'", code=2),
    # -- a key given twice in a JSON file read as input: json keeps the last in silence, as YAML here does not --
    Case("truth-json-fault-component-twice", ("map", "{d}/run", "--config", "{cfg}", *QUICK, "--out", "{d}/o"),
         "truth.json: key 'GPS' given twice in one JSON object", copy_run(lambda r: (r / "truth.json").write_text(
             json.dumps({**json.loads((r / "truth.json").read_text()), "faults": {"GPS": "first"}})
             .replace('"GPS": "first"', '"GPS": [[1, 2]], "GPS": []')))),
    Case("marker-files-twice", (*MAP, *QUICK, "--out", "{d}/m"), "its .gslam-result.json is not one gslam wrote",
         text("m/.gslam-result.json", '{"command": "map", "files": ["../x"], "files": ["metrics.json"]}')),
    Case("ablate-resumed-metrics-key-twice", ("ablate", "{spec}", "--out", "{d}/o"),
         "metrics.json: expected the JSON object gslam writes, found invalid JSON (key 'ate_rmse_m' given twice",
         finished_sweep('{"ate_rmse_m": 0.1, "ate_rmse_m": 1e9}')),
    # -- the sixth attack: a key given twice inside what a merge key (<<) brings, which PyYAML flattens unseen --
    Case("config-merge-brings-a-key-twice", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"),
         "c.yaml: line 3: key 'sigma_yaw_deg' given twice (earlier on the same line)",
         text("c.yaml", "backend:\n  factors:\n    compass: {<<: {sigma_yaw_deg: 300, sigma_yaw_deg: 3}}\n")),
    Case("config-merge-list-brings-a-key-twice", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"),
         "c.yaml: line 4: key 'distance_m' given twice (first on line 3)",
         text("c.yaml", "keyframes:\n  <<: [{period_s: 0.5},\n        {distance_m: 0.2,\n         distance_m: 20}]\n")),
    Case("scenario-merge-brings-a-key-twice", ("simulate", "{d}/s.yaml", "--out", "{d}/o"),
         "s.yaml: line 2: key 'max_speed_m_s' given twice",
         lambda d, w: (d / "s.yaml").write_text("robot:\n  <<: {max_speed_m_s: 0.4, max_speed_m_s: 40}\n"
                                                + w.scenario.read_text().replace("robot:\n", "", 1))),
    Case("variants-merge-brings-a-key-twice", ("compare", "{run}", "--config", "{cfg}", "--variants", "{d}/v.yaml",
                                               "--out", "{d}/o"), "v.yaml: line 1: key 'validation.mode' given twice",
         text("v.yaml", "a: {<<: {validation.mode: 'off', validation.mode: 'on'}}\n")),
    Case("set-merge-brings-a-key-twice", (*MAP, "--out", "{d}/o", "--set",
                                          "backend.factors.compass={{<<: {{sigma_yaw_deg: 300, sigma_yaw_deg: 3}}}}"),
         "key 'sigma_yaw_deg' given twice"),
    Case("config-merges-itself", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"),
         "c.yaml: line 2: invalid YAML (a mapping merges itself (<<: an alias of its own anchor))",
         text("c.yaml", "backend: &b\n  <<: *b\n")),
    # -- values one step (ulp) past a bound: the message shows the value, not the bound it passes --
    *(Case(f"set-{key}-one-ulp-past-its-bound", (*MAP, *extra, "--out", "{d}/o", "--set", f"{key}={value!r}"), says)
      for key, extra, value, says in (
          ("keyframes.period_s", (), float(np.nextafter(1e-4, 0)),
           "keyframes.period_s: 9.999999999999999e-05 s is below 0.0001 s"),
          ("output.map_voxel_m", (), float(np.nextafter(100.0, 200)), "output.map_voxel_m: 100.00000000000001 m is above 100 m"),
          ("gating.inflation", ("--gating", "on"), float(np.nextafter(1e3, 2e3)),
           "inflation: 1000.0000000000001 is above 1000"),
          ("backend.factors.odometry.sigma_xy_m", (), float(np.nextafter(1e-4, 0)),
           "sigma_xy_m: 9.999999999999999e-05 m is below 0.0001 m"),
      )),
    Case("relation-k-sigma-one-ulp-below-its-bound", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"),
         "relations.5.k_sigma: 0.49999999999999994 sigmas is below 0.5 sigmas",
         config(relation(5, k_sigma=float(np.nextafter(0.5, 0))))),
    Case("scenario-leg-speed-one-ulp-past-its-bound", ("simulate", "{d}/s.yaml", "--out", "{d}/o"),
         "leg speed (fourth value) 50.00000000000001 m/s is above 50 m/s",
         scenario(lambda t: t["robot"]["waypoints"].__setitem__(1, [1.0, 1.2, 0.0, float(np.nextafter(50.0, 100))]))),
    Case("librsf-speed-one-ulp-past-its-bound", LIBRSF, "odom2 line #3: speed 100.00000000000001 m/s",
         text("X_Input.txt", "".join(f"odom2 {0.1 * k:.1f} {'100.00000000000001' if k == 2 else '0.5'} 0 0 0.01 0.01 0.01\n"
                                     for k in range(50)))),
    # -- a ROS 2 bag whose metadata.yaml lists files that are not its own --
    *(Case(f"bag-metadata-{name}", argv, f"metadata.yaml: relative_file_paths lists {says}", copy_run(_listing(change)))
      for name, argv, change, says in (
          ("lists-a-file-up", ("map", "{d}/run", "--config", "{cfg}", "--out", "{d}/o"), lambda b: ["../truth.json"],
           "'../truth.json', which is not the name of a file in the bag's folder"),
          ("lists-an-absolute-path", ("map", "{d}/run", "--config", "{cfg}", "--out", "{d}/o"), lambda b: ["/etc/passwd"],
           "'/etc/passwd', which is not the name of a file in the bag's folder"),
          ("lists-another-recording", ("map", "{d}/run", "--config", "{cfg}", "--out", "{d}/o"),
           lambda b: shutil.copy(b / "bag.db3", b.parent / "other.db3") and ["../other.db3"], "'../other.db3', which is not"),
          ("lists-a-missing-file", ("map", "{d}/run", "--config", "{cfg}", "--out", "{d}/o"), lambda b: ["bag.db3", "bag_1.db3"],
           "'bag_1.db3', which is no file in"),
          ("lists-a-folder", ("map", "{d}/run", "--config", "{cfg}", "--out", "{d}/o"),
           lambda b: (b / "sub").mkdir() or ["sub"], "'sub', which is no file in"),
          ("inspect-lists-a-file-up", ("inspect", "{d}/run"), lambda b: ["../scenario.yaml"], "'../scenario.yaml', which is not"),
          ("inject-lists-another-recording", ("inject", "{d}/run", "--fault", "gyro_bias@2:4", "--out", "{d}/o"),
           lambda b: shutil.copy(b / "bag.db3", b.parent / "other.db3") and ["../other.db3"], "'../other.db3', which is not"),
      )),
    # -- a result folder of gslam's given back as the recording ('run.mcap: scan topic not in the bag' before) --
    *(Case(f"{name}-of-a-{made}-result", argv if name == "inspect" else (*argv, "--out", "{d}/o"),
           f"r: a gslam {made} result (its output), not a recording; give the recording it was made from, ",
           earlier_result(made))
      for name, argv, made in (
          ("map", ("map", "{d}/r", "--config", "{cfg}"), "map"),
          ("compare", ("compare", "{d}/r", "--config", "{cfg}", "--only", "ungated"), "compare"),
          ("calibrate", ("calibrate", "{d}/r", "--config", "{cfg}"), "map"),
          ("inject", ("inject", "{d}/r", "--fault", "gyro_bias@2:4"), "map"),
          ("inspect", ("inspect", "{d}/r"), "map"),
          ("map", ("map", "{d}/r", "--config", "{cfg}"), "compare"),
      )),
    # -- an input echoed back in the error line: a 1 MB key was a 1 MB line; a long word keeps its start and end --
    Case("config-unknown-key-of-a-megabyte", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"),
         "c.yaml: unknown config key 'kkkkk", text("c.yaml", "? " + "k" * 1_000_000 + "\n: 1\n")),
    Case("set-value-of-100-kb", (*MAP, "--out", "{d}/o", "--set", "backend.optimizer=" + "i" * 100_000),
         "...(100,019 characters)...iiii"),
    Case("variant-name-of-a-megabyte", ("compare", "{run}", "--config", "{cfg}", "--variants", "{d}/v.yaml", "--out", "{d}/o"),
         "v.yaml: variant 'vvv", text("v.yaml", "? " + "v" * 1_000_000 + "\n: {validation.mode: 'off'}\n")),
    Case("compare-only-of-100-kb", ("compare", "{run}", "--config", "{cfg}", "--only", "x" * 100_000, "--out", "{d}/o"),
         "unknown variant 'xxx"),
    # -- control characters reach the terminal as escapes, and a key with brackets is named, not its section --
    Case("config-unknown-key-with-terminal-escapes", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"),
         "c.yaml: unknown config key '\\x1b]0;pwned\\x07\\x1b[2Jboom'", text("c.yaml", '"\\e]0;pwned\\a\\e[2Jboom": 1\n')),
    Case("map-input-path-with-a-terminal-escape", ("map", "{d}/x\x1b[31mred", "--config", "{cfg}", "--out", "{d}/o"),
         "x\\x1b[31mred: no such file or directory"),
    Case("config-unknown-key-with-brackets", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"),
         "c.yaml: unknown config key 'keyframes.period[s]'; did you mean 'period_s'?",
         text("c.yaml", "keyframes:\n  period[s]: 0.5\n")),
    Case("set-unknown-key-with-brackets", (*MAP, "--out", "{d}/o", "--set", "backend.x[2]=1"),
         "--set backend.x[2]=1: unknown config key 'backend.x[2]'"),
    # -- an output name longer than a file system takes, under a folder still to be made: refused before the work --
    *(Case(f"{command}-out-name-of-300-bytes-in-a-new-folder", (*argv, "{d}/new/" + "o" * 300 + suffix),
           f"{flag} has a name of {300 + len(suffix)} bytes (oooo", text("mine.txt", "mine\n"))
      for command, argv, flag, suffix in (
          ("map", (*MAP, *QUICK, "--out"), "--out", ""),
          ("simulate", ("simulate", "{scen}", "--out"), "--out", ""),
          ("compare", ("compare", "{run}", "--config", "{cfg}", "--only", "ungated", *QUICK, "--out"), "--out", ""),
          ("calibrate", ("calibrate", "{run}", "--config", "{cfg}", "--out"), "--out", ".yaml"),
          ("inspect", ("inspect", "{run}", "--config-out"), "--config-out", ".yaml"),
      )),
    # -- a bag's metadata.yaml as hostile YAML: rosbags reads it, one line each (passed before; kept so none turns
    # -- into a traceback or a run of another file)
    *(Case(f"bag-metadata-{name}", ("map", "{d}/run", "--config", "{cfg}", "--out", "{d}/o"), says,
           copy_run(lambda r, change=change: (r / "bag" / "metadata.yaml").write_text(
               change((r / "bag" / "metadata.yaml").read_text()))))
      for name, change, says in (
          ("key-twice", lambda m: m.replace("  storage_identifier: sqlite3\n",
                                            "  storage_identifier: sqlite3\n  storage_identifier: mcap\n"),
           "metadata.yaml: while constructing a mapping"),
          ("python-tag", lambda m: m + "z: !!python/object/apply:os.system ['true']\n",
           "could not determine a constructor for the tag 'tag:yaml.org,2002:python/object/apply:os.system'"),
      )),
    # -- a recorder killed before it wrote the MCAP index, a copy cut short --
    *(Case(f"mcap-truncated-{name}", (*argv, "{d}/" + ("m.mcap" if bare else "m"), *rest),
           ("m.mcap" if bare else "m") + ": not a readable ROS bag (the MCAP file ends early, a recording or a copy "
           "cut short: File end magic is invalid.)",
           truncated_mcap(fraction, bare))
      for name, argv, rest, fraction, bare in (
          ("map-at-a-third", ("map",), ("--config", "{cfg}", "--out", "{d}/o"), 0.3, False),
          ("map-at-the-end", ("map",), ("--config", "{cfg}", "--out", "{d}/o"), 0.98, False),
          ("inspect-bare-file", ("inspect",), (), 0.5, True),
          ("inject-bare-file", ("inject",), ("--fault", "gyro_bias@1:2", "--out", "{d}/o"), 0.5, True),
      )),
    *(Case(f"ros1-bag-truncated-{name}", (*argv, "{d}/r.bag", *rest),
           "r.bag: not a readable ROS bag (the bag's index is cut off or damaged, a recording or a copy cut short: "
           "'rosbag reindex' it and read it again: Bag index looks damaged",
           truncated_ros1(fraction))
      for name, argv, rest, fraction in (
          ("map-at-a-third", ("map",), ("--config", "{cfg}", "--out", "{d}/o"), 0.3),
          ("inspect-at-the-end", ("inspect",), (), 0.98),
      )),
    Case("inject-fault-parameter-of-100-kb", ("inject", "{run}", "--fault", "gyro_bias@2:4," + "b" * 100_000 + "=1", "--out",
                                              "{d}/o"), "unknown parameter 'bbb"),
    # -- the seventh attack: lines with more values than their counts say, read shifted in silence before --
    *(Case(f"carmen-{name}", CARMEN, f"c.log:1: expected {says}", make)
      for name, make, says in (
          ("flaser-beam-count-two-short", carmen(encoding=lambda s: s.replace("FLASER 181 ", "FLASER 179 ").encode()),
           "FLASER n r_1..r_n x y theta odom_x odom_y odom_theta ts host logger_ts (190 fields, got 192); more values "
           "than n says"),
          ("flaser-a-field-after-logger-ts", carmen(encoding=lambda s: s.replace("\nODOM", " 7\nODOM").encode()),
           "FLASER n r_1..r_n x y theta odom_x odom_y odom_theta ts host logger_ts (192 fields, got 193)"),
          ("robotlaser-a-field-after-logger-ts", carmen(robotlaser=(-1.57, 3.14, 0.0174),
                                                       encoding=lambda s: s.replace("\nODOM", " 7\nODOM").encode()),
           "ROBOTLASER1 type start fov resolution max_range accuracy mode n r_1..r_n m rem_1..rem_m poses ... ts "
           "(205 fields, got 206); more values than n or m says"),
      )),
    *(Case(f"librsf-{name}", LIBRSF, says, make)
      for name, make, says in (
          ("odom2-two-columns-more", text("X_Input.txt", "".join(f"odom2 {0.1 * k:.1f} 0.5 0 0 0.01 0.01 0.01 7 8\n"
                                                                 for k in range(50))),
           "X_Input.txt:1: expected odom2 t vx vy wz var_vx var_vy var_wz (7 values, got 9)"),
          ("loop-a-column-more", librsf_with("loop 9.0 1.0 1 0.5"), "X_Input.txt:101: expected loop t t_other weight (3 "
                                                                    "values, got 4)"),
          ("ground-truth-a-column-more", librsf_with("loop 9.0 1.0 1", "".join(
              f"point2 {0.1 * k:.1f} {0.05 * k} 0 0.1 0 0 0.1 9\n" for k in range(100))),
           "X_GT.txt:1: expected point2 t x y c_xx c_xy c_yx c_yy (7 values, got 8)"),
      )),
    # -- one key given twice on the command line: the later won in silence --
    *(Case(f"set-{name}", (*MAP, "--out", "{d}/o", *extra), says)
      for name, extra, says in (
          ("key-twice", ("--set", "keyframes.period_s=0.5", "--set", "keyframes.period_s=0.7"),
           "--set keyframes.period_s=0.7: key 'keyframes.period_s' given twice (first set by --set keyframes.period_s=0.5)"),
          ("section-after-a-key-inside-it", ("--set", "keyframes.distance_m=0.3", "--set", "keyframes={{period_s: 0.5}}"),
           "--set keyframes={period_s: 0.5}: sets the whole section 'keyframes', replacing 'keyframes.distance_m' (first "
           "set by --set keyframes.distance_m=0.3)"),
          ("key-inside-a-section-given-before", ("--set", "keyframes={{period_s: 0.5}}", "--set", "keyframes.period_s=0.7"),
           "--set keyframes.period_s=0.7: key 'keyframes.period_s' given twice (first set by --set keyframes={period_s: 0.5})"),
          ("mode-and-gating", ("--set", "validation.mode=off", "--gating", "on"),
           "--gating on: key 'validation.mode' given twice (first set by --set validation.mode=off)"),
      )),
    Case("calibrate-set-key-twice", (*CAL, "--set", "keyframes.period_s=0.5", "--set", "keyframes.period_s=0.7", "--out",
                                     "{d}/c.yaml"), "--set keyframes.period_s=0.7: key 'keyframes.period_s' given twice"),
    Case("compare-variant-and-set-one-key", ("compare", "{run}", "--config", "{cfg}", "--variants", "{d}/v.yaml", "--set",
                                             "validation.mode=on", "--out", "{d}/o"),
         "v.yaml: variant 'a': validation.mode=off: key 'validation.mode' given twice (first set by --set validation.mode=on)",
         text("v.yaml", "a: {validation.mode: 'off'}\n")),
    Case("compare-variant-key-and-its-section", ("compare", "{run}", "--config", "{cfg}", "--variants", "{d}/v.yaml", "--out",
                                                 "{d}/o"),
         "v.yaml: variant 'a': keyframes.period_s=0.7: key 'keyframes.period_s' given twice (first set by keyframes={period_s: "
         "0.5})", text("v.yaml", "a: {keyframes: {period_s: 0.5}, keyframes.period_s: 0.7}\n")),
    # -- a fault whose interval holds no sample of its stream: 'the input with the faults added', unchanged --
    Case("inject-multipath-into-a-run-without-a-fix", ("inject", "{run}", "--fault", "multipath@2:4", "--out", "{d}/o"),
         "no GPS fix with a position between 2 and 4 s, so the fault would change nothing"),
    Case("inject-laser-cut-between-two-scans", ("inject", "{d}/c.log", "--fault", "laser_cut@2.1:2.3", "--out", "{d}/o"),
         "no laser scan between 2.1 and 2.3 s, so the fault would change nothing", carmen()),
    Case("inject-gyro-bias-between-two-samples", ("inject", "{d}/t.mat", "--fault", "gyro_bias@0.101:0.105", "--out", "{d}/o"),
         "no gyro sample between 0.101 and 0.105 s", broad_mat()),
    # -- a NaN in a BROAD trial's IMU arrays: named by field, sample and axis, as stored --
    *(Case(f"broad-{name}", ("map", "{d}/t.mat", "--config", "{cfg}", "--out", "{d}/o"), f"t.mat: {says}", broad_mat(**fields))
      for name, fields, says in (
          ("one-gyro-sample-nan", {"imu_gyr": np.where(np.arange(150).reshape(50, 3) == 32, np.nan, 0.0)},
           "imu_gyr/imu_acc/imu_mag: expected finite samples; imu_gyr at sample 10 (t = 0.100 s) is nan on axis z (1 of "
           "50 samples not finite)"),
          ("magnetometer-nan-from-sample-5", {"imu_mag": np.where(np.arange(50)[:, None] >= 5, np.nan, [[0.0, 20.0, -40.0]])},
           "imu_gyr/imu_acc/imu_mag: expected finite samples; imu_mag at sample 5 (t = 0.050 s) is nan on axis x (45 of "
           "50 samples not finite)"),
      )),
    # -- kinds each reader and command already answers in one line, kept so that none turns into a traceback --
    *(Case(f"config-yaml-{name}", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"), f"c.yaml: {says}", text("c.yaml", content))
      for name, content, says in (
          ("custom-tag", "keyframes: {period_s: !custom 0.5}\n", "line 1: invalid YAML (could not determine a constructor "
                                                                  "for the tag '!custom')"),
          ("set-for-a-section", "keyframes: !!set {period_s}\n", "keyframes: Input should be a valid dictionary"),
          ("binary-for-a-number", "keyframes: {period_s: !!binary aGVsbG8=}\n", "keyframes.period_s: Input should be a "
                                                                                "valid number"),
          ("null-key", "~: 1\n", "None: Keys should be strings"),
          ("list-key", "? [a, b]\n: 1\n", "line 1: invalid YAML (found unhashable key)"),
          ("sexagesimal-period", "keyframes: {period_s: 0:30}\n", "keyframes.period_s: Input should be a valid number"),
      )),
    *(Case(f"set-{name}", (*MAP, "--out", "{d}/o", "--set", expr), f"--set {expr}: {says}")
      for name, expr, says in (
          ("empty-value-for-a-choice", "backend.optimizer=", "backend.optimizer: Input should be 'batch'"),
          ("list-for-a-number", "keyframes.period_s=[1,2]", "keyframes.period_s: Input should be a valid number"),
          ("alias-for-a-number", "keyframes.period_s=*a", "keyframes.period_s: Input should be a valid number"),
          ("through-a-list", "validation.observers.relations.0.k_sigma=3", "'validation.observers.relations' is a value"),
      )),
    *(Case(f"inject-{name}", ("inject", "{run}", "--fault", fault, "--out", "{d}/o"), f"--fault {fault}: {says}")
      for name, fault, says in (
          ("before-the-start", "gyro_bias@-5:2", "start_s: -5 s is below 0 s: a fault's times count from the recording's start"),
          ("of-no-length", "gyro_bias@2:2", "the interval 2:2 must end after it starts"),
          ("param-without-value", "gyro_bias@2:4,bias_deg_s", "expected param=value, got 'bias_deg_s'"),
          ("without-a-kind", "@1:2", "unknown fault kind ''"),
          ("infinite", "gyro_bias@inf:inf", "start_s: Input should be a finite number"),
          ("three-times", "gyro_bias@2:4:6", "end_s: Input should be a valid number"),
          ("dipole-side-up", "dipole@2:4,side=up", "side: Input should be 'left' or 'right'"),
      )),
    Case("carmen-beam-count-changes", CARMEN, "c.log:4: expected 181 beams at the same angles as the first scan",
         carmen(encoding=_second_scan_a_beam_short)),
    *(Case(f"librsf-{name}", LIBRSF, says, text("X_Input.txt", content))
      for name, content, says in (
          ("stamp-twice", "".join(f"odom2 {0.1 * (k - (k == 11)):.1f} 0.5 0 0 0.01 0.01 0.01\n" for k in range(50)),
           "odom2 line #12: expected increasing times, got 1.0 after 1.0"),
          ("loop-without-weight", "".join(f"odom2 {0.1 * k:.1f} 0.5 0 0 0.01 0.01 0.01\n" for k in range(50))
           + "loop 4.0 1.0\n", "X_Input.txt:51: expected loop t t_other weight"),
      )),
    *(Case(f"broad-{name}", ("map", "{d}/t.mat", "--config", "{cfg}", "--out", "{d}/o"), f"t.mat: {says}", make)
      for name, make, says in (
          ("one-sample", broad_mat(**{k: v[:1] for k, v in {
              "imu_gyr": np.zeros((50, 3)), "imu_acc": np.tile([0, 0, 9.81], (50, 1)), "imu_mag": np.tile([0, 20, -40], (50, 1)),
              "opt_quat": np.tile([1, 0, 0, 0], (50, 1)), "opt_pos": np.zeros((50, 3)),
              "movement": np.ones((50, 1), dtype=np.uint8)}.items()}), "no samples"),
          ("acceleration-transposed", broad_mat(imu_acc=np.tile([0, 0, 9.81], (50, 1)).T),
           "imu_acc: expected shape (50, 3), got (3, 50)"),
      )),
    Case("compare-variants-file-empty", ("compare", "{run}", "--config", "{cfg}", "--variants", "{d}/v.yaml", "--out", "{d}/o"),
         "v.yaml: no variants", text("v.yaml", "")),
    # -- the eighth attack: a YAML truth value inside a list of numbers, read as 1 or 0 in silence before --
    *(Case(f"scenario-{name}", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), f"s.yaml: {says}", scenario(change))
      for name, change, says in (
          ("waypoint-coordinate-true", lambda t: t["robot"]["waypoints"].__setitem__(1, [1.0, True]),
           "robot: waypoints.1.1: expected a number, not true"),
          ("waypoint-pause-true", lambda t: t["robot"]["waypoints"].__setitem__(1, [1.0, 1.2, True]),
           "robot: waypoints.1.2: expected a number, not true"),
          ("wall-corner-true", lambda t: t["world"]["walls"].append([[0.0, True], [1.0, 1.0]]),
           "world: walls.7.0.1: expected a number, not true"),
          ("steel-position-false", lambda t: t["world"]["disturbers"][0].update(position=[False, 1.0, 0.0]),
           "world.disturbers.0: position.0: expected a number, not false"),
      )),
    Case("ablate-seed-true", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"),
         "spec.yaml: inputs.scenarios.0: seeds.0: expected a number, not true",
         lambda d, w: spec_in(d, w, inputs={"scenarios": [{"path": str(w.scenario), "seeds": [True]}]})),
    Case("ablate-integer-distribution-true", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"),
         "sweep.random.params.submaps.search_depth: integer.0: expected a number, not true",
         spec(sweep={"random": {"samples": 1, "params": {"submaps.search_depth": {"integer": [True, 5]}}}})),
    # -- a NaN beam angle: 'beam angles change at message 1' before, of a bag whose every angle is NaN --
    Case("bag-angle-increment-nan", BAG, "scan topic '/scan': non-finite angle_min/angle_increment at message 0",
         bag(each("/scan", lambda t, m: setattr(m, "angle_increment", math.nan)))),
    Case("bag-angle-min-nan-from-message-5", BAG, "scan topic '/scan': non-finite angle_min/angle_increment at message 5",
         bag(from_message("/scan", 5, lambda m: setattr(m, "angle_min", math.nan)))),
    # -- a NaN range limit: 'the laser returns nothing (its range limits are [0.1, nan] m)' before, a warning --
    *(Case(f"bag-{name}", BAG, f"scan topic '/scan': non-finite range_min/range_max at message {says}", bag(change))
      for name, change, says in (
          ("range-max-nan", each("/scan", lambda t, m: setattr(m, "range_max", math.nan)), "0 (0.1, nan)"),
          ("range-min-nan-from-message-3", from_message("/scan", 3, lambda m: setattr(m, "range_min", math.nan)), "3 (nan,"),
          ("range-max-minus-inf", each("/scan", lambda t, m: setattr(m, "range_max", -math.inf)), "0 (0.1, -inf)"),
      )),
    # -- inspect lists a bag's topics without reading their messages (docs/cli.md); its starter reads them as map does --
    *(Case(f"inspect-config-out-bag-{name}", ("inspect", "{d}/b", "--config-out", "{d}/s.yaml"), f"b: {says}", bag(change))
      for name, change, says in (
          ("angle-increment-nan", each("/scan", lambda t, m: setattr(m, "angle_increment", math.nan)),
           "scan topic '/scan': non-finite angle_min/angle_increment at message 0"),
          ("scans-without-beams", each("/scan", lambda t, m: setattr(m, "ranges", m.ranges[:0].copy())),
           "laser scans have no beams"),
      )),
    # -- keys holding characters that look like others or like none: shown as the key they seemed to be --
    *(Case(f"config-key-{name}", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"), f"c.yaml: unknown config key {says}",
           text("c.yaml", content))
      for name, content, says in (
          ("with-a-zero-width-space", "keyframes: {period_s\u200b: 0.5}\n", "'keyframes.period_s\\u200b'; did you mean "
           "'period_s'? (its '\\u200b' is U+200B ZERO WIDTH SPACE; keys are ASCII)"),
          ("with-a-right-to-left-override", "keyframes: {\u202eperiod_s: 0.5}\n",
           "'keyframes.\\u202eperiod_s'; did you mean 'period_s'? (its '\\u202e' is U+202E RIGHT-TO-LEFT OVERRIDE"),
          ("indented-with-a-no-break-space", "keyframes:\n\u00a0 period_s: 0.5\n",
           "'\\xa0 period_s' (its '\\xa0' is U+00A0 NO-BREAK SPACE; keys are ASCII)"),
          ("with-a-cyrillic-letter", "keyframes: {period_\u0455: 0.5}\n",
           "'keyframes.period_\u0455'; did you mean 'period_s'? (its '\u0455' is U+0455 CYRILLIC SMALL LETTER DZE"),
      )),
    Case("set-key-with-a-zero-width-space", (*MAP, "--out", "{d}/o", "--set", "keyframes.period_s\u200b=0.5"),
         "unknown config key 'keyframes.period_s\\u200b'; did you mean 'period_s'? (its '\\u200b' is U+200B"),
    Case("scenario-key-with-a-no-break-space", ("simulate", "{d}/s.yaml", "--out", "{d}/o"),
         "'robot.max_speed\\xa0m_s'", scenario(lambda t: t["robot"].update({"max_speed\u00a0m_s": 0.4}))),
    # -- names YAML reads as no text: compare wrote folders True, None and 1 --
    *(Case(f"compare-variant-named-{name}", ("compare", "{run}", "--config", "{cfg}", "--variants", "{d}/v.yaml", "--out",
                                             "{d}/o"), f"v.yaml: variant name {says}", text("v.yaml", f"{key}: {{}}\n"))
      for name, key, says in (
          ("yes", "yes", "true: YAML reads it as a truth value (as it reads yes, no, on, off, true and false unquoted)"),
          ("a-tilde", "~", "null: YAML reads it as null (as it reads ~, null and an empty key), not as a name; quote it"),
          ("a-number", "1", "1: YAML reads it as a number, not as a name; quote it"),
      )),
    # -- an ablation's variant names: a newline split summary.md's table row in two, a NUL was written into it --
    *(Case(f"ablate-variant-named-{name}", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), f"spec.yaml: variants: name {says}",
           spec_text(f"variants: {{{key}: {{validation.mode: 'off'}}}}\n"))
      for name, key, says in (
          ("no", "no", "false: YAML reads it as a truth value"),
          ("with-a-newline", '"a\\nb"', "'a\\nb': a variant's name names its jobs: ASCII letters and digits"),
          ("with-a-nul", '"a\\0b"', "'a\\x00b': a variant's name names its jobs"),
      )),
    # -- the ninth attack: a sweep's title and a recorded input's name with control characters, written into
    # -- summary.md's title and report.html as they were --
    *(Case(f"ablate-{name}", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), f"spec.yaml: {says}", spec(**{key: value}))
      for name, key, value, says in (
          ("name-with-a-newline", "name", "two\nlines", "name: holds the control character '\\n' at character 4; "
           "expected a title of one line"),
          ("name-with-a-nul", "name", "a\0b", "name: holds the control character '\\x00'"),
          ("name-with-a-terminal-escape", "name", "\x1b]0;pwned\x07", "name: holds the control character '\\x1b' at "
           "character 1"),
          ("description-with-a-nul", "description", "one\ntwo\0", "description: holds the control character '\\x00' at "
           "character 8; expected text of lines and tabs"),
      )),
    Case("ablate-recorded-input-named-with-a-newline", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"),
         "spec.yaml: inputs.recorded.0.name: 'a\\nb': a recorded input's name names its jobs: ASCII letters",
         both(carmen(), lambda d, w: (d / "spec.yaml").write_text(
             f"name: x\nconfig: {CONFIGS / 'datasets' / 'carmen.yaml'}\n"
             f"inputs: {{recorded: [{{path: {d / 'c.log'}, name: \"a\\nb\"}}]}}\n"))),
    # -- one fault given twice: the two were added, 4 deg/s of gyro bias for the 2 asked for --
    *(Case(f"inject-{name}", ("inject", "{run}", "--fault", first, "--fault", second, "--out", "{d}/o"),
           "--fault gyro_bias@2:4,bias_deg_s=2.0,label_deg_s=0.57 given twice; each --fault is added on top of the others")
      for name, first, second in (
          ("fault-given-twice", "gyro_bias@2:4", "gyro_bias@2:4"),
          ("fault-given-twice-once-with-its-default-spelled-out", "gyro_bias@2:4", "gyro_bias@2.0:4,bias_deg_s=2"),
      )),
    # -- a sweep value given twice on one axis: one job in silence, where seeds given twice are refused --
    *(Case(f"ablate-{name}", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), f"spec.yaml: {says}", make)
      for name, make, says in (
          ("grid-value-twice-as-int-and-float", spec(sweep={"grid": {"gating.inflation": [2, 2.0]}}),
           "sweep: grid.gating.inflation: 2 and 2.0 are one value, so two jobs would compute the same thing"),
          ("grid-value-twice-in-a-second-grid", spec(sweep={"grid": [{"gating.inflation": [2]},
                                                                     {"gating.inflation": [3, 2, 3]}]}),
           "sweep: grid.1.gating.inflation: 3 and 3 are one value"),
          ("input-sweep-value-twice", lambda d, w: spec_in(d, w, inputs={"scenarios": [{
              "path": str(w.scenario), "seeds": [1], "sweep": {"grid": {"validation.mode": ["off", "on", "off"]}}}]}),
           "inputs.scenarios.0.sweep: grid.validation.mode: 'off' and 'off' are one value"),
      )),
    # -- a value that starts with '-' (argparse took it for an option), '-' as an output (a folder named '-') --
    Case("calibrate-clean-from-a-negative-start", (*CAL[:-1], "-5:10", "--out", "{d}/c.yaml"),
         "argument --clean: expected one argument (a value that starts with '-' is read as an option: give it as "
         "--clean=VALUE)", code=2),
    Case("calibrate-clean-negative-start-as-told", (*CAL[:-2], "--clean=-5:10", "--out", "{d}/c.yaml"),
         "--clean -5:10: expected START:END in seconds from the run's start, END > START >= 0"),
    *(Case(f"{name}-out-a-dash", (*argv, flag, "-"), f"argument {flag}: '-' would be a file or folder named '-', not "
           "standard output", code=2)
      for name, argv, flag in (
          ("map", (*MAP, *QUICK), "--out"),
          ("simulate", ("simulate", "{scen}"), "--out"),
          ("ablate", ("ablate", "{spec}"), "--out"),
          ("calibrate", ("calibrate", "{run}", "--config", "{cfg}"), "--out"),
          ("inspect", ("inspect", "{run}"), "--config-out"),
      )),
    # -- a truth.json fault lasting past the data (scored as missed there), a variant named twice in --only --
    *(Case(f"truth-fault-{name}", ("map", "{d}/run", "--config", "{cfg}", *QUICK, "--out", "{d}/o"),
           f"truth.json: faults.IMU_YAW [{start:g}, {end:g}] s after t0 1700000000 reaches outside the recording "
           "(1700000000 s plus 24.0 s) by more than 10 s", copy_run(lambda r, start=start, end=end: (r / "truth.json").write_text(
               json.dumps({**json.loads((r / "truth.json").read_text()), "faults": {"IMU_YAW": [[start, end]]}}))))
      for name, start, end in (("ending-2000-s-after-the-start", 1.0, 2000.0), ("starting-30-s-before-the-start", -30.0, 5.0))),
    *(Case(f"{command}-only-a-variant-twice", (command, *argv, "--only", "ungated,gated,ungated", "--out", "{d}/o"),
           "argument --only: 'ungated' given twice in 'ungated,gated,ungated'; give each variant once", code=2)
      for command, argv in (("compare", ("{run}", "--config", "{cfg}")), ("demo", ()))),
    # -- kinds every command already answers in one line, kept so that none turns into a traceback or a hang --
    *(Case(f"{name}-alias-bomb", argv, "expands to more than 1,000,000 values (YAML aliases)", make)
      for name, argv, make in (
          ("scenario", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), text("s.yaml", YAML_BOMB)),
          ("spec", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), text("spec.yaml", YAML_BOMB)),
          ("variants", ("compare", "{run}", "--config", "{cfg}", "--variants", "{d}/v.yaml", "--out", "{d}/o"),
           text("v.yaml", YAML_BOMB)),
          ("model", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"),
           both(text("m.yaml", YAML_BOMB), text("c.yaml", "validation: {model: m.yaml}\n"))),
      )),
    *(Case(f"{name}-nested-5000-deep", argv, "line 1: invalid YAML (exceeded maximum nesting depth)", make)
      for name, argv, make in (
          ("scenario", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), text("s.yaml", "[" * 5000 + "]" * 5000)),
          ("spec", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), text("spec.yaml", "{a: " * 5000 + "1" + "}" * 5000)),
          ("variants", ("compare", "{run}", "--config", "{cfg}", "--variants", "{d}/v.yaml", "--out", "{d}/o"),
           text("v.yaml", "[" * 5000 + "]" * 5000)),
      )),
    Case("set-section-alias-bomb", (*MAP, "--out", "{d}/o", "--set", "keyframes={{" + YAML_BOMB.strip().replace("\n", ", ")
                                    .replace("{", "{{").replace("}", "}}") + "}}"), "unknown config key 'keyframes.a'"),
    *(Case(f"set-{name}-nan", (*MAP, "--out", "{d}/o", "--set", f"{key}={value}"), f"--set {key}={value}: {key}: expected a "
           f"finite number, got {value.lower()}")
      for name, key, value in (
          ("integer", "backend.max_iterations", ".nan"),
          ("switch", "output.plots", ".NaN"),
          ("choice", "backend.optimizer", "-.inf"),
      )),
    Case("variants-value-nan", ("compare", "{run}", "--config", "{cfg}", "--variants", "{d}/v.yaml", "--out", "{d}/o"),
         "v.yaml: variant 'a': keyframes.period_s=.nan: keyframes.period_s: expected a finite number, got .nan",
         text("v.yaml", "a: {keyframes.period_s: .nan}\n")),
    Case("ablate-set-nan", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), "--set keyframes.period_s=.nan: keyframes.period_s: "
         "expected a finite number", spec_text("set: {keyframes.period_s: .nan}\n")),
    Case("ablate-uniform-to-infinity", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"),
         "sweep.random.params.gating.inflation.uniform.1: Input should be a finite number",
         spec_text("sweep: {random: {samples: 2, params: {gating.inflation: {uniform: [1, .inf]}}}}\n")),
    Case("config-decimal-comma-in-a-flow-mapping", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"),
         "c.yaml: backend.5: Keys should be strings", text("c.yaml", "backend: {robust_param: 1,5}\n")),
    Case("config-fullwidth-digits", (*MAP[:2], "--config", "{d}/c.yaml", "--out", "{d}/o"),
         "keyframes.period_s: Input should be a valid number", text("c.yaml", "keyframes: {period_s: \uff10.\uff15}\n")),
    *(Case(f"bag-{name}", BAG, says, bag(change))
      for name, change, says in (
          ("scans-without-beams", each("/scan", lambda t, m: setattr(m, "ranges", m.ranges[:0].copy())),
           "laser scans have no beams"),
          ("scans-lose-their-beams-at-message-10", from_message("/scan", 10, lambda m: setattr(m, "ranges", m.ranges[:0].copy())),
           "scan topic '/scan': message 10 has 0 beams, the first had"),
          ("odometry-stamps-all-zero", each("/odom", lambda t, m: setattr(m.header, "stamp", type(m.header.stamp)(sec=0, nanosec=0))),
           "odometry topic '/odom': duplicate header stamp at message 1 (t = 0.000000000 s"),
      )),
    Case("carmen-nul-bytes-mid-file", CARMEN, "c.log: cannot read: not a CARMEN text log (binary content)",
         both(carmen(), _rewritten("c.log", lambda b: b.replace(b"\nODOM", b"\n\0\0ODOM", 1)))),
    Case("librsf-nul-bytes-mid-file", LIBRSF, "X_Input.txt: cannot read: not a libRSF text file (binary content)",
         both(librsf_with("loop 9.0 1.0 1"), _rewritten("X_Input.txt", lambda b: b.replace(b"\nodom2", b"\n\0odom2", 1)))),
    Case("carmen-unicode-minus", CARMEN, "c.log:3: expected ODOM x y theta tv rv accel ts host logger_ts",
         carmen(encoding=lambda s: s.replace("ODOM 0.100 0", "ODOM \u22120.100 0", 1).encode())),
    Case("carmen-a-line-of-30-million-values", CARMEN, "c.log:121: a line of over 1 MB; no CARMEN text log record is "
         "that long",
         both(carmen(), _rewritten("c.log", lambda b: b + b"FLASER 3 " + b"1 " * 30_000_000 + b"\n"))),
    Case("librsf-a-line-of-30-million-values", LIBRSF, "X_Input.txt:102: a line of over 1 MB; no libRSF text file "
         "record is that long",
         both(librsf_with("loop 9.0 1.0 1"), _rewritten("X_Input.txt", lambda b: b + b"odom2 " + b"1 " * 30_000_000 + b"\n"))),
    Case("map-input-a-dash", ("map", "-", "--config", "{cfg}", "--out", "{d}/o"), "-: no such file or directory"),
    Case("map-config-a-dash", ("map", "{run}", "--config", "-", "--out", "{d}/o"), "-: cannot read config (No such file"),
    Case("ablate-spec-config-a-folder", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), "cannot read config (a folder; expected "
         "a file)", both(text("cfg/keep", ""), lambda d, w: spec_in(d, w, config=str(d / "cfg")))),
    Case("ablate-spec-scenario-a-folder", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), "cannot read scenario (a folder; "
         "expected a file)", lambda d, w: spec_in(d, w, inputs={"scenarios": [{"path": str(d), "seeds": [1]}]})),
    *(Case(f"inject-{name}", ("inject", "{run}", "--fault", fault, "--out", "{d}/o"), f"--fault {fault}: {says}")
      for name, fault, says in (
          ("param-of-no-value", "gyro_bias@2:4,bias_deg_s=", "bias_deg_s: Input should be a valid number"),
          ("kind-in-capitals", "GYRO_BIAS@2:4", "unknown fault kind 'GYRO_BIAS'; expected one of"),
          ("param-value-true", "gyro_bias@2:4,bias_deg_s=true", "bias_deg_s: Input should be a valid number"),
      )),
    Case("calibrate-clean-three-times", (*CAL[:-1], "0:5:10", "--out", "{d}/c.yaml"), "--clean 0:5:10: expected START:END"),
    Case("calibrate-false-alarm-inf", ("calibrate", "{run}", "--config", "{cfg}", "--false-alarm", "inf", "--out",
                                       "{d}/c.yaml"), "--false-alarm inf: expected a share of steps"),
    # -- the tenth attack: numbers Python reads and C's strtod does not ('1_0' is 10 to one, 1 to the other; digits
    # -- of another script), read in silence before --
    *(Case(f"librsf-{name}", LIBRSF, says, both(librsf_with("loop 9.0 1.0 1"), _rewritten("X_Input.txt", change)))
      for name, change, says in (
          ("speed-with-an-underscore", lambda b: b.replace(b"odom2 1.0 0.5 ", b"odom2 1.0 0.5_0 "),
           "X_Input.txt:11: expected odom2 t vx vy wz var_vx var_vy var_wz; vx is '0.5_0', not a plain number"),
          ("time-in-arabic-indic-digits", lambda b: b.replace(b"odom2 1.0 ", "odom2 \u0661.\u0660 ".encode()),
           "X_Input.txt:11: expected odom2 t vx vy wz var_vx var_vy var_wz; t is '\u0661.\u0660', not a plain number"),
          ("loop-time-in-fullwidth-digits", lambda b: b.replace(b"loop 9.0", "loop \uff19.0".encode()),
           "X_Input.txt:101: expected loop t t_other weight; t is '\uff19.0', not a plain number"),
      )),
    *(Case(f"carmen-{name}", CARMEN, says, make)
      for name, make, says in (
          ("range-with-an-underscore", carmen(encoding=lambda s: s.replace(" 3 ", " 3_0 ", 1).encode()),
           "c.log:1: expected FLASER n r_1..r_n x y theta odom_x odom_y odom_theta ts host logger_ts; r_"),
          ("odometry-in-fullwidth-digits", carmen(encoding=lambda s: s.replace("ODOM 0.100 ", "ODOM \uff10.100 ", 1).encode()),
           "c.log:3: expected ODOM x y theta tv rv accel ts host logger_ts; x is '\uff10.100', not a plain number"),
          ("beam-count-with-an-underscore", carmen(encoding=lambda s: s.replace("FLASER 181 ", "FLASER 1_81 ").encode()),
           "c.log:1: expected FLASER n r_1..r_n x y theta odom_x odom_y odom_theta ts host logger_ts; the beam count is "
           "'1_81', not a plain number"),
          ("param-fov-with-an-underscore", carmen(head="PARAM laser_front_laser_fov 1_80"),
           "c.log:2: expected a number in PARAM laser_front_laser_fov"),
      )),
    # -- the tenth attack's kinds already answered in one line, kept so that none regresses: a libRSF header of column
    # -- names, a number spelled as a word, a bag's metadata.yaml naming another storage or a compression not applied,
    # -- output paths through /proc and /sys --
    Case("librsf-header-of-column-names", LIBRSF, "X_Input.txt:1: expected odom2 t vx vy wz var_vx var_vy var_wz",
         both(librsf_with("loop 9.0 1.0 1"), _rewritten("X_Input.txt", lambda b: b"odom2 t vx vy wz var_vx var_vy var_wz\n" + b))),
    Case("librsf-speed-spelled-infinity", LIBRSF, "X_Input.txt:1: expected odom2 t vx vy wz var_vx var_vy var_wz",
         both(librsf_with("loop 9.0 1.0 1"), _rewritten("X_Input.txt", lambda b: b.replace(b" 0.5 ", b" infinity ", 1)))),
    *(Case(f"bag-metadata-{name}", ("map", "{d}/run", "--config", "{cfg}", "--out", "{d}/o"), says,
           copy_run(lambda r, change=change: (r / "bag" / "metadata.yaml").write_text(
               change((r / "bag" / "metadata.yaml").read_text()))))
      for name, change, says in (
          ("storage-mcap-for-a-db3", lambda m: m.replace("storage_identifier: sqlite3", "storage_identifier: mcap"),
           "bag: not a readable ROS bag"),
          ("without-storage-identifier", lambda m: m.replace("  storage_identifier: sqlite3\n", ""),
           "bag: not a readable ROS bag (A metadata key is missing KeyError('storage_identifier').)"),
          ("file-compression-not-applied", lambda m: m.replace("compression_format: ''", "compression_format: zstd").replace(
              "compression_mode: ''", "compression_mode: FILE"), "bag: not a readable ROS bag (Unable to decompress"),
      )),
    Case("map-out-through-proc", (*MAP, "--out", "/proc/self/gslam-o"), "/proc/self/gslam-o: --out cannot be written"),
    Case("map-out-in-sys", (*MAP, "--out", "/sys/kernel/gslam-o"), "/sys/kernel/gslam-o: --out cannot be written"),
]


# --- the warning corpus: usable data, mapped with one line that says what is odd ---


@dataclass(frozen=True)
class Warned:
    """``argv`` as for :class:`Case`, writing ``{d}/o``; ``says``: a part of
    a warning line; the run must succeed and write its result."""

    id: str
    argv: tuple[str, ...]
    says: str
    make: Callable[[Path, World], None] | None = None
    also: str | None = None  # a part of the result's metrics.json


def _marked(text: str, line: int) -> str:
    """``text`` with a byte-order mark at the start of ``line`` (from 1), as
    ``cat`` leaves one where a second file begins."""
    lines = text.split("\n")
    lines[line - 1] = "\ufeff" + lines[line - 1]
    return "\n".join(lines)


def _first_topic_twice(metadata: str) -> str:
    """A bag's metadata.yaml with its first topic listed a second time."""
    tree = yaml.safe_load(metadata)
    topics = tree["rosbag2_bagfile_information"]["topics_with_message_count"]
    topics.append(topics[0])
    return yaml.safe_dump(tree)


def _some(fraction: float, value: float) -> Callable[[np.ndarray, int], np.ndarray]:
    def change(r: np.ndarray, k: int) -> np.ndarray:
        r = r.copy()
        r[: int(len(r) * fraction)] = value
        return r

    return change


WARNINGS: list[Warned] = [
    Warned("carmen-blind-with-loops-in-submaps", CARMEN, "so no scan-matching factor and no loop closing",
           carmen(ranges=lambda r, k: 0 * r), '"source": "none"'),
    Warned("carmen-every-range-zero", BLIND, "the laser returns nothing (every range is 0 or negative)",
           carmen(ranges=lambda r, k: 0 * r), '"scan_matching": 0'),
    Warned("carmen-every-range-negative", BLIND, "are negative, up to -", carmen(ranges=lambda r, k: -r), '"scan_matching": 0'),
    Warned("carmen-every-range-1e308", BLIND, "the laser returns nothing (no range is a finite distance)",
           carmen(ranges=lambda r, k: 0 * r + 1e308), '"scan_matching": 0'),
    Warned("carmen-a-tenth-negative", CARMEN, "ranges (9.94 %) are negative", carmen(ranges=_some(0.1, -1.0))),
    Warned("carmen-ranges-of-a-light-year", CARMEN, "beyond 10000 m (no laser measures that far)",
           carmen(ranges=_some(0.2, 9.46e15))),
    Warned("carmen-theta-unwrapped", CARMEN, "", carmen(theta=4 * math.pi)),
    Warned("carmen-stamps-moved-counted", CARMEN, "1 scan stamps step back; 6 stamps moved",
           carmen(stamp=lambda k: 1000.0 + 0.5 * k - (3.0 if 20 <= k < 26 else 0.0))),
    Warned("carmen-latin1-host", CARMEN, "", carmen(encoding=lambda s: s.replace("host", "h\xf4st").encode("latin-1"))),
    Warned("carmen-utf8-bom", CARMEN, "", carmen(encoding=lambda s: b"\xef\xbb\xbf" + s.encode())),
    Warned("config-utf8-bom", (*MAP[:2], "--config", "{d}/c.yaml", *QUICK, "--out", "{d}/o"), "",
           raw("c.yaml", b"\xef\xbb\xbfkeyframes: {period_s: 0.5}\n")),
    Warned("bag-every-range-nan", BAG, "the laser returns nothing (no range is a finite distance)",
           bag(each("/scan", lambda t, m: m.ranges.fill(np.nan))), '"scan_matching": 0'),
    Warned("bag-range-max-zero", BAG, "the laser returns nothing (its range limits are [0.1, 0] m)",
           bag(each("/scan", lambda t, m: setattr(m, "range_max", 0.0)))),
    Warned("bag-two-beams", BAG, "2 beams per scan, too few to match scans (at least 3)",
           bag(each("/scan", lambda t, m: setattr(m, "ranges", m.ranges[:2].copy())))),
    Warned("laser-beyond-the-frontend-limits", (*MAP, *QUICK, "--set", "frontend.min_range_m=25", "--out", "{d}/o"),
           "the laser returns nothing within frontend.min_range_m 25", None, '"scan_matching": 0'),
    Warned("voxel-small", (*MAP, *QUICK, "--set", "frontend.voxel_size_m=0.01", "--out", "{d}/o"),
           "frontend.voxel_size_m 0.01 is 1/"),
    Warned("voxel-large", (*MAP, *QUICK, "--set", "frontend.voxel_size_m=1.5", "--out", "{d}/o"),
           "frontend.voxel_size_m 1.5 is 1/"),
    Warned("time-offset-a-third-of-the-run", (*MAP, *QUICK, "--set", "input.time_offsets_s.compass=8", "--out", "{d}/o"),
           "input.time_offsets_s.compass +8 s moves the compass stream by"),
    Warned("scenario-leg-through-an-obstacle", ("simulate", "{d}/s.yaml", "--out", "{d}/o"),
           "the leg from robot.waypoints.1 to robot.waypoints.2 crosses world.obstacles.",
           scenario(lambda t: t["world"]["obstacles"].append([[4, 1.0], [4.4, 1.0], [4.4, 1.4], [4, 1.4]]))),
    Warned("scenario-waypoints-all-one-point", ("simulate", "{d}/s.yaml", "--out", "{d}/o"),
           "s.yaml: robot.waypoints are all (1, 1.2): the simulated robot stands still for the whole run",
           scenario_waypoints([[1.0, 1.2], [1.0, 1.2, 2.0], [1.0, 1.2]])),
    Warned("scenario-leg-through-a-wall", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), "crosses world.walls.",
           scenario(lambda t: t["world"]["walls"].append([[5, 0.5], [5, 2.0]]))),
    Warned("carmen-range-limit-param-1e300", CARMEN, "the laser's range limit is 1e+300 m, beyond 10000 m",
           carmen(head="PARAM robot_front_laser_max 1e300")),
    Warned("librsf-without-ground-truth-anchored-once", LIBRSF, "no ground truth to anchor the first pose",
           librsf_with("loop 9.0 1.0 1")),
    # -- Windows line ends and byte-order marks in every text input, and a path with a newline: read as they are --
    Warned("carmen-crlf", CARMEN, "", carmen(encoding=lambda s: s.replace("\n", "\r\n").encode())),
    Warned("librsf-crlf-with-a-bom", LIBRSF, "", both(librsf_with("loop 9.0 1.0 1"), _rewritten(
        "X_Input.txt", lambda b: b"\xef\xbb\xbf" + b.replace(b"\n", b"\r\n")))),
    Warned("config-crlf", (*MAP[:2], "--config", "{d}/c.yaml", *QUICK, "--out", "{d}/o"), "",
           both(config(lambda t: None), _rewritten("c.yaml", lambda b: b.replace(b"\n", b"\r\n")))),
    Warned("scenario-crlf-with-a-bom", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), "", both(
        scenario(lambda t: None), _rewritten("s.yaml", lambda b: b"\xef\xbb\xbf" + b.replace(b"\n", b"\r\n")))),
    Warned("truth-json-with-a-bom", ("map", "{d}/run", "--config", "{cfg}", *QUICK, "--out", "{d}/o"), "",
           copy_run(lambda r: (r / "truth.json").write_bytes(b"\xef\xbb\xbf" + (r / "truth.json").read_bytes()))),
    Warned("bag-metadata-crlf", ("map", "{d}/run", "--config", "{cfg}", *QUICK, "--out", "{d}/o"), "",
           copy_run(lambda r: (r / "bag" / "metadata.yaml").write_bytes(
               (r / "bag" / "metadata.yaml").read_bytes().replace(b"\n", b"\r\n")))),
    Warned("carmen-log-named-with-a-newline", ("map", "{d}/a\nb.log", "--config", str(CONFIGS / "datasets" / "carmen.yaml"),
                                              *QUICK, "--out", "{d}/o"), "", carmen(name="a\nb.log")),
    # -- the seventh attack's usable oddities, kept as they are --
    *(Warned(f"config-{name}", (*MAP[:2], "--config", "{d}/c.yaml", *QUICK, "--out", "{d}/o"),
             "c.yaml is empty: every key takes its built-in default", text("c.yaml", content))
      for name, content in (("only-document-markers", "---\n...\n"), ("a-null-document", "~\n"))),
    Warned("set-one-key-twice-to-one-value", (*MAP, *QUICK, "--set", "keyframes.period_s=0.5", "--set",
                                              "keyframes.period_s=0.5", "--out", "{d}/o"), ""),
    Warned("set-a-key-beside-a-section-given-before", (*MAP, *QUICK, "--set", "keyframes={{period_s: 0.5}}", "--set",
                                                       "keyframes.distance_m=0.3", "--out", "{d}/o"), ""),
    Warned("carmen-every-stamp-the-same", CARMEN, "39 of 39 scan stamps do not increase", carmen(stamp=lambda k: 1000.0)),
    Warned("carmen-one-beam-per-scan", CARMEN, "1 beam per scan, too few to match scans",
           carmen(encoding=lambda s: "\n".join(" ".join(["FLASER", "1", *line.split(" ")[182:]]) if line.startswith("FLASER")
                                               else line for line in s.split("\n")).encode())),
    # -- the eighth attack: old Mac line ends, tabs between values, a laser mounted upside down: read as they are --
    Warned("carmen-cr-line-ends", CARMEN, "", carmen(encoding=lambda s: s.replace("\n", "\r").encode())),
    Warned("carmen-tab-separated", CARMEN, "", carmen(encoding=lambda s: s.replace(" ", "\t").encode())),
    Warned("librsf-tab-separated", LIBRSF, "", both(librsf_with("loop 9.0 1.0 1"), _rewritten(
        "X_Input.txt", lambda b: b.replace(b" ", b"\t")))),
    Warned("bag-laser-upside-down", BAG, "", bag(each("/scan", lambda t, m: (
        setattr(m, "angle_min", m.angle_max), setattr(m, "angle_increment", -m.angle_increment),
        setattr(m, "ranges", m.ranges[::-1].copy()))))),
    Warned("inject-two-gyro-biases-overlap", ("inject", "{run}", "--fault", "gyro_bias@2:6", "--fault",
                                              "gyro_bias@4:8,bias_deg_s=1", "--out", "{d}/o"),
           "--fault gyro_bias@2:6,bias_deg_s=2.0,label_deg_s=0.57 and --fault gyro_bias@4:8,bias_deg_s=1.0,label_deg_s=0.57 "
           "overlap from 4 to 6 s: both are added there"),
    # -- a metric of the spec's that no job writes: a column of '–' in summary.md, said nowhere --
    *(Warned(f"ablate-metric-{name}", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), says,
             spec(metrics=[metric, "ate_rmse_m"]))
      for name, metric, says in (
          ("unknown", "nope", "metrics: no finished job wrote 'nope', so its column of summary.md is empty; the metrics are "
           "the columns of summary.csv ("),
          ("with-a-typo", "ate_rmse", "metrics: no finished job wrote 'ate_rmse', so its column of summary.md is empty; "
           "did you mean 'ate_rmse_m'?"),
      )),
    # -- gslam inject into a CARMEN log holding a byte that is no ASCII: a UnicodeEncodeError traceback before --
    *(Warned(f"inject-carmen-{name}", ("inject", "{d}/c.log", "--fault", "laser_cut@2:4", "--out", "{d}/o"), "",
             carmen(encoding=encoding))
      for name, encoding in (
          ("with-a-latin1-host", lambda s: s.replace("host", "h\xf4st").encode("latin-1")),
          ("with-a-utf8-comment", lambda s: ("# r\u00e9glages du laser \u2014 lab\n" + s).encode()),
      )),
    # -- the ninth attack: two logs joined by cat, the second's byte-order mark hiding its first record (skipped before) --
    Warned("carmen-byte-order-mark-in-the-middle", CARMEN, "c.log:61: a byte-order mark inside the CARMEN text log (files "
           "joined?); read past it", carmen(encoding=lambda s: _marked(s, 61).encode()), '"n_poses": 40'),
    Warned("librsf-byte-order-marks-in-the-middle", LIBRSF, "X_Input.txt:51: a byte-order mark inside the libRSF text file "
           "(files joined?), and 1 more after it; read past it", both(librsf_with("loop 9.0 1.0 1"), _rewritten(
               "X_Input.txt", lambda b: b.replace(b"\nodom2 5.0 ", b"\n\xef\xbb\xbfodom2 5.0 ").replace(
                   b"\nloop", b"\n\xef\xbb\xbfloop")))),
    # -- the tenth attack: usable oddities read as they are (numbers in scientific notation and -0.0, what a bag's
    # -- metadata.yaml says of its topics where the database says otherwise, walls and legs of no length) --
    Warned("librsf-scientific-notation-and-minus-zero", LIBRSF, "", both(librsf_with("loop 9.0 1.0 1"), _rewritten(
        "X_Input.txt", lambda b: b.replace(b" 0.5 0 ", b" 5E-1 -0.0 ").replace(b" 0.01 0.01 0.01", b" 1e-2 1.0e-02 1e-320")))),
    *(Warned(f"bag-metadata-{name}", ("map", "{d}/run", "--config", "{cfg}", *QUICK, "--out", "{d}/o"), "",
             copy_run(lambda r, change=change: (r / "bag" / "metadata.yaml").write_text(
                 change((r / "bag" / "metadata.yaml").read_text()))), '"n_poses"')
      for name, change in (
          ("counts-of-another-bag", lambda m: m.replace("message_count: 2400", "message_count: 10")),
          ("a-topic-listed-twice", _first_topic_twice),
          ("serialization-format-unknown", lambda m: m.replace("serialization_format: cdr", "serialization_format: json", 1)),
          ("version-from-the-future", lambda m: m.replace("version: 8", "version: 99")),
      )),
    *(Warned(f"scenario-{name}", ("simulate", "{d}/s.yaml", "--out", "{d}/o"), "", scenario(change))
      for name, change in (
          ("wall-of-no-length", lambda t: t["world"]["walls"].append([[3.0, 6.0], [3.0, 6.0]])),
          ("a-waypoint-given-twice", lambda t: t["robot"]["waypoints"].insert(1, list(t["robot"]["waypoints"][1]))),
          ("waypoints-a-nanometre-apart", lambda t: t["robot"]["waypoints"].insert(
              2, [t["robot"]["waypoints"][1][0] + 1e-9, t["robot"]["waypoints"][1][1]])),
      )),
]


def _run(argv: list[str], capsys) -> tuple[int, str, list]:
    with warnings.catch_warnings(record=True) as caught, time_limit(TIME_LIMIT_S):
        warnings.simplefilter("always")
        try:
            code = main(["-q", *argv])
        except SystemExit as e:  # argparse
            code = e.code
    _, err = capsys.readouterr()
    leaked = [w for w in caught if issubclass(w.category, (RuntimeWarning, UserWarning))]
    return code, err, leaked


def run_error(case: Case, world: World, tmp_path: Path, capsys, longest_line: int | None = LONGEST_LINE) -> None:
    """Run ``case`` in this process and check what a refused input must
    give: its exit code and error (:func:`check_error_output`), no line
    longer than ``longest_line`` (None: unchecked), no leaked warning,
    nothing changed."""
    d, watched, before = prepare(case, world, tmp_path, checksums)
    capsys.readouterr()
    code, err, leaked = _run(expand(case.argv, d, world), capsys)
    assert code == case.code, f"exit {code}: {err[-800:]}"
    check_error_output(code, err, case)
    if longest_line is not None:
        longest = max(map(len, err.splitlines()))
        assert longest <= longest_line, f"a line of {longest:,} characters"
    assert not leaked, [str(w.message) for w in leaked]
    assert checksums(*watched) == before, "an input changed, or something was left behind"


@pytest.mark.parametrize("case", ERRORS, ids=[c.id for c in ERRORS])
def test_hostile_input_gives_one_clean_error(case: Case, world: World, tmp_path: Path, capsys):
    run_error(case, world, tmp_path, capsys)


def run_warned(case: Warned, world: World, tmp_path: Path, capsys, caplog,
               commands: tuple[str, ...] = ("map", "simulate", "inject", "ablate")) -> Path:
    """Run ``case`` in this process and check what a usable but odd input
    must give: exit 0, no traceback or leaked warning, one-line warnings of
    which exactly one says ``case.says``, a result of one of ``commands`` in
    ``{d}/o`` (its metrics holding ``case.also``), nothing else changed.
    The case's folder ``d``."""
    d = tmp_path / "case"
    d.mkdir()
    if case.make is not None:
        case.make(d, world)
    before = checksums(d, world.run, world.scenario.parent, CONFIGS)
    capsys.readouterr()
    with caplog.at_level(logging.WARNING):
        code, err, leaked = _run(expand(case.argv, d, world), capsys)
    assert code == 0, err[-800:]
    assert "Traceback" not in err and not leaked, (err, [str(w.message) for w in leaked])
    said = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert all("\n" not in s for s in said), said
    if case.says:
        assert sum(case.says in s for s in said) == 1, f"expected {case.says!r} once in: {said}"
    out = d / "o"
    assert json.loads((out / ".gslam-result.json").read_text())["command"] in commands
    if case.also is not None:
        assert case.also in (out / "metrics.json").read_text()
    after = checksums(d, world.run, world.scenario.parent, CONFIGS)
    assert {k: v for k, v in after.items() if not k.startswith(str(out))} == before
    return d


@pytest.mark.parametrize("case", WARNINGS, ids=[c.id for c in WARNINGS])
def test_odd_but_usable_input_is_used_with_one_warning(case: Warned, world: World, tmp_path: Path, capsys, caplog):
    d = run_warned(case, world, tmp_path, capsys, caplog)
    assert not [p for p in d.rglob("*") if ".gslam-tmp-" in p.name]


DATA_ROOTS = {  # GSLAM_DATA as set by mistake, and what {data}/ in a spec then says
    "missing": ("{d}/none", "recorded input {{data}}/carmen/c.log: GSLAM_DATA='{d}/none' is not a folder; expected the "
                "folder holding the data sets"),
    "a-file": ("{d}/f.txt", "GSLAM_DATA='{d}/f.txt' is not a folder"),
    "blank": ("   ", "GSLAM_DATA='   ' is not a folder"),
    "home-of-no-user": ("~gslam-no-such-user/data", "GSLAM_DATA='~gslam-no-such-user/data': cannot expand '~' (no such "
                        "user or no home folder)"),
}


@pytest.mark.parametrize("name", DATA_ROOTS)
def test_a_data_root_that_names_no_folder_is_one_line(name: str, world: World, tmp_path: Path, capsys, monkeypatch):
    """A spec's {data}/ under a GSLAM_DATA that names no folder: the error
    named the path joined below it (or, for ~ of no user, was a traceback)."""
    value, says = (v.format(d=tmp_path) for v in DATA_ROOTS[name])
    (tmp_path / "f.txt").write_text("mine\n")
    (tmp_path / "spec.yaml").write_text(f"name: x\nconfig: {TELEMAX_CONFIG}\ninputs: {{recorded: [{{path: '{{data}}/carmen/c.log'}}]}}\n")
    monkeypatch.setenv("GSLAM_DATA", value)
    code, err, leaked = _run(["ablate", str(tmp_path / "spec.yaml"), "--out", str(tmp_path / "o")], capsys)
    assert code == 1 and err.count("\n") == 1 and says in err and "Traceback" not in err, err
    assert not leaked and sorted(p.name for p in tmp_path.iterdir()) == ["f.txt", "spec.yaml"]


def test_a_relative_data_root_is_from_the_working_folder(world: World, tmp_path: Path, capsys, monkeypatch):
    """GSLAM_DATA=data read from the working folder, as a shell user means
    it; it was taken from the spec's folder, where nothing was found."""
    (tmp_path / "data" / "carmen").mkdir(parents=True)
    carmen()(tmp_path / "data" / "carmen", world)
    (tmp_path / "specs").mkdir()
    (tmp_path / "specs" / "spec.yaml").write_text(
        f"name: x\nconfig: {CONFIGS / 'datasets' / 'carmen.yaml'}\ninputs: {{recorded: [{{path: '{{data}}/carmen/c.log'}}]}}\n")
    monkeypatch.setenv("GSLAM_DATA", "data")
    monkeypatch.chdir(tmp_path)
    code, err, leaked = _run(["ablate", "specs/spec.yaml", "--out", "o"], capsys)
    assert code == 0 and not leaked, err[-800:]
    assert len(list((tmp_path / "o" / "jobs").iterdir())) == 1


@pytest.mark.parametrize("command", ["ablate", "compare"])
def test_text_of_the_users_reaches_report_html_as_text(command: str, world: World, tmp_path: Path, capsys):
    """A sweep's name and description, a recording's file name: shown in
    report.html as the text given, never read by the browser as HTML."""
    hostile = "<script>alert(1)</script>"
    carmen(name=f"{hostile[:8]}.log")(tmp_path, world)
    if command == "ablate":
        (tmp_path / "spec.yaml").write_text(yaml.safe_dump({
            "name": hostile, "description": '<img src=x onerror="alert(1)">', "config": str(TELEMAX_CONFIG),
            "inputs": {"scenarios": [{"path": str(world.scenario), "seeds": [1]}]}, "variants": {"a": {}}}))
        argv = ["ablate", str(tmp_path / "spec.yaml")]
    else:
        argv = ["compare", str(tmp_path / f"{hostile[:8]}.log"), "--config", str(CONFIGS / "datasets" / "carmen.yaml"),
                "--only", "ungated", *QUICK]
    code, err, leaked = _run([*argv, "--out", str(tmp_path / "o")], capsys)
    assert code == 0 and not leaked, err[-800:]
    page = (tmp_path / "o" / "report.html").read_text()
    assert "&lt;script&gt;" in page and "<script" not in page and "<img src=x" not in page


def test_an_injected_carmen_log_keeps_its_bytes_that_are_no_utf8(world: World, tmp_path: Path, capsys):
    """A Latin-1 host name in a CARMEN log: gslam inject failed with a
    traceback writing it back; every line it does not change is now the
    log's own, byte for byte."""
    carmen(encoding=lambda s: s.replace("host", "h\xf4st").encode("latin-1"))(tmp_path, world)
    code, err, leaked = _run(["inject", str(tmp_path / "c.log"), "--fault", "laser_cut@2:4", "--out", str(tmp_path / "o")],
                             capsys)
    assert code == 0 and not leaked, err[-800:]
    given, written = ((p.read_bytes().split(b"\n")) for p in (tmp_path / "c.log", tmp_path / "o" / "bag" / "c.log"))
    assert [ln for ln in given if ln.startswith(b"ODOM")] == [ln for ln in written if ln.startswith(b"ODOM")]
    assert all(b"h\xf4st" in ln for ln in written if ln)


def test_corpus_counts():
    """At least 60 new cases; tests/test_fuzz.py's stay beside them."""
    from tests.test_fuzz import CASES

    assert len(ERRORS) + len(WARNINGS) + len(PROCESS) >= 60
    assert len({c.id for c in [*CASES, *ERRORS, *WARNINGS]}) == len(CASES) + len(ERRORS) + len(WARNINGS)
    commands = {c.argv[0] for c in [*ERRORS, *WARNINGS]}
    assert {"simulate", "map", "compare", "ablate", "inspect", "inject", "calibrate"} <= commands


# --- as real processes: signals, killed runs, full disks ----------------------------


def signals_as_a_user_has_them() -> None:
    """A child process's stop signals at their defaults, as a user's gslam
    has them, not the test runner's: under nohup (SIGHUP ignored) or as a
    background job of a script (SIGINT ignored), which gslam keeps ignored,
    the signal cases would test nothing (a ``preexec_fn``)."""
    for s in STOPS:
        signal.signal(s, signal.SIG_DFL)


def _gslam(argv: list, cwd: Path, limit_bytes: int | None = None) -> subprocess.Popen:
    def limit() -> None:
        signals_as_a_user_has_them()
        if limit_bytes is not None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, limit_bytes))

    return subprocess.Popen([sys.executable, "-m", "slam.cli", "-q", *map(str, argv)], cwd=cwd,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": str(REPO)}, preexec_fn=limit)


def _wait_for(predicate: Callable[[], bool], proc: subprocess.Popen, seconds: float = 60.0) -> None:
    deadline = time.monotonic() + seconds
    while not predicate() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)


def _said(err: str) -> str:
    """stderr without its warnings (the short run has no GPS fix, and says so)."""
    return "".join(line for line in err.splitlines(keepends=True) if not line.startswith("WARNING "))


def _temps(root: Path) -> list[Path]:
    """gslam's temporary files and folders under ``root``, while gslam may
    be renaming them (os.walk passes over a folder gone between listing it
    and entering it; rglob raised)."""
    return [Path(folder) / name for folder, dirs, files in os.walk(root) for name in (*dirs, *files)
            if ".gslam-tmp-" in name]


SIGNALLED = {
    "compare-SIGTERM": (["compare", "{run}", "--config", TELEMAX_CONFIG, "--only", "ungated,gated"], signal.SIGTERM),
    "map-SIGHUP": (["map", "{run}", "--config", TELEMAX_CONFIG, "--gating", "on"], signal.SIGHUP),
    "simulate-SIGTERM": (["simulate", "{scen}"], signal.SIGTERM),
    "inject-SIGTERM": (["inject", "{run}", "--fault", "gyro_bias@2:4"], signal.SIGTERM),
    "compare-SIGINT": (["compare", "{run}", "--config", TELEMAX_CONFIG, "--only", "ungated"], signal.SIGINT),
    # Ctrl-\ and the signals a job scheduler or a script may send.
    "map-SIGQUIT": (["map", "{run}", "--config", TELEMAX_CONFIG], signal.SIGQUIT),
    "inject-SIGUSR1": (["inject", "{run}", "--fault", "gyro_bias@2:4"], signal.SIGUSR1),
    "simulate-SIGALRM": (["simulate", "{scen}"], signal.SIGALRM),
}
FULL_DISK = {
    "simulate": (["simulate", "{scen}", "--out", "{d}/o"], 1_000_000, "the simulate result's bag ("),
    "map": (["map", "{run}", "--config", TELEMAX_CONFIG, "--out", "{d}/o"], 20_000, "no space left to write the map result"),
    "inject": (["inject", "{run}", "--fault", "gyro_bias@2:4", "--out", "{d}/o"], 1_000_000, "the inject result's bag ("),
    "calibrate": (["calibrate", "{run}", "--config", TELEMAX_CONFIG, "--clean", "0:10", "--out", "{d}/c.yaml"], 2_000,
                  "c.yaml: File too large"),
}
PROCESS = [*SIGNALLED, *(f"full-{k}" for k in FULL_DISK), "killed-compare-left-for-the-next-run", "space-estimated",
           "two-calibrates-into-one-file", "home-missing", "home-a-file"]


def _argv(argv: list, d: Path, world: World) -> list[str]:
    names = {"d": d, "run": world.run, "scen": world.scenario}
    return [str(a).format(**names) for a in argv]


@pytest.mark.parametrize("name", SIGNALLED)
def test_a_signal_ends_a_command_as_ctrl_c_does(name: str, world: World, tmp_path: Path):
    argv, sig = SIGNALLED[name]
    out = tmp_path / "out"
    before = checksums(world.run, world.scenario.parent)
    proc = _gslam([*_argv(argv, tmp_path, world), "--out", out], tmp_path)
    _wait_for(lambda: bool(_temps(tmp_path)), proc)  # the work (and the imports it needs) from here
    assert proc.poll() is None, proc.communicate()[1]
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=30)
    what = "interrupted" if sig == signal.SIGINT else f"terminated ({signal.Signals(sig).name})"
    assert proc.returncode == 128 + sig and _said(err) == f"gslam: {what}\n", (proc.returncode, err)
    # Nothing, or (a signal Python could not raise where it came) the whole result.
    assert not _temps(tmp_path) and (not out.exists() or (out / ".gslam-result.json").is_file())
    assert checksums(world.run, world.scenario.parent) == before


def test_a_terminated_sweep_stops_its_workers_at_once(world: World, tmp_path: Path):
    proc = _gslam(["ablate", world.spec, "--workers", "2", "--out", tmp_path / "sweep"], tmp_path)
    _wait_for(lambda: (tmp_path / "sweep" / "inputs").is_dir(), proc)
    proc.send_signal(signal.SIGTERM)
    start = time.monotonic()
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 143 and _said(err) == "gslam: terminated (SIGTERM)\n", err
    assert time.monotonic() - start < 10


def test_two_maps_into_one_new_out_at_once_leave_one_result_and_one_line(world: World, tmp_path: Path):
    """Two gslam map runs started together into the same new --out: one
    result, whole, and the other says so in one line; no temporary left."""
    argv = ["map", world.run, "--config", TELEMAX_CONFIG, *QUICK, "--out", tmp_path / "o"]
    procs = [_gslam(argv, tmp_path), _gslam([*argv, "--gating", "on"], tmp_path)]
    errs = [_said(p.communicate(timeout=120)[1]) for p in procs]
    assert sorted(p.returncode for p in procs) == [0, 1], errs
    lost = errs[[p.returncode for p in procs].index(1)]
    assert lost.count("\n") == 1 and "--out was filled by someone else while this command ran" in lost, lost
    assert json.loads((tmp_path / "o" / ".gslam-result.json").read_text())["command"] == "map"
    assert not _temps(tmp_path) and [p.name for p in tmp_path.iterdir()] == ["o"]


def test_two_calibrates_into_one_new_file_at_once_leave_one_result_and_one_line(world: World, tmp_path: Path):
    """Two gslam calibrate runs started together into the same new --out
    file both said 'wrote', the later replacing the earlier's file in
    silence: one writes it, the other says so in one line."""
    argv = ["calibrate", world.run, "--config", TELEMAX_CONFIG, "--clean", "0:10", "--out", tmp_path / "c.yaml"]
    procs = [_gslam(argv, tmp_path), _gslam([*argv[:-2], "--false-alarm", "0.01", *argv[-2:]], tmp_path)]
    errs = [_said(p.communicate(timeout=120)[1]) for p in procs]
    assert sorted(p.returncode for p in procs) == [0, 1], errs
    lost = errs[[p.returncode for p in procs].index(1)]
    assert lost == f"gslam: error: {tmp_path / 'c.yaml'}: --out was written by someone else while this command ran; " \
                   "nothing was written (give a new file name)\n", lost
    assert (tmp_path / "c.yaml").read_text().startswith("# gslam calibrate result")
    assert not _temps(tmp_path) and [p.name for p in tmp_path.iterdir()] == ["c.yaml"]


@pytest.mark.parametrize("home", ["missing", "a-file"])
def test_a_home_matplotlib_cannot_use_is_left_as_it_is(home: str, world: World, tmp_path: Path):
    """HOME naming a folder that does not exist: gslam map made it (its
    .config/matplotlib and .cache/matplotlib); HOME a file: matplotlib's
    two warning lines, and a matplotlib-* folder left in the temporary
    folder. Now nothing is made outside --out, nothing is left and nothing
    but gslam's own lines is said."""
    map_beside_a_file(world, tmp_path, HOME=str(tmp_path / home / "me"))


def map_beside_a_file(world: World, tmp_path: Path, **settings: str) -> None:
    """``gslam map`` of ``world``'s run into ``tmp_path/o``, with the
    environment ``settings`` (they may name ``tmp_path/a-file``, a file
    holding "mine") and its own empty TMPDIR: it maps, says nothing of
    matplotlib, and leaves nothing but a-file (unchanged), o and an empty
    tmp."""
    (tmp_path / "tmp").mkdir()
    (tmp_path / "a-file").write_text("mine\n")
    env = {k: v for k, v in os.environ.items() if not k.startswith(("XDG_", "MPL"))}
    env.update(settings, TMPDIR=str(tmp_path / "tmp"), PYTHONPATH=str(REPO))
    done = subprocess.run([sys.executable, "-m", "slam.cli", "-q", "map", str(world.run), "--config", str(TELEMAX_CONFIG),
                           "--out", str(tmp_path / "o")], cwd=tmp_path, capture_output=True, text=True,
                          timeout=TIME_LIMIT_S, env=env)
    assert done.returncode == 0, done.stderr[-800:]
    assert "matplotlib" not in done.stderr, done.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a-file", "o", "tmp"]
    assert list((tmp_path / "tmp").iterdir()) == [] and (tmp_path / "a-file").read_text() == "mine\n"


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_an_interrupted_sweep_leaves_no_half_written_job(sig: int, world: World, tmp_path: Path):
    """A sweep stopped while a worker writes a job: the workers were ended
    and the job's temporary folder left in jobs/ for the next run to find;
    the sweep removes it once its workers are gone."""
    proc = _gslam(["ablate", world.spec, "--out", tmp_path / "sweep"], tmp_path)
    _wait_for(lambda: any("jobs" in p.parts for p in _temps(tmp_path)), proc)
    assert proc.poll() is None, proc.communicate()[1]
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=30)
    what = "interrupted" if sig == signal.SIGINT else "terminated (SIGTERM)"
    assert proc.returncode == 128 + sig and _said(err) == f"gslam: {what}\n", err
    assert not _temps(tmp_path)


def test_a_killed_runs_temporary_folder_goes_with_the_next_run_into_its_folder(world: World, tmp_path: Path, capsys):
    proc = _gslam(["compare", world.run, "--config", TELEMAX_CONFIG, "--only", "ungated", "--out", tmp_path / "a"], tmp_path)
    _wait_for(lambda: bool(_temps(tmp_path)), proc)
    time.sleep(0.3)
    proc.kill()
    proc.communicate()
    assert _temps(tmp_path)
    assert main(["-q", "map", str(world.run), "--config", str(TELEMAX_CONFIG), *QUICK, "--out", str(tmp_path / "b")]) == 0
    capsys.readouterr()
    assert not _temps(tmp_path) and {p.name for p in tmp_path.iterdir()} == {"b"}


@pytest.mark.parametrize("name", FULL_DISK)
def test_a_full_disk_is_one_line_naming_the_result(name: str, world: World, tmp_path: Path):
    """The file size limit makes every write past it fail as a full disk
    does (EFBIG instead of ENOSPC): the same paths, without filling a disk."""
    argv, limit, says = FULL_DISK[name]
    d = tmp_path / "case"
    d.mkdir()
    proc = _gslam(_argv(argv, d, world), d, limit_bytes=limit)
    _, err = proc.communicate(timeout=120)
    err = _said(err)
    assert proc.returncode == 1 and err.count("\n") == 1 and says in err and str(d) in err, err
    assert ".gslam-tmp-" not in err
    assert list(d.iterdir()) == []


def test_the_space_a_simulation_needs_is_checked_first(world: World, tmp_path: Path, capsys, monkeypatch):
    real = os.statvfs

    def small(path):
        st = real(path)
        return os.statvfs_result((st.f_bsize, st.f_frsize, st.f_blocks, 10, 10, st.f_files, st.f_ffree, st.f_favail,
                                  st.f_flag, st.f_namemax))

    monkeypatch.setattr(os, "statvfs", small)
    code = main(["-q", "simulate", str(world.scenario), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 1 and "--out needs about" in err and "free some space" in err, err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name, config", [
    ("huge.log", "carmen.yaml"),
    ("Huge_Input.txt", "librsf_corridor.yaml"),
    ("huge.bag", "husky.yaml"),
    ("huge.mcap", "husky.yaml"),
    ("huge.db3", "husky.yaml"),
])
def test_a_huge_sparse_file_is_refused_on_its_first_bytes(tmp_path, capsys, name, config):
    """A 20 GB file of zeros (sparse: no disk is used) is refused in one line
    from its first bytes, before a reader takes gigabytes into memory."""
    from slam.cli import main

    path = tmp_path / name
    with open(path, "wb") as f:
        f.truncate(20 << 30)
    code = main(["-q", "map", str(path), "--config", f"configs/datasets/{config}", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 1 and err.count("\n") == 1 and str(path) in err
    assert "binary content" in err or "not a readable ROS bag" in err


def test_a_run_given_twice_is_learnt_from_once_with_one_warning(world: World, tmp_path: Path, capsys, caplog):
    """gslam calibrate given one recording five ways (its path, the path with
    a slash, a link to it, its bag, a copy of the run folder) learns from it
    once, says so in one warning line, and writes what it writes for the run
    given once: counted five times, each step's false alarm would weigh a
    fifth."""
    (tmp_path / "link").symlink_to(world.run)
    shutil.copytree(world.run, tmp_path / "copy")
    once, four = tmp_path / "once.yaml", tmp_path / "four.yaml"
    cal = ("calibrate", "--config", str(TELEMAX_CONFIG), "--clean", "0:10")
    assert main(["-q", *cal[:1], str(world.run), *cal[1:], "--out", str(once)]) == 0
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        code = main(["-q", *cal[:1], str(world.run), f"{world.run}/", str(tmp_path / "link"), str(world.run / "bag"),
                     str(tmp_path / "copy"), *cal[1:], "--out", str(four)])
    assert code == 0 and "Traceback" not in capsys.readouterr().err
    said = [r.getMessage() for r in caplog.records if "repeat" in r.getMessage()]
    assert len(said) == 1 and said[0].startswith("4 of the 5 runs given repeat a recording; each recording is learnt "
                                                 "from once: "), said
    assert f"{tmp_path / 'copy'} (a copy of the recording of {world.run})" in said[0]
    assert four.read_text() == once.read_text()


@pytest.mark.parametrize("command", ["map", "compare", "ablate", "simulate"])
def test_a_removed_working_folder_is_one_line_before_any_work(command: str, world: World, tmp_path: Path):
    """A shell whose folder was removed under it: gslam map, compare and
    ablate said 'No such file or directory' naming nothing (the config's
    loader asks for the working folder), and past that loading Open3D ends
    the process in oneMKL's 'FATAL ERROR: Cannot load libOpen3D' (exit 2,
    the temporary folder left); simulate ran. Every command now says so
    first, before any work."""
    argv = {"map": ["map", world.run, "--config", TELEMAX_CONFIG, *QUICK],
            "compare": ["compare", world.run, "--config", TELEMAX_CONFIG, "--only", "ungated", *QUICK],
            "ablate": ["ablate", world.spec], "simulate": ["simulate", world.scenario]}[command]
    gone, out = tmp_path / "gone", tmp_path / "out"
    gone.mkdir()
    out.mkdir()
    done = subprocess.run([sys.executable, "-m", "slam.cli", "-q", *map(str, argv), "--out", str(out / "o")], cwd=gone,
                          preexec_fn=lambda: os.rmdir(gone), capture_output=True, text=True, timeout=TIME_LIMIT_S,
                          env={**os.environ, "PYTHONPATH": str(REPO)})
    assert (done.returncode, done.stderr) == (1, "gslam: error: the current folder no longer exists (removed while a "
                                                 "shell was in it); cd to a folder that does and run again\n")
    assert list(out.iterdir()) == []


@pytest.mark.parametrize("encoding", [None, "latin-1"])
def test_a_path_in_a_c_locale_is_named_by_the_bytes_given(encoding: str | None, world: World, tmp_path: Path):
    """Under LC_ALL=C without Python's UTF-8 mode, a path's non-ASCII bytes
    are no text: the error and the 'wrote' line named them as Python's
    escapes ('\\udcc3\\udcb1'), a name the user never typed; they name the
    bytes given, as the shell shows them, and the result goes where it was
    asked to."""
    env = {**os.environ, "PYTHONPATH": str(REPO), "LC_ALL": "C", "LANG": "C", "PYTHONUTF8": "0"}
    env.pop("PYTHONIOENCODING", None)
    if encoding is not None:
        env["PYTHONIOENCODING"] = encoding
    missing, out = os.fsencode(tmp_path) + "/ñone".encode(), os.fsencode(tmp_path) + "/résultat→".encode()
    gslam = [sys.executable, "-m", "slam.cli"]
    done = subprocess.run([*gslam, "-q", "map", missing, "--config", str(TELEMAX_CONFIG), "--out", os.fsencode(tmp_path / "o")],
                          capture_output=True, env=env, timeout=TIME_LIMIT_S)
    assert (done.returncode, done.stderr) == (1, b"gslam: error: " + missing + b": no such file or directory\n")
    done = subprocess.run([*gslam, "map", str(world.run), "--config", str(TELEMAX_CONFIG), *QUICK, "--out", out],
                          capture_output=True, env=env, timeout=TIME_LIMIT_S)
    assert done.returncode == 0 and done.stdout.startswith(b"wrote " + out + b"\n"), done
    assert os.listdir(os.fsencode(tmp_path)) == ["résultat→".encode()]


@pytest.mark.parametrize("command", ["map", "map-again", "simulate", "inject", "compare", "calibrate", "inspect"])
def test_an_out_name_near_the_file_systems_limit_is_written(command: str, world: World, tmp_path: Path, capsys):
    """A result's name of 250 bytes is a valid file name (at most 255), but
    the temporary name built beside it ('.NAME.gslam-tmp-PID-HOST-TAG')
    was not: every command said '--out cannot be written: ... (File name
    too long)' about a name the user may give. The temporary name keeps
    only the start of a long name."""
    long = tmp_path / ("r" * 246 + (".yaml" if command in ("calibrate", "inspect") else ""))
    cfg = ("--config", str(TELEMAX_CONFIG))
    argv = {"map": ["map", world.run, *cfg, *QUICK, "--out"], "map-again": ["map", world.run, *cfg, *QUICK, "--out"],
            "simulate": ["simulate", world.scenario, "--out"],
            "inject": ["inject", world.run, "--fault", "gyro_bias@2:4", "--out"],
            "compare": ["compare", world.run, *cfg, "--only", "ungated", *QUICK, "--out"],
            "calibrate": ["calibrate", world.run, *cfg, "--clean", "0:10", "--out"],
            "inspect": ["inspect", world.run, "--config-out"]}[command]
    for _ in range(2 if command == "map-again" else 1):
        assert main(["-q", *map(str, argv), str(long)]) == 0, capsys.readouterr().err
    assert [p.name for p in tmp_path.iterdir()] == [long.name]


def test_a_warning_that_echoes_the_input_is_one_short_line_with_its_control_characters_escaped(world: World,
                                                                                                 tmp_path: Path):
    # The log's name holds a newline and an ESC sequence (retitling a
    # terminal), and its odometry has a gap, which a warning names the log
    # for; a PARAM value of 100,000 characters is echoed back.
    name = "a\nb\x1b]0;t\x07.log"
    carmen(n=20, head="PARAM robot_front_laser_max " + "x" * 100_000 + " host 0", name=name)(tmp_path, world)
    lines = (tmp_path / name).read_text().splitlines()
    gap = [i for i, line in enumerate(lines) if line.startswith("ODOM")][20:24]
    (tmp_path / name).write_text("\n".join(line for i, line in enumerate(lines) if i not in gap) + "\n")
    proc = _gslam(["map", tmp_path / name, "--config", CONFIGS / "datasets" / "carmen.yaml", *QUICK,
                   "--out", tmp_path / "o"], tmp_path)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, err[-800:]
    warned = [line for line in err.splitlines() if line.startswith("WARNING ")]
    assert any("robot_front_laser_max" in line and "characters" in line for line in warned), warned
    assert any("b\\x1b]0;t\\x07.log: " in line and "odometry" in line for line in warned), warned
    assert max(map(len, err.splitlines())) <= 2_000 and "\x1b" not in err and "\x07" not in err, err[:300]
