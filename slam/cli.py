"""``gslam``: the command line. It only parses arguments and calls the
library; every command is a library function returning a result object."""

from __future__ import annotations

import argparse
import atexit
import codecs
import gc
import json
import logging
import math
import os
import platform
import re
import shlex
import signal
import sys
import unicodedata
import warnings
from pathlib import Path
from typing import NoReturn

from slam import __version__
from slam.errors import GslamError, Terminated, reader_left
from slam.outputs.plot_home import plot_home
from slam.processes.signals import STOPS, as_interrupt
from validation.base.errors import InputError
from validation.base.modes import GatingMode

log = logging.getLogger("gslam")

EXAMPLES = """\
examples:
  gslam demo
  gslam simulate configs/scenarios/telemax_lab.yaml --out runs/lab --seed 1
  gslam inspect runs/lab --config-out my_robot.yaml
  gslam map runs/lab --config configs/telemax.yaml --out runs/lab_map
  gslam map runs/lab --config configs/telemax.yaml --out runs/lab_gated --gating on
  gslam map runs/lab --config configs/telemax.yaml --out runs/lab_isam2 --set backend.optimizer=isam2
  gslam map recording.bag --config my_robot.yaml --out runs/real --set input.topics.scan=/base_scan
  gslam compare runs/lab --config configs/telemax.yaml --out runs/lab_compare
  gslam inject recording.bag --config my_robot.yaml --fault dipole@100:120 --out runs/with_dipole
  gslam calibrate recording.bag --config my_robot.yaml --out my_robot_calibrated.yaml
  gslam ablate configs/ablations/gating_policy.yaml --out runs/ablate_gating --workers 2

paths starting with configs/ that do not exist in the working folder name
the configs shipped with gslam, so these examples work from any folder.
"""

INPUTS = """\
recording to read; its format is recognised from the path: a ROS 1 .bag
file, a ROS 2 bag (folder with metadata.yaml, or a .db3 or .mcap file), a
run folder (a simulated run folder or a gslam inject result: truth.json + bag/), a CARMEN
.log or .log.gz, a BROAD trial .mat, or a libRSF *_Input.txt"""

OUTPUT_RULE = """\
--out must be new, or an earlier result of the same command (it holds
.gslam-result.json, which lists the files the command wrote): those are
replaced, any file of yours there is kept. Anything else is refused before
any work. --force adds the command's files to another folder, replacing
nothing of yours. --out is never empty, an input, a folder holding one or
a place inside one, a link, a device or a pipe."""


def _config_path(path: str | None) -> Path | None:
    from slam.resources import resolve_config_path

    return resolve_config_path(path) if path is not None else None


def _cmd_simulate(args: argparse.Namespace) -> int:
    from slam.sim import simulate

    res = simulate(_config_path(args.scenario), args.out, seed=args.seed, progress=not args.quiet, force=args.force)
    _say(f"wrote {res.run_dir} ({res.duration_s:.1f} s simulated)")
    for comp, intervals in res.faults.items():
        if intervals:
            spans = ", ".join(f"{a:.1f}-{b:.1f} s" for a, b in intervals)
            print(f"  true faults {comp}: {spans}")
    return 0


