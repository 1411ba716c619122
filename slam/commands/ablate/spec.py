"""The ablation spec: which inputs, which base config, which variants and
which sweeps (``gslam ablate SPEC.yaml``).

Every model forbids unknown keys, so a typo in a spec stops before any job
runs, with one line naming the spec file and the key. Paths in a spec are
relative to the spec file. A sweep key is a dotted path into the pipeline
config (``gating.inflation``) or, with the prefix ``scenario.``, into the
scenario of a simulated input (``scenario.sensors.gyro.noise_rad_s``). A
path segment that meets a list selects elements by index (``0``), by their
``name`` field (``yaw_compass_gyro``) or by a glob over names (``yaw_*``,
``*``); see :func:`slam.commands.ablate.jobs.set_path`.
"""

from __future__ import annotations

import math
import os
import unicodedata
from pathlib import Path
from typing import Annotated, Any

import yaml
from pydantic import Discriminator, Field, Tag, ValidationError, ValidationInfo, field_validator, model_validator

from slam.config import describe_validation_error
from validation.base.yamlio import load_yaml
from slam.errors import GslamError
from slam.readers.files import check_exists
from slam.results.out_checks import resolve_path
from slam.results.records import PLAIN_NAME, PLAIN_NAME_RULE
from validation.base import bounds
from validation.base.yamlio import StrictFrozen, yaml_kind

SCENARIO_PREFIX = "scenario."


INT64_MAX = 2**63 - 1

Seed = Annotated[int, bounds.SEED]
Samples = Annotated[int, bounds.SAMPLES]
SweptNumber = Annotated[float, bounds.SWEPT_NUMBER]


