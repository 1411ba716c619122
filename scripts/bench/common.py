"""What the benches share: paths, the robust-kernel variants they compare
against, simulated inputs, config building, Markdown tables, and the
results page each bench writes into ``docs/results/``."""

from __future__ import annotations

import copy
import csv
import datetime
import io
import logging
import os
import platform
import shlex
import subprocess
from collections.abc import Sequence
from importlib import metadata
from pathlib import Path

import yaml

from slam.host import cpu_info
from slam.results.atomic import write_text

REPO = Path(__file__).resolve().parents[2]
RESULTS = REPO / "docs" / "results"
CONFIGS = REPO / "configs"
KERNELS = ("huber", "cauchy", "dcs", "gnc_tls", "gnc_gm")
"""The robust-kernel variants of ``configs/variants.yaml`` (all ungated)."""
HUSKY_BAG = Path("rosbag") / "test1_husky_2015.bag"
"""The Husky bag, under the data folder."""


def carmen_log(data: Path, name: str) -> Path:
    """CARMEN log ``name`` (``intel``, ``freiburg-079`` ...) under the data folder ``data``."""
    return data / "carmen" / f"{name}-corrected.log.gz"


PACKAGES = ("numpy", "gtsam", "kiss-icp", "rosbags", "python-sat")


def quiet_logging(fmt: str = "%(message)s") -> None:
    """The bench's own progress on stderr; the pipeline's INFO lines left out."""
    logging.basicConfig(level=logging.INFO, format=fmt)
    for noisy in ("slam", "validation"):
        logging.getLogger(noisy).setLevel(logging.ERROR)


def table(header: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    """A Markdown table; cells are written as given (format them first)."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join("–" if c is None else str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def csv_text(rows: Sequence[dict], fieldnames: Sequence[str] | None = None) -> str:
    """Rows as CSV with a header (default columns: the first row's keys)."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(fieldnames or rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return buf.getvalue()


def machine() -> str:
    """One line: CPU (with its family, model and widest vector unit: two
    machines both called "AMD EPYC" can be a generation apart, and numpy
    and the compiled kernels then take other code paths, which round
    differently; a map that hangs on one weak match can then differ),
    cores, memory, Python and the main packages' versions."""
    cpu = platform.processor() or platform.machine()
    mem_kib = 0
    try:
        info = cpu_info()
        cpu = info.get("model name", cpu)
        if "cpu family" in info and "model" in info:
            flags = set(info.get("flags", "").split())
            vector = next((v for v, f in (("AVX-512", "avx512f"), ("AVX2", "avx2")) if f in flags), "no AVX2")
            cpu += f" (family {info['cpu family']} model {info['model']}, {vector})"
        mem_kib = int(Path("/proc/meminfo").read_text().split()[1])
    except (OSError, ValueError, IndexError):
        pass
    versions = []
    for p in PACKAGES:
        try:
            versions.append(f"{p} {metadata.version(p)}")
        except metadata.PackageNotFoundError:
            pass
    return (f"{cpu}, {os.cpu_count()} cores, {mem_kib / 2**20:.0f} GiB, Python {platform.python_version()}, "
            + ", ".join(versions))


def commit() -> str:
    """The checked-out commit, marked when the tree has uncommitted changes."""
    try:
        rev = subprocess.run(["git", "rev-parse", "--short=10", "HEAD"], cwd=REPO, capture_output=True, text=True,
                             check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", "slam", "validation",
                                "configs", "scripts"], cwd=REPO, capture_output=True, text=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown (not a git checkout)"
    return f"{rev} (with uncommitted changes)" if dirty else rev


def publish(name: str, title: str, body: str, argv: Sequence[str] | None, bench: str | None = None) -> Path:
    """Write ``docs/results/NAME.md``: ``title``, a header naming the
    command (``python -m scripts.bench BENCH ARGV``, BENCH defaulting to
    NAME), commit, machine and date, then ``body`` (Markdown)."""
    path = RESULTS / f"{name}.md"
    path.parent.mkdir(parents=True, exist_ok=True)
    write_text(path, stamped(title, body, argv, bench or name))
    print(f"wrote {path.relative_to(REPO)}")
    return path


def stamped(title: str, body: str, argv: Sequence[str] | None, bench: str) -> str:
    """A results page: ``title``, the header naming the command
    (``python -m scripts.bench BENCH ARGV``), commit, machine and date,
    then ``body``."""
    command = " ".join(["python -m scripts.bench", bench, *map(shlex.quote, argv or [])])
    date = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    header = (f"# {title}\n\n"
              f"Written by `{command}` at commit {commit()}, {date}, on {machine()}. "
              "Generated: run the command again rather than editing this page.\n\n")
    return header + body.rstrip("\n") + "\n"


ROWS_MEASURED = "These rows were measured by"
"""How a page summarised from earlier runs' rows (one run or several) begins to say so."""


def include_in_readme(name: str) -> None:
    """Copy the first table of ``docs/results/NAME.md``, with the line
    naming its command, commit and date, into ``README.md`` between the
    markers ``<!-- results/NAME -->`` and ``<!-- /results/NAME -->``."""
    page = (RESULTS / f"{name}.md").read_text().splitlines()
    written = next(line for line in page if line.startswith("Written by "))
    start = next(i for i, line in enumerate(page) if line.startswith("| "))
    end = next((i for i in range(start, len(page)) if not page[i].startswith("|")), len(page))
    # A page summarised from earlier rows says where they were measured.
    measured = [line for line in page[:start] if line.startswith(ROWS_MEASURED)]
    block = "\n".join([*page[start:end], "", written.split(", on ")[0] + ".", *measured])
    readme = REPO / "README.md"
    text = readme.read_text()
    begin, close = f"<!-- results/{name} -->", f"<!-- /results/{name} -->"
    if begin not in text or close not in text:
        return
    head, rest = text.split(begin, 1)
    write_text(readme, head + begin + "\n" + block + "\n" + close + rest.split(close, 1)[1])


def simulated(cache: Path, scenario: str, seed: int, laps: int | None = None) -> Path:
    """The run folder of ``configs/scenarios/SCENARIO.yaml`` with ``seed``
    (and, for a looping scenario, ``laps`` laps), simulated into ``cache``
    once and reused after."""
    from slam.sim import load_scenario, simulate_scenario

    out = cache / (f"{scenario}_s{seed}" + (f"_{laps}laps" if laps is not None else ""))
    if (out / "truth.json").exists():
        return out
    loaded = load_scenario(CONFIGS / "scenarios" / f"{scenario}.yaml")
    tree = loaded.model_dump()
    tree["seed"] = seed
    if laps is not None:
        tree["robot"]["laps"] = laps
    simulate_scenario(type(loaded).model_validate(tree), out)
    return out


def base_config(config_path: Path, added: list[dict], folder: Path, off: tuple[str, ...] = ()) -> Path:
    """The dataset config with ``added`` relations (and their model lines)
    beside its own and the checks ``off`` turned off."""
    tree = yaml.safe_load(config_path.read_text())
    tree = copy.deepcopy(tree)
    for check in off:
        tree["validation"]["observers"].setdefault(check, {})["enabled"] = False
    model_path = (config_path.parent / tree["validation"]["model"]).resolve()
    model = yaml.safe_load(model_path.read_text())
    for rel in added:
        tree["validation"]["observers"]["relations"].append(rel)
        model["relations"][rel["name"]] = ["IMU_YAW", "IMU_GYRO"]
    tree["validation"]["model"] = model
    out = folder / f"base_{len(list(folder.glob('base_*')))}.yaml"
    out.write_text(yaml.safe_dump(tree, sort_keys=False))
    return out