def _cmd_inject(args: argparse.Namespace) -> int:
    from slam.config import load_config
    from slam.commands.inject import inject

    from slam.config import config_files

    config_path = _config_path(args.config)
    config = load_config(config_path)
    res = inject(args.input, args.fault or [], args.out, config.input, inputs=config_files(config_path),
                 force=args.force)
    _say(f"wrote {res.run_dir} ({res.duration_s:.1f} s, the input with the faults added; truth.json beside it)")
    for comp, intervals in sorted(res.injected.items()):
        spans = ", ".join(f"{a:.1f}-{b:.1f} s" for a, b in intervals) or "none beyond the nominal noise"
        print(f"  injected faults {comp}: {spans}")
    return 0


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from slam.commands.calibrate import calibrate
    from slam.commands.calibrate.support import uses_fitted_gain

    res = calibrate(args.runs, _config_path(args.config), args.out, clean=args.clean, false_alarm=args.false_alarm,
                    force=args.force, progress=not args.quiet, overrides=args.set or [],
                    lag_reference=args.lag_reference, drop_unsupported=not args.keep_unsupported)
    for name, choice in res.choices.items():
        if name in res.dropped:
            print(f"  {name}: dropped, the data do not support it: {res.dropped[name].reason}")
            continue
        if choice is None:
            print(f"  {name}: kept as configured (no run has both its streams)")
            continue
        r = choice.relation
        what = f"b {r.boundary:.3g}" if r.kind == "trend" else f"sigma_floor {r.sigma_floor:.3g} x {r.k_sigma:g}"
        alarm = f"{100 * choice.alarm:.2f} %" if choice.met else "target not met"
        verdict = res.support.get(name)
        why = f", kept: {verdict.measure} {verdict.value:.2f}" if verdict is not None and verdict.kept else ""
        gain = choice.fit.gain if uses_fitted_gain(r) else r.gain  # the one its observer uses
        print(f"  {name} ({r.kind}): gain {gain:.3f}, {what}, w {r.window_s:g} s, th {r.threshold}: "
              f"alarms on {alarm} of the learning steps{why}")
    if res.choices:
        kept = [n for n in res.choices if n not in res.dropped]
        gone = f", dropped {len(res.dropped)} ({', '.join(res.dropped)})" if res.dropped else ", dropped none"
        print(f"  relations: kept {len(kept)} of {len(res.choices)}{gone}")
    for p in res.proposals:
        print(f"  proposed {p.choice.relation.name}: rates correlate {p.choice.fit.corr:.3f} (commented out in the file)")
    for lag in res.applied:
        print(f"  time offset of {lag.stream} against {lag.reference}: {lag.offset_s:+.3f} s, RMS of the rate "
              f"difference {-100 * lag.gain:+.0f} %: added to input.time_offsets_s, the relations learnt with it")
    for lag in res.lags:
        if not any(a.stream == lag.stream for a in res.applied):
            print(f"  time offset of {lag.stream} against {lag.reference}: {lag.offset_s:+.3f} s, RMS of the rate "
                  f"difference {-100 * lag.gain:+.0f} %: kept as configured, {lag.why_not() or 'proposed (see the file)'}")
    if res.applied_heading is not None:
        h = res.applied_heading
        print(f"  compass heading against the GPS course: {math.degrees(h.offset_rad):+.1f} deg (mean resultant length "
              f"{h.steadiness:.2f} over {h.steps} steps): added to input.compass.mounting_yaw_deg, the relations "
              "learnt with it")
    elif res.heading_offset is not None:
        h = res.heading_offset
        print(f"  compass heading against the GPS course: {math.degrees(h.offset_rad):+.1f} deg: kept as configured, "
              f"{h.why_not()}")
    if res.compass_noise is not None:
        n = res.compass_noise
        print(f"  compass factor: sd {math.degrees(n.sd_rad):.3g} deg against the gyro, correlated over "
              f"{n.correlation_s:.3g} s: written to backend.factors.compass")
    _say(f"wrote {res.out} (target {100 * res.target_per_observer:.3f} % of steps per observer): "
          f"gslam map RUN --config {res.out} --out DIR --gating on")
    return 0


def _cmd_inspect(args: argparse.Namespace) -> int:
    from slam.commands.inspect.inspection import inspect_recording
    from slam.results.outdir import check_new_file, file_state, write_result_file

    base = _config_path(args.config) if args.config is not None else None
    checked = None
    if args.config_out is not None:
        from slam.config import config_files

        check_new_file(args.config_out, [args.input, *config_files(base)], args.force, command="inspect",
                       flag="--config-out")
        checked = file_state(args.config_out)
    found = inspect_recording(args.input, starter=args.config_out is not None, base=base)
    print(found.report())
    if args.config_out is None:
        print(f"a starter config, with the system model proposed for these streams: "
              f"gslam inspect {args.input} --config-out my_robot.yaml")
        return 0
    write_result_file(args.config_out, found.starter, checked, flag="--config-out")
    if found.proposal is not None and found.proposal.nothing_to_validate() is None:
        _say(f"wrote {args.config_out}: learn its observers with gslam calibrate {args.input} --config "
              f"{args.config_out} --out learnt.yaml, then gslam map {args.input} --config learnt.yaml --out DIR "
              "--gating on")
    else:
        _say(f"wrote {args.config_out}: gslam map {args.input} --config {args.config_out} --out runs/first_map "
              "(ungated)")
    return 0


def _cmd_map(args: argparse.Namespace) -> int:
    from slam.config import check_given_once, config_files, load_config
    from slam.pipeline.folder import run_map

    overrides = list(args.set or [])
    names = [f"--set {text}" for text in overrides]
    if args.gating is not None:
        overrides.append(f"validation.mode={args.gating}")
        names.append(f"--gating {args.gating}")
    check_given_once(overrides, names)
    config_path = _config_path(args.config)
    config = load_config(config_path, overrides)
    res = run_map(args.input, config, args.out, progress=not args.quiet, inputs=config_files(config_path),
                  force=args.force)
    _print_metrics(res.out_dir, res.metrics)
    return 0


