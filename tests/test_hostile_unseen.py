"""Hostile input of kinds the other corpora (tests/test_fuzz.py,
tests/test_hostile.py, tests/test_hostile_readers.py,
tests/test_hostile_commands.py) did not hold, run by their runners:

* stamps before 1970 (a CARMEN log, a ROS 2 bag, a scenario's t0): read
  and mapped, then writing run.mcap, whose log times are unsigned, ended in
  a traceback;
* numbers YAML 1.1 reads as another value than their digits say, in every
  YAML input and ``--set``: a leading 0 (``010`` read as octal 8) and base
  60 (``1:30`` read as 90): used in silence;
* a sweep with a failing job: exit 1 with no error line;
* a CARMEN ``PARAM robot_front_laser_max nan``: every scan left out with a
  warning where a LaserScan's NaN range_max is an error;
* an ``MPLCONFIGDIR`` that is a file: matplotlib's two warning lines and a
  folder of its own left in the temporary folder;
* Ctrl-C while a command starts: the process ended by SIGINT after saying
  "interrupted", or its teardown crashed, or a callback from numba's
  compiler swallowed it (a traceback, and the map ran on);
* the environment of the libraries: ``NUMBA_NUM_THREADS=abc`` (a warning
  quoting a traceback) or ``0`` (a traceback), ``MPLBACKEND=bogus`` (two);
* a CARMEN range limit of 0 or below (every scan left out with a warning);
* ``--out ~nouser/o`` and ``--out=~/o``: a folder named '~...' made in the
  working folder;
* ``validation.observers: null`` (every observer reset to its default);
* a YAML input named as another kind (``cannot read config`` for a
  variants file or a spec, ``found a int``);

and, kept so that none regresses, kinds already answered in one line: a
gzip'd log corrupted or cut inside its stream, a ROS 1 bag whose index
points past its end or into a chunk, BROAD fields of disagreeing lengths or
MATLAB v7.3, libRSF stamps given twice or swapped, YAML keys and values of
odd types and tags, ``--set`` values in YAML syntax, sections of the wrong
type deep in a config, a spec or a variants file, a YAML 2.0 directive,
and an odd environment of the libraries (``PYTHONWARNINGS=error``, a
``TMPDIR`` or ``NUMBA_CACHE_DIR`` that is no folder, an unknown locale,
nonsense BLAS thread counts).
"""

from __future__ import annotations

import gzip
import json
import logging
import os
import signal
import struct
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from slam.errors import Terminated
from slam.processes.signals import as_interrupt
from tests.conftest import CONFIGS, REPO, TELEMAX_CONFIG
from tests.test_fuzz import (  # noqa: F401 - world is a fixture
    Case, World, broad_mat, check_error_output, data, expand, scenario, set_in, text, world,
)
from tests.test_hostile import (
    BAG, CARMEN, MAP, QUICK, _gslam, _run, _said, _temps, _wait_for, bag, carmen, librsf_with, map_beside_a_file,
    restamp, run_error, signals_as_a_user_has_them, spec_text,
)
from tests.bagfactory import driving_bag

pytestmark = pytest.mark.slow  # end to end: pytest -m 'not slow' leaves it out

CONFIG = (*MAP[:2], "--config", "{d}/c.yaml", *QUICK, "--out", "{d}/o")
LIBRSF = ("map", "{d}/X_Input.txt", "--config", str(CONFIGS / "datasets" / "librsf_corridor.yaml"), *QUICK, "--out",
          "{d}/o")
BROAD = ("map", "{d}/t.mat", "--config", "{cfg}", *QUICK, "--out", "{d}/o")
GZ = (CARMEN[0], "{d}/c.log.gz", *CARMEN[2:])
ROS1 = ("map", "{d}/r.bag", "--config", "{cfg}", *QUICK, "--out", "{d}/o")
VARIANTS = ("compare", "{run}", "--config", "{cfg}", "--variants", "{d}/v.yaml", *QUICK, "--out", "{d}/o")


def set_(expr: str) -> tuple[str, ...]:
    return (*MAP, *QUICK, "--out", "{d}/o", "--set", expr)


def gzipped_carmen(change: Callable[[bytes, bytes], bytes]) -> Callable[[Path, World], None]:
    """The CARMEN log gzip'd at ``{d}/c.log.gz``, its bytes then ``change(gz, log)``."""

    def make(d: Path, world: World) -> None:
        carmen()(d, world)
        log = (d / "c.log").read_bytes()
        (d / "c.log").unlink()
        (d / "c.log.gz").write_bytes(change(gzip.compress(log), log))

    return make