class Distribution(StrictFrozen):
    """One randomly sampled parameter: exactly one of ``uniform: [lo, hi]``,
    ``log_uniform: [lo, hi]``, ``integer: [lo, hi]`` (inclusive) or
    ``choice: [values]``."""

    uniform: tuple[SweptNumber, SweptNumber] | None = None
    log_uniform: tuple[SweptNumber, SweptNumber] | None = None
    integer: tuple[int, int] | None = None
    choice: list[Any] | None = Field(None, min_length=1)

    @field_validator("integer")
    @classmethod
    def _int64(cls, bounds: tuple[int, int] | None) -> tuple[int, int] | None:
        """numpy draws integers of 64 bits: a bound beyond them raised in the draw."""
        if bounds is not None and any(abs(b) > INT64_MAX for b in bounds):
            raise ValueError(f"[{bounds[0]:.3g}, {bounds[1]:.3g}] reaches beyond a 64-bit integer (+-{INT64_MAX:.3g}), "
                             "which numpy draws; no count a config holds comes near it")
        return bounds

    @model_validator(mode="after")
    def _exactly_one(self) -> "Distribution":
        given = [k for k in ("uniform", "log_uniform", "integer", "choice") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError("give exactly one of uniform, log_uniform, integer, choice")
        lo_hi = self.uniform or self.log_uniform or self.integer
        if lo_hi is not None and lo_hi[0] > lo_hi[1]:
            raise ValueError("the lower bound exceeds the upper bound")
        if self.log_uniform is not None and self.log_uniform[0] <= 0:
            raise ValueError("log_uniform bounds must be > 0")
        return self


class RandomSweep(StrictFrozen):
    """``samples`` points drawn with ``seed`` (the same spec draws the same
    points), each parameter independently."""

    samples: Samples
    seed: Seed = 0
    params: dict[str, Distribution] = Field(min_length=1)


Axis = Annotated[list[Any], Field(min_length=1)]
"""The values one key is swept over: an empty list would sweep nothing and
leave the key at the config's value in silence."""


def _grid_form(value: Any) -> str:
    return "[list]" if isinstance(value, list) else "[mapping]"


# One grid or a list of them, told apart by their form as Seeds are below,
# so that an error names the key of the form given (sweep.grid.1.KEY).
Grid = Annotated[
    Annotated[dict[str, Axis], Tag("[mapping]")] | Annotated[list[dict[str, Axis]], Tag("[list]")],
    Discriminator(_grid_form),
]


_NONE = object()


def _same_value(a: Any, b: Any) -> bool:
    """One value to a config: 2 and 2.0 are; true and 1 are not (YAML's truth values are no numbers)."""
    return a == b and isinstance(a, bool) == isinstance(b, bool)


def _shown(value: Any) -> str:
    return yaml.safe_dump(value, default_flow_style=True).split("\n")[0].removesuffix(" ...")


class SweepSpec(StrictFrozen):
    """``grid``: a mapping key -> values (their full product), or a list of
    such mappings (the union of their products: one-at-a-time sweeps).
    ``random``: seeded random samples. With both, every grid point is
    combined with every random sample."""

    grid: Grid = Field(default_factory=dict)
    random: RandomSweep | None = None

    @model_validator(mode="after")
    def _values_once(self) -> "SweepSpec":
        """A value given twice on one axis (``[2, 2.0]``) would be one job
        in silence where the spec asks for two, while a seed given twice is
        refused: refused alike."""
        for i, grid in enumerate(self.grids()):
            for key, values in grid.items():
                for k, value in enumerate(values):
                    same = next((v for v in values[:k] if _same_value(v, value)), _NONE)
                    if same is not _NONE:
                        where = f"grid.{i}.{key}" if isinstance(self.grid, list) else f"grid.{key}"
                        raise ValueError(f"{where}: {_shown(same)} and {_shown(value)} are one value, so two jobs "
                                         "would compute the same thing; give each value once")
        return self

    def grids(self) -> list[dict[str, list[Any]]]:
        return self.grid if isinstance(self.grid, list) else [self.grid]

    def keys(self) -> list[str]:
        keys: list[str] = []
        for g in self.grids():
            keys += [k for k in g if k not in keys]
        if self.random is not None:
            keys += [k for k in self.random.params if k not in keys]
        return keys


class SeedRange(StrictFrozen):
    """``count`` consecutive seeds from ``first``."""

    first: Seed = 1
    count: Samples

    @model_validator(mode="after")
    def _last_seed(self) -> "SeedRange":
        if self.first + self.count - 1 > bounds.MAX_SEED:
            raise ValueError(f"the last seed, {self.first + self.count - 1}, is above {bounds.MAX_SEED}: "
                             "64 bits of seed name more runs than any sweep draws (bounded as a scenario's seed)")
        return self

    def seeds(self) -> list[int]:
        return list(range(self.first, self.first + self.count))


def _seeds_form(value: Any) -> str:
    return "[range]" if isinstance(value, (dict, SeedRange)) else "[list]"


# A list of seeds or a range, told apart by their form, so that an error
# names the key of the form given (seeds.count), not both forms' failures.
# The tags hold brackets: describe_validation_error leaves them out of keys.
Seeds = Annotated[
    Annotated[list[Seed], Field(min_length=1, max_length=1_000_000), Tag("[list]")]
    | Annotated[SeedRange, Tag("[range]")],
    Discriminator(_seeds_form),
]


class ScenarioInput(StrictFrozen):
    """A scenario YAML simulated once per seed (``seeds``: a list or a
    range). ``sweep``, if given, replaces the spec's sweep for this input
    (e.g. a scenario parameter only this scenario has)."""

    path: Path
    seeds: Seeds
    sweep: SweepSpec | None = None

    def seed_list(self) -> list[int]:
        return list(self.seeds) if isinstance(self.seeds, list) else self.seeds.seeds()

    def seed_count(self) -> int:
        return len(self.seeds) if isinstance(self.seeds, list) else self.seeds.count

    def first_seeds(self, n: int) -> "ScenarioInput":
        """This input with only its first ``n`` seeds."""
        seeds = self.seeds[:n] if isinstance(self.seeds, list) else self.seeds.model_copy(
            update={"count": min(n, self.seeds.count)})
        return self.model_copy(update={"seeds": seeds})


class RecordedInput(StrictFrozen):
    """A recorded run (bag, log or run folder) used as it is; ``name`` labels
    it in job ids and tables (default: the file name). A path starting with
    ``{data}`` is under the data root (``$GSLAM_DATA``, else
    ``../shared/data``); a ``*`` in the file name makes one input per
    matching file, each labelled by its file name."""

    path: Path
    name: str | None = None
    sweep: SweepSpec | None = None

    @field_validator("name")
    @classmethod
    def _plain_name(cls, name: str | None) -> str | None:
        # it names the input's jobs and its table in summary.md, as a variant's name does
        if name is not None and not PLAIN_NAME.fullmatch(name):
            raise ValueError(f"{name!r}: a recorded input's name names its jobs: {PLAIN_NAME_RULE}")
        return name

    def label(self) -> str:
        return self.name or self.path.name.split(".")[0]


class InputsSpec(StrictFrozen):
    scenarios: list[ScenarioInput] = Field(default_factory=list)
    recorded: list[RecordedInput] = Field(default_factory=list)

    @model_validator(mode="after")
    def _some(self) -> "InputsSpec":
        if not self.scenarios and not self.recorded:
            raise ValueError("at least one scenario or recorded input is needed")
        return self


class AblationSpec(StrictFrozen):
    """Root of an ablation spec (e.g. ``configs/ablations/gating_policy.yaml``).

    ``variants``: name -> dotted overrides (as ``configs/variants.yaml``);
    none given means one variant ``base``. ``set``: overrides for every job.
    ``plots``: write each run's PNG figures, and (unless ``set`` or a
    variant says otherwise) its occupancy grid and ``run.mcap`` (off by
    default: they cost more than a short run's mapping). ``metrics``: the metric columns of
    ``summary.md`` (default: ATE, detection delay, alarm fraction,
    isolation precision and recall, faults missed, runtime).
    """

    name: str = Field(min_length=1)
    description: str = ""
    config: Path
    inputs: InputsSpec
    variants: dict[str, dict[str, Any]] = Field(default_factory=lambda: {"base": {}})
    set: dict[str, Any] = Field(default_factory=dict)
    sweep: SweepSpec = SweepSpec()
    plots: bool = False
    metrics: list[str] | None = None

    @field_validator("name", "description")
    @classmethod
    def _printable(cls, text: str, info: ValidationInfo) -> str:
        """The name is the title of summary.md and report.html, one line; a
        control character there (a NUL, a newline, a terminal escape) would
        break the title or be written into both files."""
        allowed = "" if info.field_name == "name" else "\n\t"
        bad = next((c for c in text if c not in allowed and unicodedata.category(c) in ("Cc", "Zl", "Zp")), None)
        if bad is not None:
            where = "a title of one line" if info.field_name == "name" else "text of lines and tabs"
            raise ValueError(f"holds the control character {bad!r} at character {text.index(bad) + 1}; expected {where}")
        return text

    @field_validator("variants", mode="before")
    @classmethod
    def _names_are_text(cls, variants: Any) -> Any:
        """A name YAML read as something else (``no:`` a truth value) is
        named as YAML read it, not by pydantic's index for it."""
        for key in variants if isinstance(variants, dict) else ():
            if not isinstance(key, str):
                raise ValueError(f"name {_shown(key)}: YAML reads it as {yaml_kind(key)}, not as a name; quote it")
        return variants

    @model_validator(mode="after")
    def _names(self) -> "AblationSpec":
        if not self.variants:
            raise ValueError("variants: at least one variant is needed")
        for name in self.variants:
            # a variant's name is in its jobs' folder names and a row of summary.md
            if not PLAIN_NAME.fullmatch(name):
                raise ValueError(f"variants: name {name!r}: a variant's name names its jobs: {PLAIN_NAME_RULE}")
        for key in self.sweep_keys():
            if not key or key.startswith(".") or key.endswith(".") or ".." in key:
                raise ValueError(f"sweep: '{key}' is not a dotted key")
        return self

    def sweep_keys(self) -> list[str]:
        """Every swept key, of the spec's sweep and the inputs' own."""
        keys = self.sweep.keys()
        for inp in [*self.inputs.scenarios, *self.inputs.recorded]:
            if inp.sweep is not None:
                keys += [k for k in inp.sweep.keys() if k not in keys]
        return keys

    def resolved(self, base_dir: Path) -> "AblationSpec":
        """A copy with every path made absolute against ``base_dir``."""

        def absolute(p: Path) -> Path:
            return p if p.is_absolute() else resolve_path(base_dir / p)

        inputs = InputsSpec(
            scenarios=[s.model_copy(update={"path": absolute(s.path)}) for s in self.inputs.scenarios],
            recorded=[r.model_copy(update={"path": absolute(r.path)}) for r in self.inputs.recorded],
        )
        return self.model_copy(update={"config": absolute(self.config), "inputs": inputs})


DATA_PLACEHOLDER = "{data}"


def _expand_recorded(spec: AblationSpec, source: Path) -> AblationSpec:
    """Resolve ``{data}`` and expand globs in the recorded inputs' paths."""
    from slam.readers.datasets import DATA_ENV, data_root

    base_dir = resolve_path(source).parent
    recorded: list[RecordedInput] = []
    for rec in spec.inputs.recorded:
        text = str(rec.path)
        if text.startswith(DATA_PLACEHOLDER):
            root = data_root()
            if not root.is_dir():
                given = f"{DATA_ENV}={os.environ[DATA_ENV]!r}" if os.environ.get(DATA_ENV) else f"the data root {root}"
                raise GslamError(f"{source}: recorded input {rec.path}: {given} is not a folder; expected the folder "
                                 "holding the data sets (carmen/, broad/, librsf/, rosbag/)")
            text = str(root) + text[len(DATA_PLACEHOLDER):]
        p = Path(text) if Path(text).is_absolute() else base_dir / text
        if not any(c in p.name for c in "*?["):
            recorded.append(rec.model_copy(update={"path": p}))
            continue
        matches = sorted(p.parent.glob(p.name))
        if not matches:
            raise GslamError(f"{source}: recorded input {rec.path}: no file matches {p}")
        recorded += [rec.model_copy(update={"path": m, "name": None}) for m in matches]
    return spec.model_copy(update={"inputs": spec.inputs.model_copy(update={"recorded": recorded})})


DEFAULT_MAX_JOBS = 10_000
"""Most jobs a spec may expand to unless ``--max-jobs`` says more (the
shipped specs have at most a few hundred)."""


def sweep_size(sweep: SweepSpec) -> int:
    """Points of a sweep (at most: repeated grid points count once each
    time), computed without listing them."""
    grid = sum(math.prod(len(v) for v in g.values()) for g in sweep.grids()) or 1
    return grid * (sweep.random.samples if sweep.random is not None else 1)


def job_counts(spec: AblationSpec) -> list[tuple[str, int, str]]:
    """Per input: where it is in the spec, its number of jobs and how that
    number comes about, without expanding anything."""
    variants = len(spec.variants)
    out = []
    for kind, inputs in (("scenarios", spec.inputs.scenarios), ("recorded", spec.inputs.recorded)):
        for i, inp in enumerate(inputs):
            points = sweep_size(inp.sweep if inp.sweep is not None else spec.sweep)
            seeds = inp.seed_count() if isinstance(inp, ScenarioInput) else 1
            where = f"inputs.{kind}.{i}"
            how = (f"{seeds:,} seeds x " if isinstance(inp, ScenarioInput) else "") + \
                f"{variants:,} variants x {points:,} sweep points"
            if inp.sweep is None and spec.sweep.random is not None and points >= sweep_size(spec.sweep):
                how += f" (sweep.random.samples {spec.sweep.random.samples:,})"
            out.append((where, seeds * variants * points, how))
    return out


def check_job_count(spec: AblationSpec, source: str | Path, max_jobs: int | None) -> int:
    """The number of jobs of ``spec``; a one-line error naming the input
    that makes the most if they are more than ``max_jobs`` (default
    :data:`DEFAULT_MAX_JOBS`), before anything is allocated for them."""
    limit = DEFAULT_MAX_JOBS if max_jobs is None else max_jobs
    counts = job_counts(spec)
    total = sum(n for _, n, _ in counts)
    if total > limit:
        where, n, how = max(counts, key=lambda c: c[1])
        raise GslamError(f"{source}: {total:,} jobs, more than {limit:,}; {where} alone makes {n:,} ({how}); "
                         "give fewer, or --max-jobs to allow more")
    return total


def load_spec(path: str | Path, max_seeds: int | None = None, max_jobs: int | None = None) -> AblationSpec:
    """Read and validate an ablation spec; ``max_seeds`` keeps only the first
    seeds of each scenario input (a quick look at a long spec); more jobs
    than ``max_jobs`` (default :data:`DEFAULT_MAX_JOBS`) are refused before
    any is listed. Bad input raises :class:`GslamError` naming the file and
    the key."""
    path = Path(path)
    tree = load_yaml(path, "ablation spec")
    try:
        spec = AblationSpec.model_validate(tree)
    except ValidationError as e:
        raise GslamError(describe_validation_error(str(path), e, "spec", model=AblationSpec)) from None
    if max_seeds is not None:
        scenarios = [s.first_seeds(max_seeds) for s in spec.inputs.scenarios]
        spec = spec.model_copy(update={"inputs": spec.inputs.model_copy(update={"scenarios": scenarios})})
    check_job_count(spec, path, max_jobs)
    spec = _expand_recorded(spec, path)
    check_job_count(spec, path, max_jobs)  # globs may have made more inputs
    spec = spec.resolved(resolve_path(path).parent)
    for p in [spec.config] + [s.path for s in spec.inputs.scenarios] + [r.path for r in spec.inputs.recorded]:
        try:
            check_exists(p)
        except GslamError as e:
            raise GslamError(f"{path}: {e}") from None
    _check_base_config(spec.config, path)
    return spec


SPEC_KEYS = frozenset({"inputs", "variants", "sweep"})
"""Top-level keys of a spec that no pipeline config has."""


def _check_base_config(config: Path, source: Path) -> None:
    """``config`` must be a pipeline config: not the spec itself, nor another
    spec (each would fail later as 'unknown config key name', in a variant)."""
    if config.is_file() and source.is_file() and os.path.samefile(config, source):
        raise GslamError(f"{source}: config names this spec file itself; it must name the pipeline config the jobs "
                         "start from (e.g. config: ../telemax.yaml)")
    tree = load_yaml(config, "config")
    if "name" in tree and SPEC_KEYS & set(tree):
        raise GslamError(f"{source}: config {config} is an ablation spec, not a pipeline config; it must name the "
                         "pipeline config the jobs start from (e.g. config: ../telemax.yaml)")