def _cmd_compare(args: argparse.Namespace) -> int:
    from slam.commands.compare import run_compare

    res = run_compare(args.input, _config_path(args.config), args.out, _config_path(args.variants), args.only,
                      args.set or [], progress=not args.quiet, force=args.force, command=args.command_line)
    print((res.out_dir / "comparison.md").read_text())
    _say(f"wrote {res.out_dir}" + _report_hint(res.out_dir))
    _warn_self_checks(res.results)
    return 0


def _report_hint(folder: Path) -> str:
    """A pointer to ``report.html`` where the folder has one, else nothing."""
    page = folder / "report.html"
    return f"; open {page} in a browser for the tables and figures" if page.is_file() else ""


def _cmd_demo(args: argparse.Namespace) -> int:
    from slam.commands.demo import run_demo

    res = run_demo(args.out, _config_path(args.scenario), _config_path(args.config), _config_path(args.variants),
                   args.only, args.seed, progress=not args.quiet, force=args.force, command=args.command_line)
    if res.simulated:
        print(f"simulated {res.run_dir} ({res.duration_s:.1f} s of the mission)")
    else:
        print(f"reused {res.run_dir} (the same scenario and seed)")
    print((res.compare.out_dir / "comparison.md").read_text())
    print(f"result folders, tables and figures in {res.compare.out_dir}" + _report_hint(res.compare.out_dir))
    _warn_self_checks(res.compare.results)
    return 0


def _cmd_ablate(args: argparse.Namespace) -> int:
    from slam.commands.ablate import load_spec, run_ablation

    if args.address is not None and args.backend != "ray":  # read by Ray only: ignored in silence otherwise
        raise GslamError(f"--address {args.address}: a Ray cluster's address, but --backend is {args.backend}; "
                         "give --backend ray, or leave --address out")
    spec_path = _config_path(args.spec)
    spec = load_spec(spec_path, max_seeds=args.seeds, max_jobs=args.max_jobs)
    res = run_ablation(spec, args.out, workers=args.workers, backend=args.backend, address=args.address,
                       progress=not args.quiet, source=str(spec_path), force=args.force)
    print(res.summary.md_path.read_text())
    print(f"{len(res.jobs)} jobs: {len(res.ran)} ran, {len(res.skipped)} already finished, "
          f"{len(res.failed)} failed ({res.wall_s:.1f} s); wrote {res.out_dir}" + _report_hint(res.out_dir))
    for job_id, error in res.failed.items():
        print(f"  failed {job_id}: {error}")
    if res.failed:  # exit 1 says so on standard error too, as every refused command does
        first, n = next(iter(res.failed)), len(res.failed)
        others = len(res.jobs) - n
        print(f"gslam: error: {n} of {len(res.jobs)} jobs failed ({'the first, ' if n > 1 else ''}{first}: "
              f"{_shortened(_one_line(res.failed[first]))}); errors in {res.out_dir / 'failed'}"
              f"{f', the other {others} written' if others else ''}; run the command again to retry", file=sys.stderr)
        return 1
    return 0


def _warn_self_checks(results: dict) -> None:
    """One warning line per variant whose map failed its self-check."""
    from slam.outputs.self_check import warning_line

    for name, res in results.items():
        check = res.metrics.get("self_check")
        if check is not None and check["failed"]:
            print(f"gslam: warning: {name}: {warning_line(check)}", file=sys.stderr)


def _print_metrics(out_dir: Path, metrics: dict) -> None:
    keys = (
        "ate_rmse_m", "ate_rmse_unaligned_m", "rpe_trans_pct", "rpe_rot_deg_per_m", "final_error_m",
        "n_poses", "runtime_s", "realtime_factor", "realtime_factor_unavailable", "alarm_fraction", "detection_delay_s",
        "isolation_precision", "isolation_recall", "validation_time_s",
    )
    shown = {k: metrics[k] for k in keys if k in metrics}
    check = metrics.get("self_check")
    _say(f"wrote {out_dir}")
    if check is not None:
        from slam.outputs.self_check import summary_line, warning_line

        if check["failed"]:
            print(f"gslam: warning: {warning_line(check)}", file=sys.stderr)
        else:
            print(summary_line(check))
    print(json.dumps(shown, indent=2))