def _flipped_mid_stream(gz: bytes, log: bytes) -> bytes:
    middle = len(gz) // 2
    return gz[:middle] + bytes(b ^ 0xFF for b in gz[middle:middle + 8]) + gz[middle + 8:]


def ros1(change: Callable[[bytes], bytes]) -> Callable[[Path, World], None]:
    """The driving bag as a ROS 1 bag at ``{d}/r.bag``, its bytes then ``change(bytes)``."""

    def make(d: Path, world: World) -> None:
        full = driving_bag(ros=1, duration_s=4.0).write(d / "full.bag")
        (d / "r.bag").write_bytes(change(full.read_bytes()))
        full.unlink()

    return make


def _header_field(name: bytes, value: int, fmt: str) -> Callable[[bytes], bytes]:
    """A ROS 1 bag's first ``name=`` header field (the bag header's) set to ``value``."""

    def change(raw: bytes) -> bytes:
        at = raw.index(name + b"=") + len(name) + 1
        return raw[:at] + struct.pack(fmt, value) + raw[at + struct.calcsize(fmt):]

    return change


def librsf_lines(change: Callable[[str], str]) -> Callable[[Path, World], None]:
    def make(d: Path, world: World) -> None:
        librsf_with("loop 9.0 1.0 1")(d, world)
        (d / "X_Input.txt").write_text(change((d / "X_Input.txt").read_text()))

    return make


def scenario_text(old: str, new: str) -> Callable[[Path, World], None]:
    """The short scenario at ``{d}/s.yaml`` with its text ``old`` written ``new``."""

    def make(d: Path, world: World) -> None:
        body = world.scenario.read_text()
        assert old in body
        (d / "s.yaml").write_text(body.replace(old, new, 1))

    return make


def robotlaser_max_range(value: str, scan: int) -> Callable[[Path, World], None]:
    """The CARMEN log of ROBOTLASER1 lines (max_range 50) whose line of
    scan ``scan`` gives ``value`` as its max_range."""

    def encoded(log: str) -> bytes:
        head, *scans = log.split("ROBOTLASER1 ")
        scans[scan] = scans[scan].replace(" 50 0.01 0 181 ", f" {value} 0.01 0 181 ", 1)
        return "ROBOTLASER1 ".join([head, *scans]).encode()

    return carmen(robotlaser=(-1.5707963, 3.1415927, 0.0174533), encoding=encoded)


def _every_topic_before_1970(b) -> None:
    for topic in {t for (_, _, t, _, _) in b._messages}:
        restamp(topic, lambda k: -1.8e9)(b)