def _whole(minimum: int, maximum: int | None = None, why: str = ""):
    """An argparse type: a whole number of at least ``minimum`` (and at most
    ``maximum``, ``why`` saying why)."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got '{text}'") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"expected {minimum} or more, got {value}")
        if maximum is not None and value > maximum:
            raise argparse.ArgumentTypeError(f"expected at most {maximum}, got {value:.3g}: {why}")
        return value

    return parse


_positive = _whole(1)
# at most validation.base.bounds.MAX_SEED (not imported here: parsing the command line needs no pydantic)
_seed = _whole(0, 2**64 - 1, "64 bits of seed name more runs than any sweep draws (a scenario's seed is bounded "
               "alike)")
_workers = _whole(1, 1024, "more processes than any machine runs at once")


def _names(text: str) -> list[str]:
    """An argparse type: comma-separated names, none of them empty."""
    names = [n.strip() for n in text.split(",")]
    if not all(names):
        raise argparse.ArgumentTypeError(f"expected comma-separated variant names, got '{text}'")
    twice = next((n for k, n in enumerate(names) if n in names[:k]), None)
    if twice is not None:  # run once in silence: a slip for another name, most likely
        raise argparse.ArgumentTypeError(f"'{twice}' given twice in '{text}'; give each variant once")
    return names


def _out_path(text: str) -> str:
    if not text.strip():
        raise argparse.ArgumentTypeError("is empty; give a path (an unset shell variable?)")
    if text == "-":  # the shell's word for standard output, which gslam writes no result to
        raise argparse.ArgumentTypeError("'-' would be a file or folder named '-', not standard output, which gslam "
                                         "writes no result to; give a path (./- for one named '-')")
    if text.startswith("~"):
        return _home_expanded(text)
    return text


def _home_expanded(text: str) -> str:
    """An output path starting with '~' as the shell would have written it
    had it expanded it (``--out=~/runs/x``, a quoted path: not expanded),
    where a folder named '~' beside the user's would be made instead; one
    of a user the shell does not know (which it leaves as it is) refused."""
    expanded = os.path.expanduser(text)
    if expanded.startswith("~"):
        user = text.split("/", 1)[0]
        raise argparse.ArgumentTypeError(f"'{text}': cannot expand '{user}' (no such user or no home folder); give "
                                         f"the folder spelled out (./{text} for one named '{user}')")
    return expanded


class _Once(argparse.Action):
    """argparse's store, refusing the option a second time: argparse keeps
    the last in silence (``--out a --out b`` wrote b), where a key given
    twice to ``--set`` is refused."""

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        given = namespace.__dict__.setdefault("_given_once", {})
        if self.dest in given:
            parser.error(f"argument {'/'.join(self.option_strings)}: given twice ({given[self.dest]!r}, then "
                         f"{option_string}={values!r}); the second would silently replace the first: give it once")
        given[self.dest] = values
        setattr(namespace, self.dest, values)


class _Parser(argparse.ArgumentParser):
    """argparse, whose 'expected one argument' says how to give a value
    that starts with '-' (``--clean -5:10`` reads -5:10 as an option), and
    whose options of one value may be given once."""

    def add_argument(self, *args, **kwargs):
        if kwargs.get("action") is None and args and args[0].startswith("-"):
            kwargs["action"] = _Once
        return super().add_argument(*args, **kwargs)

    def error(self, message: str) -> NoReturn:
        flag = re.fullmatch(r"argument (--[\w-]+)(?:/\S+)?: expected one argument", message)
        if flag is not None:
            message += f" (a value that starts with '-' is read as an option: give it as {flag[1]}=VALUE)"
        super().error(message)


def _sub(sub, name: str, help: str, examples: str, common: argparse.ArgumentParser) -> argparse.ArgumentParser:
    return sub.add_parser(name, help=help, description=help, epilog=examples, parents=[common],
                          formatter_class=argparse.RawDescriptionHelpFormatter)


def _add_out(parser: argparse.ArgumentParser, what: str, **kwargs) -> None:
    parser.add_argument("--out", type=_out_path, help=f"{what}; see the --out rule below", **kwargs)
    parser.add_argument("--force", action="store_true",
                        help="add the command's files to an existing folder that is not its result "
                             "(nothing of yours there is replaced; the input never)")


def build_parser() -> argparse.ArgumentParser:
    # -v and -q work before and after the command; SUPPRESS keeps a flag
    # given before it from being reset by the command's parser.
    common = _Parser(add_help=False)
    common.add_argument("-v", "--verbose", action="store_true", default=argparse.SUPPRESS, help="log progress details")
    common.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS, help="no progress bars")
    p = _Parser(
        prog="gslam",
        description="Offline SLAM (GTSAM) with sensor validation that gates each factor per time step.",
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    p.add_argument("--version", action="version",
                   version=f"gslam {__version__} (gated-slam, Python {platform.python_version()})")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    d = _sub(sub, "demo", "simulate the Telemax lab mission, map it ungated, gated and with the oracle",
             "examples:\n  gslam demo\n  gslam demo --out runs/demo_all --only "
             "ungated,gated,oracle,huber,cauchy,dcs,gnc_tls,gnc_gm --seed 2\n\n" + OUTPUT_RULE, common)
    _add_out(d, "demo folder (default runs/demo): the simulated run and the comparison", default="runs/demo")
    d.add_argument("--scenario", default=None, help="scenario YAML (default: the shipped configs/scenarios/telemax_lab.yaml)")
    d.add_argument("--config", default=None, help="pipeline config YAML (default: the shipped configs/telemax.yaml)")
    d.add_argument("--variants", default=None, help="variants YAML (default: the shipped configs/variants.yaml)")
    d.add_argument("--only", type=_names, default="ungated,gated,oracle", help="variants to run (default ungated,gated,oracle)")
    d.add_argument("--seed", type=_seed, default=None, help="random seed (default: the scenario's)")
    d.set_defaults(func=_cmd_demo)

    s = _sub(sub, "simulate", "simulate a scenario into a ROS 2 bag plus true fault intervals",
             "example:\n  gslam simulate configs/scenarios/telemax_lab.yaml --out runs/lab --seed 1\n\n" + OUTPUT_RULE,
             common)
    s.add_argument("scenario", help="scenario YAML (e.g. configs/scenarios/telemax_lab.yaml)")
    _add_out(s, "run folder to create (bag/, truth.json, scenario.yaml)", required=True)
    s.add_argument("--seed", type=_seed, default=None, help="random seed (default: the scenario's)")
    s.set_defaults(func=_cmd_simulate)

    j = _sub(sub, "inject", "add physically modelled faults to a recording; write it with its true fault intervals",
             "examples:\n  gslam inject $GSLAM_DATA/carmen/aces-corrected.log.gz --fault laser_cut@300:500,range_m=4 "
             "--out runs/aces_cut\n  gslam inject $GSLAM_DATA/rosbag/test1_husky_2015.bag --config configs/datasets/husky.yaml "
             "--fault dipole@100:120,moment_A_m2=2000,distance_m=3 --out runs/husky_dipole\n"
             "  gslam map runs/aces_cut --config configs/datasets/carmen.yaml --out runs/aces_cut_map --gating on\n\n"
             "fault kinds (times in s from the recording's start; parameters in slam/commands/inject/spec.py):\n"
             "  dipole@T0:T1[,moment_A_m2=500,distance_m=2,side=left,height_m=0,azimuth_deg=90,target=auto,label_deg=5]\n"
             "  laser_cut@T0:T1[,range_m=4]   gyro_bias@T0:T1[,bias_deg_s=2]   slip@T0:T1[,scale=1.5,yaw_scale=1]\n"
             "  multipath@T0:T1[,bias_m=8,azimuth_deg=0]\n\n" + OUTPUT_RULE, common)
    j.add_argument("input", help="recording to add faults to: a ROS 1 .bag or ROS 2 bag, a run folder "
                   "(truth.json + bag/), a CARMEN .log or .log.gz, or a BROAD trial .mat")
    j.add_argument("--config", default=None, help="pipeline config YAML whose input section reads the recording "
                   "(topics, frames; default: the built-in defaults)")
    j.add_argument("--fault", action="append", metavar="KIND@T0:T1[,param=value]", help="a fault to add (repeatable)")
    _add_out(j, "run folder to create (bag/ with the recording, truth.json)", required=True)
    j.set_defaults(func=_cmd_inject)

    k = _sub(sub, "calibrate", "learn the observers' relation models and parameters from recorded runs",
             "examples:\n  gslam calibrate runs/lab_clean --config configs/telemax.yaml --out calibrated.yaml\n"
             "  gslam calibrate robot.bag --config my_robot.yaml --clean 0:120 --out my_robot_calibrated.yaml\n"
             "  gslam map other.bag --config my_robot_calibrated.yaml --out runs/other --gating on\n\n"
             "--out must be a new file, or an earlier calibrate result (its first line says so), which is\n"
             "replaced; --force replaces a file another gslam command wrote, never one of yours. Never a\n"
             "run, a file inside a run folder, or the config.", common)
    k.add_argument("runs", nargs="+", metavar="RUN", help="recorded runs to learn from (any input gslam map reads)")
    k.add_argument("--config", required=True, help="pipeline config whose observers are calibrated (its input "
                   "section reads the runs, its validation section names the relations and the pass)")
    k.add_argument("--clean", default=None, metavar="START:END",
                   help="seconds of every run declared clean (END may be 'end'); default: whole runs, robust statistics")
    k.add_argument("--false-alarm", type=float, default=0.005, metavar="SHARE",
                   help="target share of a run's validation steps with a false alarm (default 0.005)")
    k.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a config key (repeatable)")
    k.add_argument("--lag-reference", default="gyro", choices=["gyro", "odometry", "compass", "scan", "none"],
                   help="the stream the yaw streams' time offsets are measured against (default gyro; none: "
                        "measure none, keep input.time_offsets_s as configured)")
    k.add_argument("--out", required=True, type=_out_path, metavar="MODEL.yaml", help="the calibrated config to write")
    k.add_argument("--keep-unsupported", action="store_true",
                   help="keep the relations whose streams the data show not to move together (default: drop them, "
                        "with the reason in the file)")
    k.add_argument("--force", action="store_true",
                   help="replace --out if another gslam command wrote it (never a file of yours)")
    k.set_defaults(func=_cmd_calibrate)

    i = _sub(sub, "inspect", "list what a recording holds (topics, types, counts, rates, time span); "
             "write a starter config for gslam map with the system model proposed for its streams",
             "examples:\n  gslam inspect recording.bag\n  gslam inspect recording.bag --config-out my_robot.yaml\n"
             "  gslam calibrate recording.bag --config my_robot.yaml --out learnt.yaml\n"
             "  gslam map recording.bag --config learnt.yaml --out runs/gated --gating on\n"
             "  gslam inspect recording.bag --config mine.yaml --config-out mine_proposed.yaml", common)
    i.add_argument("input", help=INPUTS)
    i.add_argument("--config", default=None, help="a config to build the starter on: its input and other sections "
                   "kept, its validation model, observers and gating factors proposed for the recording's streams "
                   "(default: topics guessed from a bag, the shipped config for the other formats)")
    i.add_argument("--config-out", default=None, type=_out_path, metavar="FILE",
                   help="write a commented starter config for gslam map with the topics filled in and the system "
                        "model proposed (a new file, or an earlier one gslam inspect wrote)")
    i.add_argument("--force", action="store_true", help="replace FILE of --config-out if another gslam command wrote it")
    i.set_defaults(func=_cmd_inspect)

    m = _sub(sub, "map", "map a recorded or simulated run and evaluate it",
             "examples:\n  gslam map runs/lab --config configs/telemax.yaml --out runs/lab_map\n"
             "  gslam map runs/lab --config configs/telemax.yaml --out runs/x --set backend.factors.gps.enabled=false\n"
             "  gslam map recording.bag --config my_robot.yaml --out runs/real\n\n" + OUTPUT_RULE, common)
    m.add_argument("input", help=INPUTS)
    m.add_argument("--config", required=True, help="pipeline config YAML (e.g. configs/telemax.yaml; "
                   "gslam inspect INPUT --config-out FILE writes a starter)")
    _add_out(m, "result folder", required=True)
    m.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a config key (repeatable)")
    m.add_argument("--gating", choices=[mode.value for mode in GatingMode], default=None,
                   help="off: every factor in; on: sensor validation gates factors (offline or causal as "
                        "validation.pass says; offline by default); oracle: the tight oracle, from ground truth: "
                        "each degree of freedom of a measurement off by more than validation.oracle_k_sigma sigmas "
                        "is excluded; interval_oracle: each component's factors gated over its true fault "
                        "intervals (default: the config's validation.mode)")
    m.set_defaults(func=_cmd_map)

    c = _sub(sub, "compare", "run ungated, gated, oracle and robust-kernel variants on the same run",
             "examples:\n  gslam compare runs/lab --config configs/telemax.yaml --out runs/lab_compare\n"
             "  gslam compare runs/lab --config configs/telemax.yaml --out runs/x --only ungated,gated\n\n"
             + OUTPUT_RULE, common)
    c.add_argument("input", help=INPUTS)
    c.add_argument("--config", required=True, help="pipeline config YAML")
    _add_out(c, "comparison folder: one result folder per variant, tables, figures", required=True)
    c.add_argument("--variants", default=None, help="variants YAML (default: the shipped configs/variants.yaml)")
    c.add_argument("--only", type=_names, default=None, help="comma-separated subset of the variants")
    c.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a config key for every variant")
    c.set_defaults(func=_cmd_compare)

    a = _sub(sub, "ablate", "run a sweep of configs, scenarios and seeds (resumable; local or Ray)",
             "examples:\n  gslam ablate configs/ablations/gating_policy.yaml --out runs/ablate_gating\n"
             "  gslam ablate configs/ablations/paper_parameters.yaml --out runs/pp --workers 2 --seeds 3\n"
             "  gslam ablate SPEC.yaml --out /shared/runs/x --backend ray --address auto\n\n" + OUTPUT_RULE
             + "\nRunning again into the same sweep folder skips the finished jobs.", common)
    a.add_argument("spec", help="ablation spec YAML (e.g. configs/ablations/gating_policy.yaml)")
    _add_out(a, "sweep folder; running again skips finished jobs", required=True)
    a.add_argument("--workers", type=_workers, default=None, help="parallel jobs (default: CPU count)")
    a.add_argument("--backend", choices=["local", "ray"], default="local",
                   help="local: process pool; ray: one Ray task per job (pip install \".[ray]\")")
    a.add_argument("--address", default=None, help="Ray cluster address (e.g. auto); default: a local Ray instance")
    a.add_argument("--seeds", type=_positive, default=None, help="only the first N seeds of each scenario (a quick look)")
    a.add_argument("--max-jobs", type=_positive, default=None, metavar="N",
                   help="run a spec of more than 10,000 jobs (a larger count is refused before anything runs)")
    a.set_defaults(func=_cmd_ablate)
    return p


_NO_WORKING_FOLDER = ("the current folder no longer exists (removed while a shell was in it); cd to a folder that "
                      "does and run again")


def _working_folder_exists() -> bool:
    """False when the current folder was removed: os.getcwd's error names no file."""
    try:
        os.getcwd()
    except FileNotFoundError:
        return False
    return True


def _as_given_or_escaped(err: UnicodeError) -> tuple[str | bytes, int]:
    """Encoding errors on the terminal: a path's bytes that were no text in
    the locale (Python holds them as lone surrogates) go out as the bytes
    the user gave, as the shell shows them; any other character the
    terminal cannot encode as a backslash escape."""
    if not isinstance(err, UnicodeEncodeError):
        raise err
    part = err.object[err.start : err.end]
    if all(0xDC80 <= ord(c) <= 0xDCFF for c in part):
        return bytes(ord(c) - 0xDC00 for c in part), err.end
    return codecs.backslashreplace_errors(err)


_TERMINAL_ERRORS = "gslam-terminal"
codecs.register_error(_TERMINAL_ERRORS, _as_given_or_escaped)


def main(argv: list[str] | None = None) -> int:
    received: list[int] = []
    try:
        # From the first line: a Ctrl-C while the arguments are read, or
        # the result reported, ends the command as one during its work does.
        with as_interrupt(received):
            return _command(argv, received)
    except Terminated as e:
        return _stopped(e.signum)
    except KeyboardInterrupt:  # raised by a library, or before the handlers were set
        return _stopped(signal.SIGINT)


def _command(argv: list[str] | None, received: list[int]) -> int:
    """The command of ``argv`` run, its errors as one line each; ``received``:
    the signals that came while it ran (see :func:`main`)."""
    args = build_parser().parse_args(argv)
    args.command_line = shlex.join(["gslam", *(sys.argv[1:] if argv is None else argv)])  # as results name it
    stderr = logging.StreamHandler()
    stderr.setFormatter(_WarningLines("%(levelname)s %(name)s: %(message)s"))
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, handlers=[stderr])
    warnings.showwarning = _show_warning
    if not _working_folder_exists():  # libraries fail on it, some by ending the process (oneMKL, loading Open3D)
        print(f"gslam: error: {_NO_WORKING_FOLDER}", file=sys.stderr)
        return 1
    for stream in (sys.stdout, sys.stderr):  # a Latin-1 terminal cannot encode a path named in Greek
        if hasattr(stream, "reconfigure"):
            stream.reconfigure(errors=_TERMINAL_ERRORS)
    if sys.stdout is not None and not isinstance(sys.stdout, _WatchedStdout):
        sys.stdout = _WatchedStdout(sys.stdout)
    try:
        try:
            with plot_home():
                code = args.func(args)
        except Exception:
            if received:  # the signal's exception turned into another on its way (an import it interrupted)
                return _stopped(received[0])
            raise
        # A signal whose exception was swallowed where Python cannot raise
        # (a destructor, a callback) and came again too late stopped
        # nothing: the command finished.
        return _stopped(received[0]) if received else code
    except InputError as e:
        print(f"gslam: error: {_shortened(_one_line(str(e)))}", file=sys.stderr)
        return 1
    except BrokenPipeError:  # the reader left (gslam inspect ... | head): no more to say
        return reader_left()
    except OSError as e:  # the machine, not the input: a full disk, a vanished folder
        if e.filename is None and getattr(sys.stdout, "failed", False):  # gslam ... > /dev/full
            sys.stdout = open(os.devnull, "w")  # the interpreter's last flush must not fail either
            print(f"gslam: error: standard output: {e.strerror or e}", file=sys.stderr)
            return 1
        if e.filename is None and not _working_folder_exists():  # removed while gslam ran
            print(f"gslam: error: {_NO_WORKING_FOLDER}", file=sys.stderr)
            return 1
        where = f"{e.filename}: " if e.filename else ""
        print(f"gslam: error: {_shortened(_one_line(f'{where}{e.strerror or e}'))}", file=sys.stderr)
        return 1
    except MemoryError as e:
        print(f"gslam: error: not enough memory ({_one_line(str(e)) or 'MemoryError'})", file=sys.stderr)
        return 1


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A Python warning (numpy's overflow, a library's deprecation) as one
    line naming where it arose, like the command's own warnings, instead of
    the interpreter's two lines quoting the source."""
    stream = file if file is not None else sys.stderr
    if stream is None:
        return
    try:
        stream.write(f"gslam: warning: {_one_line(str(message))} ({category.__name__}, "
                     f"{Path(filename).name}:{lineno})\n")
    except (OSError, ValueError):  # stderr closed or gone: nowhere to say it
        pass