ERRORS = [
    # -- stamps before 1970: mapped, then run.mcap (unsigned log times) failed with a traceback --
    Case("carmen-stamps-before-1970", CARMEN, "c.log: scans stamp 0 is -1000 s since 1970; expected 0 to",
         carmen(stamp=lambda k: -1000.0 + 0.5 * k)),
    Case("bag-stamps-before-1970", (*BAG[:3], "{cfg}", *BAG[4:]), "s since 1970; expected 0 to 2147483647 s",
         bag(_every_topic_before_1970)),
    Case("scenario-t0-before-1970", ("simulate", "{d}/s.yaml", "--out", "{d}/o"),
         "s.yaml: environment.t0_s: Input should be greater than or equal to 0",
         scenario(set_in("environment", "t0_s", -1000.0))),
    # -- numbers YAML 1.1 reads as another value than their digits say: used in silence --
    Case("config-count-with-a-leading-zero", CONFIG, "c.yaml: line 1: invalid YAML (010 is octal 8 to YAML 1.1",
         text("c.yaml", "backend: {max_iterations: 010}\n")),
    Case("config-count-with-a-leading-zero-under-yaml-1.2", CONFIG, "c.yaml: line 3: invalid YAML (010 is octal 8",
         text("c.yaml", "%YAML 1.2\n---\nbackend: {max_iterations: 010}\n")),
    Case("config-period-in-base-60", CONFIG, "c.yaml: line 1: invalid YAML (1:30 is a base-60 number to YAML 1.1 (90)",
         text("c.yaml", "keyframes: {period_s: 1:30}\n")),
    Case("config-period-as-a-clock-time", CONFIG, "(1:30:00 is a base-60 number to YAML 1.1 (5400)",
         text("c.yaml", "gating: {holdoff_s: 1:30:00}\n")),
    Case("config-float-in-base-60", CONFIG, "(1:30.5 is a base-60 number to YAML 1.1 (90.5)",
         text("c.yaml", "keyframes: {period_s: 1:30.5}\n")),
    Case("set-count-with-a-leading-zero", set_("backend.max_iterations=010"),
         "--set backend.max_iterations=010: 010 is octal 8 to YAML 1.1 (a leading 0), 10 to YAML 1.2"),
    Case("set-period-in-base-60", set_("keyframes.period_s=1:30"),
         "--set keyframes.period_s=1:30: 1:30 is a base-60 number to YAML 1.1 (90)"),
    Case("scenario-laps-with-a-leading-zero", ("simulate", "{d}/s.yaml", "--out", "{d}/o"),
         "s.yaml: line 240: invalid YAML (010 is octal 8", scenario_text("  laps: 1\n", "  laps: 010\n")),
    Case("variants-value-in-base-60", VARIANTS, "v.yaml: line 1: invalid YAML (2:00 is a base-60 number",
         text("v.yaml", "slow: {keyframes.period_s: 2:00}\n")),
    Case("spec-variant-value-with-a-leading-zero", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), "(017 is octal 15",
         spec_text("variants: {a: {backend.max_iterations: 017}}\n")),
    # -- a CARMEN PARAM NaN: every scan left out with a warning --
    *(Case(f"carmen-param-laser-max-{name}", CARMEN, f"c.log:1: PARAM robot_front_laser_max {value}: expected the "
           "laser's maximum range in metres", carmen(head=f"PARAM robot_front_laser_max {value}"))
      for name, value in (("nan", "nan"), ("NaN", "NaN"), ("minus-nan", "-nan"))),
    # -- a CARMEN range limit of 0 or below: every scan left out with a warning --
    *(Case(f"carmen-param-laser-max-{name}", CARMEN, f"c.log:1: PARAM robot_front_laser_max {value}: expected the "
           "laser's maximum range in metres, above 0", carmen(head=f"PARAM robot_front_laser_max {value}"))
      for name, value in (("zero", "0"), ("minus-zero", "-0.0"), ("negative", "-30"), ("minus-inf", "-inf"))),
    Case("carmen-robotlaser-max-range-zero", CARMEN, "c.log:1: ROBOTLASER1 max_range 0: expected the laser's maximum "
         "range in metres, above 0", robotlaser_max_range("0", scan=0)),
    Case("carmen-robotlaser-max-range-negative-later", CARMEN, "c.log:7: ROBOTLASER1 max_range -50: expected",
         robotlaser_max_range("-50", scan=2)),
    # -- an output path of a user that does not exist: a folder '~nouser' made in the working folder --
    *(Case(f"{name}-out-of-no-user", (*argv, flag, "~gslam-no-such-user/o"), f"argument {flag}: "
           "'~gslam-no-such-user/o': cannot expand '~gslam-no-such-user' (no such user or no home folder)", code=2)
      for name, argv, flag in (
          ("map", (*MAP, *QUICK), "--out"),
          ("simulate", ("simulate", "{scen}"), "--out"),
          ("compare", ("compare", "{run}", "--config", "{cfg}", "--only", "ungated"), "--out"),
          ("inject", ("inject", "{run}", "--fault", "gyro_bias@2:4"), "--out"),
          ("ablate", ("ablate", "{spec}"), "--out"),
          ("calibrate", ("calibrate", "{run}", "--config", "{cfg}"), "--out"),
          ("demo", ("demo",), "--out"),
          ("inspect", ("inspect", "{run}"), "--config-out"),
      )),
    # -- null for the observers' section: every observer reset to its default in silence --
    *(Case(f"set-observers-{name}", set_(f"validation.observers={value}"), f"--set validation.observers={value}: "
           "validation.observers: expected a mapping of the observers' settings, got null")
      for name, value in (("null", "null"), ("tilde", "~"), ("empty", ""))),
    Case("set-observers-a-list", set_("validation.observers=[1]"), "validation.observers: expected a mapping of the "
         "observers' settings, got a list"),
    Case("config-observers-empty", CONFIG, "c.yaml: validation.observers: expected a mapping of the observers' "
         "settings, got null", text("c.yaml", "validation:\n  observers:\n")),
    Case("variant-observers-null", VARIANTS, "validation.observers: expected a mapping",
         text("v.yaml", "a: {validation.observers: null}\n")),
    # -- a YAML input that is no mapping, or not a file, named as another kind ("found a int", "cannot read config") --
    Case("config-top-level-a-number", CONFIG, "c.yaml: expected a YAML mapping of keys at the top level, found a "
         "number", text("c.yaml", "5\n")),
    Case("config-top-level-text", CONFIG, "c.yaml: expected a YAML mapping of keys at the top level, found text",
         text("c.yaml", "backend\n")),
    Case("variants-a-folder", VARIANTS, "v.yaml: cannot read variants file (a folder; expected a file)",
         lambda d, w: (d / "v.yaml").mkdir()),
    Case("spec-a-folder", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), "spec.yaml: cannot read ablation spec (a "
         "folder; expected a file)", lambda d, w: (d / "spec.yaml").mkdir()),
    Case("variants-utf16", VARIANTS, "v.yaml: UTF-16 text; expected a YAML variants file in UTF-8",
         data("v.yaml", "a: {validation.mode: 'off'}\n".encode("utf-16"))),
    Case("spec-utf16", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"), "spec.yaml: UTF-16 text; expected a YAML "
         "ablation spec in UTF-8", data("spec.yaml", "name: x\n".encode("utf-16"))),
    # -- kinds already answered in one line, kept so that none regresses --
    Case("config-yaml-2.0-directive", CONFIG, "c.yaml: line 1: invalid YAML (found incompatible YAML document)",
         text("c.yaml", "%YAML 2.0\n---\nbackend: {}\n")),
    Case("config-factor-a-number", CONFIG, "c.yaml: backend.factors.odometry: Input should be a valid dictionary",
         text("c.yaml", "backend: {factors: {odometry: 5}}\n")),
    Case("config-topics-a-list", CONFIG, "c.yaml: input.topics: Input should be a valid dictionary",
         text("c.yaml", "input: {topics: [/scan, /imu]}\n")),
    Case("config-loops-enabled-a-word", CONFIG, "c.yaml: loops.enabled: Input should be a valid boolean",
         text("c.yaml", "loops: {enabled: maybe}\n")),
    Case("config-voxel-size-a-list", CONFIG, "c.yaml: frontend.voxel_size_m: Input should be a valid number",
         text("c.yaml", "frontend: {voxel_size_m: [0.1]}\n")),
    Case("spec-variants-a-list", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"),
         "spec.yaml: variants: Input should be a valid dictionary", spec_text("variants: [a, b]\n")),
    Case("spec-variant-null", ("ablate", "{d}/spec.yaml", "--out", "{d}/o"),
         "spec.yaml: variants.a: Input should be a valid dictionary", spec_text("variants: {a: null}\n")),
    Case("variants-variant-null", VARIANTS, "v.yaml: variant 'a': expected a mapping of dotted.key: value",
         text("v.yaml", "a: null\n")),
    Case("set-value-starting-with-an-equals-sign", set_("backend.max_iterations==5"),
         "--set backend.max_iterations==5: backend.max_iterations: Input should be a valid integer"),
    Case("set-binary-tag", set_("backend.max_iterations=!!binary AAAA"),
         "--set backend.max_iterations=!!binary AAAA: backend.max_iterations: Input should be a valid integer"),
    Case("carmen-gz-corrupted-mid-stream", GZ, "c.log.gz: not a valid gzip file", gzipped_carmen(_flipped_mid_stream)),
    Case("carmen-gz-wrong-crc", GZ, "c.log.gz: not a valid gzip file (CRC check failed",
         gzipped_carmen(lambda gz, log: gz[:-8] + bytes([gz[-8] ^ 1]) + gz[-7:])),
    Case("carmen-gz-wrong-length", GZ, "c.log.gz: not a valid gzip file (Incorrect length",
         gzipped_carmen(lambda gz, log: gz[:-1] + bytes([gz[-1] ^ 1]))),
    Case("carmen-log-holding-gzip", CARMEN, "c.log", gzipped_carmen(lambda gz, log: gz),),
    Case("carmen-beam-count-short-of-its-ranges", CARMEN, "c.log:1: expected FLASER",
         carmen(ranges=lambda r, k: r, head="FLASER 3 1 2 3 4 5 0 0 0 0 0 0 1000.0 host 1000.0")),
    Case("carmen-range-inf", CARMEN, "c.log:", carmen(ranges=lambda r, k: np.where(np.arange(len(r)) == 7, np.inf, r))),
    Case("ros1-index-past-the-end", ROS1, "r.bag: not a readable ROS bag (the bag's index is cut off or damaged",
         ros1(lambda raw: _header_field(b"index_pos", len(raw) + 10**6, "<Q")(raw))),
    Case("ros1-index-into-a-chunk", ROS1, "r.bag: not a readable ROS bag (the bag's index is cut off or damaged",
         ros1(lambda raw: _header_field(b"index_pos", len(raw) // 2 + 3, "<Q")(raw))),
    Case("ros1-connection-count-2e9", ROS1, "r.bag: not a readable ROS bag", ros1(_header_field(b"conn_count", 2**31, "<I"))),
    Case("ros1-version-1.2", ROS1, "r.bag", ros1(lambda raw: raw.replace(b"#ROSBAG V2.0", b"#ROSBAG V1.2", 1))),
    Case("ros1-unknown-compression", ROS1, "r.bag", ros1(lambda raw: raw.replace(b"compression=none", b"compression=zzzz", 1))),
    *(Case(f"broad-{name}", BROAD, "t.mat", broad_mat(**fields)) for name, fields in (
        ("gyro-longer-than-the-rest", {"imu_gyr": np.zeros((70, 3))}),
        ("quaternions-shorter", {"opt_quat": np.tile([1, 0, 0, 0], (30, 1))}),
        ("movement-shorter", {"movement": np.ones((20, 1), dtype=np.uint8)}),
        ("complex-gyro", {"imu_gyr": np.zeros((50, 3)) + 1j}),
        ("rate-of-two-values", {"sampling_rate": np.array([[100.0, 200.0]])}),
        ("rate-negative", {"sampling_rate": np.array([[-100.0]])}),
    )),
    Case("broad-matlab-v7.3", BROAD, "t.mat: cannot read as a MATLAB v5 file", data(
        "t.mat", b"MATLAB 7.3 MAT-file, Platform: GLNXA64, HDF5 schema 1.00 .".ljust(116, b" ") + b"\0" * 8
        + b"\x00\x02IM" + b"\x89HDF\r\n\x1a\n" + b"\0" * 400)),
    Case("librsf-stamp-given-twice", LIBRSF, "X_Input.txt: odom2 line #42: expected increasing times, got 4.0 after 4.0",
         librsf_lines(lambda t: t.replace("odom2 4.1 ", "odom2 4.0 "))),
    Case("librsf-two-lines-swapped", LIBRSF, "odom2 line #42: expected increasing times, got 4.0 after 4.1",
         librsf_lines(lambda t: t.replace("odom2 4.0 ", "odom2 X ").replace("odom2 4.1 ", "odom2 4.0 ")
                      .replace("odom2 X ", "odom2 4.1 "))),
    Case("config-key-true-in-a-section", CONFIG, "c.yaml", text("c.yaml", "backend: {true: 2}\n")),
    Case("config-merge-of-a-number", CONFIG, "c.yaml", text("c.yaml", "backend: {<<: 5}\n")),
    Case("config-tag-directive", CONFIG, "c.yaml", text("c.yaml", "%TAG !e! tag:example.com,2000:\n---\nbackend: !e!x {}\n")),
    Case("config-null-section", CONFIG, "c.yaml: backend: Input should be a valid dictionary", text("c.yaml", "backend:\n")),
    Case("set-map-for-a-number", set_("frontend.voxel_size_m={{a: 1}}"), "--set frontend.voxel_size_m={a: 1}: "),
    Case("set-two-documents", set_("frontend.voxel_size_m=0.1\n---\n0.2"), "--set frontend.voxel_size_m="),
    Case("set-timestamp-for-a-period", set_("keyframes.period_s=2001-01-01"), "--set keyframes.period_s=2001-01-01"),
    Case("variant-replacing-a-section-by-a-number", VARIANTS, "v.yaml", text("v.yaml", "a: {frontend: 5}\n")),
]


@pytest.mark.parametrize("case", ERRORS, ids=[c.id for c in ERRORS])
def test_unseen_hostile_input_gives_one_clean_error(case: Case, world: World, tmp_path: Path, capsys):
    run_error(case, world, tmp_path, capsys)


def test_a_sweep_with_a_failing_job_ends_with_one_error_line(world: World, tmp_path: Path, capsys):
    """One job of two fails: the other is written, the failure recorded,
    and the exit code 1 comes with one error line (there was none)."""
    spec_text("variants: {ok: {validation.mode: 'off'}, bad: {keyframes.period_s: 1000}}\n")(tmp_path, world)
    code, err, leaked = _run(["ablate", str(tmp_path / "spec.yaml"), "--out", str(tmp_path / "o")], capsys)
    assert code == 1 and not leaked, err[-800:]
    check_error_output(code, err, Case("ablate-a-failing-job", (), "gslam: error: 1 of 2 jobs failed ("))
    assert "fewer than 2 keyframes" in err and f"errors in {tmp_path / 'o' / 'failed'}, the other 1 written" in err
    assert len(list((tmp_path / "o" / "jobs").iterdir())) == 1 and len(list((tmp_path / "o" / "failed").iterdir())) == 1


@pytest.mark.parametrize("where", ["a-file", "beneath-a-file"])
def test_an_mplconfigdir_matplotlib_cannot_use_is_left_as_it_is(where: str, world: World, tmp_path: Path):
    """MPLCONFIGDIR naming a file: matplotlib said so in two warning lines
    and left a matplotlib-* folder in the temporary folder; now gslam's own
    temporary folder stands in, removed at the end."""
    given = tmp_path / "a-file" if where == "a-file" else tmp_path / "a-file" / "mpl"
    map_beside_a_file(world, tmp_path, MPLCONFIGDIR=str(given))
    assert (tmp_path / "o" / "trajectory.png").is_file()


def test_corpus_counts():
    assert len(ERRORS) >= 40
    assert len({c.id for c in ERRORS}) == len(ERRORS)


# --- Ctrl-C while a command starts ---------------------------------------------------


def _loaded(proc: subprocess.Popen, library: str) -> bool:
    """``library`` (a shared object's path holds it) is loaded in ``proc``."""
    try:
        return library in Path(f"/proc/{proc.pid}/maps").read_text()
    except OSError:  # ended, or no /proc
        return proc.poll() is not None


@pytest.mark.skipif(not Path("/proc/self/maps").is_file(), reason="needs /proc to see the command's imports begin")
@pytest.mark.parametrize("delay_s", [0.0, 0.2, 0.4, 0.6, 0.9])
def test_ctrl_c_while_a_map_starts_is_one_line_and_code_130(delay_s: float, world: World, tmp_path: Path):
    """Ctrl-C during the imports of a starting ``gslam map`` (``delay_s``
    after numpy is loaded): the process died by SIGINT after saying
    "interrupted" (CPython's own exit, see slam.errors.Terminated) or by
    a double free in its teardown, or a traceback came from a callback of
    numba's compiler and the map ran on to its end."""
    out = tmp_path / "o"
    proc = _gslam(["map", world.run, "--config", TELEMAX_CONFIG, *QUICK, "--out", out], tmp_path)
    _wait_for(lambda: _loaded(proc, "numpy"), proc)
    time.sleep(delay_s)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    if proc.returncode == 0:  # the map was done first
        assert "Traceback" not in err and json.loads((out / ".gslam-result.json").read_text())["command"] == "map"
        return
    assert proc.returncode == 130 and _said(err) == "gslam: interrupted\n", (proc.returncode, err)
    assert not _temps(tmp_path) and (not out.exists() or (out / ".gslam-result.json").is_file())


def test_ctrl_c_inside_code_run_by_exec_keeps_the_exit_code(tmp_path: Path):
    """A KeyboardInterrupt that went through ``exec`` (a namedtuple's, an
    import's) made CPython end a ``python -m`` process by SIGINT, though it
    was caught and the code 130 returned."""
    (tmp_path / "stopped.py").write_text(
        "import signal, sys\n"
        "from slam.processes.signals import as_interrupt\n"
        "try:\n"
        "    with as_interrupt([]):\n"
        "        exec('import signal; signal.raise_signal(signal.SIGINT); sum(range(10))')\n"
        "except KeyboardInterrupt:\n"
        "    sys.exit(130)\n")
    done = subprocess.run([sys.executable, "-m", "stopped"], cwd=tmp_path, capture_output=True, text=True, timeout=60,
                          env={**os.environ, "PYTHONPATH": f"{tmp_path}{os.pathsep}{REPO}"},
                          preexec_fn=signals_as_a_user_has_them)
    assert done.returncode == 130, (done.returncode, done.stderr)


def test_ctrl_c_swallowed_by_a_callback_comes_again(capsys):
    """Ctrl-C landing in code Python cannot raise from (a callback from C,
    here a destructor) was printed as "Exception ignored ... Traceback" and
    lost: the command ran on to its end."""

    class Cut:
        def __del__(self):
            signal.raise_signal(signal.SIGINT)
            sum(range(10))  # Python code: where the handler runs

    received: list[int] = []
    start = time.monotonic()
    # Ctrl-C as a terminal delivers it, though the tests may run where it is ignored (a script's background job).
    given = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(Terminated), as_interrupt(received):
            Cut()
            time.sleep(10)
    finally:
        signal.signal(signal.SIGINT, given)
    assert time.monotonic() - start < 5 and received[0] == signal.SIGINT
    assert "Traceback" not in capsys.readouterr().err


# --- the environment numba reads ------------------------------------------------------


def _map_with(world: World, tmp_path: Path, **settings: str) -> subprocess.CompletedProcess:
    """``gslam map`` of ``world``'s run into ``tmp_path/o`` as a process (numba
    reads its environment once, when it is imported), with ``settings``."""
    return subprocess.run([sys.executable, "-m", "slam.cli", "-q", "map", str(world.run), "--config",
                           str(TELEMAX_CONFIG), *QUICK, "--out", str(tmp_path / "o")], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120,
                          env={**os.environ, **settings, "PYTHONPATH": str(REPO)})


@pytest.mark.parametrize("threads", ["abc", "0", "-3", "1.5", ""])
def test_a_numba_thread_count_that_is_none_is_one_line(threads: str, world: World, tmp_path: Path):
    """NUMBA_NUM_THREADS=abc: numba's warning quoted a whole traceback; 0
    or below: numba's import ended gslam with a traceback."""
    done = _map_with(world, tmp_path, NUMBA_NUM_THREADS=threads)
    check_error_output(done.returncode, done.stderr, Case(
        "numba-threads", (), f"environment variable NUMBA_NUM_THREADS={threads!r}: expected a positive whole number"))
    assert done.returncode == 1 and not (tmp_path / "o").exists()


def test_a_numba_setting_numba_cannot_read_is_one_warning_line(world: World, tmp_path: Path):
    done = _map_with(world, tmp_path, NUMBA_OPT="fast", NUMBA_NUM_THREADS="2")
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    said = [line for line in done.stderr.splitlines() if "NUMBA_OPT" in line]
    assert len(said) == 1 and "NUMBA_OPT='fast': numba cannot read it" in said[0], done.stderr
    assert (tmp_path / "o" / ".gslam-result.json").is_file()


@pytest.mark.parametrize("command", ["map", "calibrate"])
def test_an_out_the_shell_left_with_its_tilde_is_in_the_home_folder(command: str, world: World, tmp_path: Path,
                                                                     capsys, monkeypatch):
    """``--out=~/o`` (the shell expands no '~' after '='): a folder named '~'
    was made in the working folder, beside the user's home."""
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.chdir(tmp_path)
    (tmp_path / "home").mkdir()
    argv = {"map": [*MAP, *QUICK, "--out=~/o"], "calibrate": ["calibrate", "{run}", "--config", "{cfg}", "--out=~/o"]}
    code, err, _ = _run(expand(tuple(argv[command]), tmp_path, world), capsys)
    assert code == 0, err[-800:]
    assert [p.name for p in tmp_path.iterdir()] == ["home"] and (tmp_path / "home" / "o").exists()



# --- the environment of the libraries gslam loads ----------------------------------------


@pytest.mark.parametrize("backend", ["bogus", "TkAgg"])
def test_a_matplotlib_backend_in_the_environment_is_left_aside(backend: str, world: World, tmp_path: Path):
    """MPLBACKEND=bogus ended matplotlib's import, and the map, with two
    tracebacks; gslam draws into files, whatever the backend (TkAgg
    without a display)."""
    map_beside_a_file(world, tmp_path, MPLBACKEND=backend, DISPLAY="")
    assert (tmp_path / "o" / "trajectory.png").is_file()


@pytest.mark.parametrize("setting", [
    {"PYTHONWARNINGS": "error"},  # every Python warning an exception
    {"TMPDIR": "/nonexistent/tmp"},
    {"TMPDIR": "/etc/hostname"},  # a file
    {"NUMBA_CACHE_DIR": "/etc/hostname"},
    {"LC_ALL": "xx_YY.bogus"},
    {"OMP_NUM_THREADS": "abc", "OPENBLAS_NUM_THREADS": "0"},
], ids=["pythonwarnings-error", "tmpdir-missing", "tmpdir-a-file", "numba-cache-a-file", "locale-unknown",
        "blas-threads-nonsense"])
def test_an_odd_environment_of_the_libraries_still_maps_without_a_traceback(setting: dict[str, str], world: World,
                                                                             tmp_path: Path):
    done = _map_with(world, tmp_path, **setting)
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr[-800:]
    assert json.loads((tmp_path / "o" / ".gslam-result.json").read_text())["command"] == "map"


# --- text logs read a megabyte at a time ----------------------------------------------


JUNK_LINE_BYTES = 64 << 20
"""A line no record is (a damaged or foreign file): read whole, it took
three times its size in memory before anything looked at it."""


def _with_a_junk_line(name: str, make: Callable[[Path, World], None], d: Path, world: World) -> Path:
    """The log ``make`` writes at ``d/name`` followed by one line of
    :data:`JUNK_LINE_BYTES` digits; gzip'd where ``name`` ends in ``.gz``."""
    make(d, world)
    plain_name = name.removesuffix(".gz")
    body = (d / plain_name).read_bytes() + b"7" * JUNK_LINE_BYTES + b"\n"
    (d / plain_name).unlink()
    (d / name).write_bytes(gzip.compress(body, compresslevel=1) if name.endswith(".gz") else body)
    return d / name


@pytest.mark.parametrize("name,config", [("c.log", "carmen.yaml"), ("c.log.gz", "carmen.yaml"),
                                         ("X_Input.txt", "librsf_corridor.yaml")])
def test_a_line_no_record_is_refused_at_its_number_without_taking_its_size_in_memory(
        name: str, config: str, world: World, tmp_path: Path):
    make = carmen() if name.startswith("c.log") else librsf_with("loop 9.0 1.0 1")
    path = _with_a_junk_line(name, make, tmp_path, world)
    lines = sum(1 for _ in (gzip.open if name.endswith(".gz") else open)(path, "rb"))
    # VmHWM, not ru_maxrss: Linux carries ru_maxrss over from the forking test process.
    probe = ("import sys\nfrom slam.cli import main\n"
             f"code = main(['-q', 'map', {str(path)!r}, '--config', {str(CONFIGS / 'datasets' / config)!r}, "
             f"'--out', {str(tmp_path / 'o')!r}])\n"
             "peak = [l for l in open('/proc/self/status') if l.startswith('VmHWM')][0].split()[1]\n"
             "print('peak_kb', peak, file=sys.stderr)\n"
             "sys.exit(code)\n")
    proc = subprocess.run([sys.executable, "-c", probe], cwd=REPO, capture_output=True, text=True, timeout=120)
    said = [line for line in proc.stderr.splitlines() if not line.startswith("peak_kb")]
    assert proc.returncode == 1 and said == [f"gslam: error: {path}:{lines}: a line of over 1 MB; no "
                                             f"{'CARMEN text log' if name.startswith('c.') else 'libRSF text file'} "
                                             "record is that long (a damaged or foreign file?)"], proc.stderr
    peak_mb = int(proc.stderr.split("peak_kb ")[1].split()[0]) / 1024
    assert peak_mb < JUNK_LINE_BYTES / (1 << 20) + 100, proc.stderr  # the interpreter and libraries; not the line


def _nul_beyond_the_first_megabyte(d: Path, world: World) -> None:
    carmen()(d, world)
    log = d / "c.log"
    log.write_bytes(log.read_bytes() + (b"# " + b"x" * 62 + b"\n") * (2 << 20 >> 6) + b"ODOM 1 2 \0 3\n")


def test_a_nul_byte_beyond_the_first_megabyte_is_still_binary_content(world: World, tmp_path: Path, capsys):
    run_error(Case("carmen-nul-beyond-the-first-megabyte", CARMEN,
                   "c.log: cannot read: not a CARMEN text log (binary content)", _nul_beyond_the_first_megabyte),
              world, tmp_path, capsys)


@pytest.mark.parametrize("end", ["\n", "\r\n", "\r"])
def test_lines_read_a_megabyte_at_a_time_are_the_lines_of_the_whole(end: str, tmp_path: Path, caplog):
    """Line ends, a UTF-8 character, a byte that is not UTF-8 and a
    byte-order mark where one megabyte ends and the next begins: the lines
    are those of ``str.splitlines`` on the whole text, the mark's line the
    one its warning names."""
    from slam.readers.files import SNIFF_BYTES, log_lines

    body = "ODOM 1 2 3\n".replace("\n", end) * (SNIFF_BYTES // (10 + len(end)))
    # The first megabyte ends inside the \r\n, or else inside the é after the line end.
    edge = SNIFF_BYTES - len(body.encode()) - (1 if end == "\r\n" else 2)
    tail = f"{'x' * edge}{end}é".encode() + b"\xf4" + f"\ufeffODOM 4{end}{end}last".encode()
    path = tmp_path / "c.log"
    path.write_bytes(body.encode() + tail)
    expected = path.read_bytes().decode("utf-8", errors="surrogateescape").replace("\ufeff", "").splitlines()
    with caplog.at_level(logging.WARNING):
        assert list(log_lines(path, "CARMEN text log")) == expected
    assert [r.getMessage() for r in caplog.records] == [
        f"{path}:{body.count(end) + 2}: a byte-order mark inside the CARMEN text log (files joined?); read past it"]