def _stopped(signum: int) -> int:
    """The line and exit code of a command stopped by a signal."""
    if signum == signal.SIGINT:
        print("gslam: interrupted", file=sys.stderr)
    else:
        print(f"gslam: terminated ({signal.Signals(signum).name})", file=sys.stderr)
    return 128 + signum


class _WatchedStdout:
    """Standard output that remembers whether a write to it failed, so that
    a full or vanished stdout is told apart from the machine's other errors."""

    def __init__(self, stream):
        self.stream, self.failed = stream, False

    def write(self, text: str) -> int:
        try:
            return self.stream.write(text)
        except OSError:
            self.failed = True
            raise

    def flush(self) -> None:
        try:
            self.stream.flush()
        except OSError:
            self.failed = True
            raise

    def __getattr__(self, name: str):
        return getattr(self.stream, name)


INVISIBLE = ("Cc", "Cf", "Zl", "Zp", "Zs")
"""Unicode categories written as escapes in a line gslam says: control
characters, format characters (a zero-width space, a right-to-left
override that reorders what follows) and separators other than the ASCII
space (a no-break space)."""


def _one_line(text: str) -> str:
    """``text`` on one line, its control and invisible characters written as
    escapes: a key or a file name holding ESC sequences would otherwise clear
    or retitle the user's terminal, and a key with a zero-width space or a
    no-break space in it would show as the key it is not."""
    text = " ".join(text.split("\n"))
    if text.isprintable():
        return text
    return "".join(_escaped(c) if unicodedata.category(c) in INVISIBLE and c not in " \t" else c for c in text)


def _escaped(c: str) -> str:
    return f"\\x{ord(c):02x}" if ord(c) <= 0xFF else f"\\u{ord(c):04x}" if ord(c) <= 0xFFFF else f"\\U{ord(c):08x}"


LONGEST_WORD = 400
"""Characters of one word of an error line shown whole: a key, a name or a
value of the input echoed back (a 1 MB key was a 1 MB line)."""


def _shortened(line: str) -> str:
    """``line`` with each word longer than :data:`LONGEST_WORD` cut to its
    start and end and its length, so that an echoed input leaves the
    message readable."""
    words = line.split(" ")
    return " ".join(w if len(w) <= LONGEST_WORD else f"{w[:200]}...({len(w):,} characters)...{w[-60:]}" for w in words)


class _WarningLines(logging.Formatter):
    """Warnings and errors logged as the error line is written: one line,
    control characters escaped, an echoed input cut to its start and end
    (a scenario or file name holding ESC sequences, a key of a megabyte)."""

    def format(self, record: logging.LogRecord) -> str:
        text = super().format(record)
        return _shortened(_one_line(text)) if record.levelno >= logging.WARNING else text


def _say(text: str) -> None:
    """A result line on stdout, one line whatever the paths in it hold."""
    print(_one_line(text))


INTERRUPTED = tuple(128 + s for s in STOPS)


def run() -> None:
    """The ``gslam`` command: :func:`main`, then a quick exit. A finished
    command has written, closed and renamed its results and reaped its
    processes; what a normal exit adds is tearing down every module and
    object (a tenth of a second after ``gslam map``), which ending the
    process does at once. An interrupted command runs the exit handlers
    first: what it stopped (a sweep's process pool, a Ray instance) ends
    with them. The teardown is left out for it too: a library whose import
    the signal cut short could crash in it (a double free) or change the
    exit code; a second Ctrl-C meanwhile is ignored, as it would only cut
    the exit handlers short with a traceback."""
    code = main()
    if code in INTERRUPTED:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        atexit._run_exitfuncs()
        gc.collect()  # what only its collection cleans up (a pool's semaphores), as a normal exit would
    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        try:
            if stream is not None:  # None: started with the stream closed (gslam ... >&-)
                stream.flush()
        except (OSError, ValueError):  # a closed pipe (gslam ... | head) or stream
            pass
    os._exit(code)


if __name__ == "__main__":
    run()
