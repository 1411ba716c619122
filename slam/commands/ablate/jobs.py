"""Expanding an ablation spec into jobs with stable ids.

A job is one ``gslam map`` run: one input (a simulated scenario and seed, or
a recorded run), one variant and one point of the sweep. Expansion builds
and validates every job's pipeline config and scenario before anything
runs, so a typo in any key stops the sweep at once. A job's id is readable
(input, seed, variant, swept values) with a hash suffix over what the job
computes (the scenario actually simulated, the seed and the config actually
used), so the same spec always gives the same ids and a changed setting a
new one.
"""

from __future__ import annotations

import copy
import fnmatch
import hashlib
import itertools
import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from pydantic import ValidationError

from slam.commands.ablate.spec import SCENARIO_PREFIX, AblationSpec, Distribution, RandomSweep, SweepSpec
from slam.config import describe_validation_error, dump_config, load_config
from slam.config.trees import non_finite, yaml_number
from validation.base.yamlio import load_yaml
from slam.errors import GslamError
from validation.base.errors import InputError
from slam.sim.budget import check_bounded
from slam.sim.scenario import Scenario


@dataclass(frozen=True)
class SimulatedInput:
    """A scenario (its validated YAML tree, seed included) to simulate into
    ``inputs/<key>/`` of the output folder."""

    key: str
    scenario: dict[str, Any]


@dataclass(frozen=True)
class Job:
    """One run: ``input_path`` is a recorded run, or None for ``simulated``."""

    id: str
    input_label: str
    seed: int | None
    variant: str
    params: dict[str, Any]
    config_path: str
    overrides: tuple[str, ...]
    simulated: SimulatedInput | None = None
    input_path: str | None = None
    plots: bool = False

    def input_dir(self, out_dir: Path) -> Path:
        """Where the job reads its run from."""
        if self.simulated is not None:
            return out_dir / "inputs" / self.simulated.key
        return Path(self.input_path)


# --- dotted paths into YAML trees ------------------------------------------------


def set_path(tree: dict[str, Any], dotted: str, value: Any) -> None:
    """Set ``value`` at ``dotted`` in a YAML tree, in place.

    Missing mapping keys are created (the model then rejects unknown ones).
    A segment that meets a list selects elements: an index (``0``), the
    element whose ``name`` is the segment, or every element whose ``name``
    matches a glob (``yaw_*``, ``*``); at least one must match.
    """
    _set(tree, dotted.split("."), value, dotted, [])


def _set(node: Any, keys: list[str], value: Any, dotted: str, done: list[str]) -> None:
    k, rest = keys[0], keys[1:]
    where = ".".join(done) or "the top level"
    if isinstance(node, list):
        targets = _select(node, k, dotted, where)
        if not rest:
            for i in targets:
                node[i] = copy.deepcopy(value)
            return
        for i in targets:
            _set(node[i], rest, value, dotted, done + [k])
        return
    if not isinstance(node, dict):
        raise GslamError(f"key '{dotted}': '{where}' is a value, not a section")
    if not rest:
        node[k] = copy.deepcopy(value)
        return
    if node.get(k) is None:
        node[k] = {}
    _set(node[k], rest, value, dotted, done + [k])


def _select(items: list[Any], segment: str, dotted: str, where: str) -> list[int]:
    if re.fullmatch(r"-?\d+", segment):
        i = int(segment)
        if not -len(items) <= i < len(items):
            raise GslamError(f"key '{dotted}': index {i} is outside '{where}' ({len(items)} elements)")
        return [i % len(items)]
    names = [it.get("name") if isinstance(it, dict) else None for it in items]
    hits = [i for i, n in enumerate(names) if isinstance(n, str) and fnmatch.fnmatchcase(n, segment)]
    if not hits:
        known = ", ".join(n for n in names if isinstance(n, str)) or "no named elements"
        raise GslamError(f"key '{dotted}': no element of '{where}' is named '{segment}' ({known})")
    return hits


def _list_prefix(tree: dict[str, Any], dotted: str) -> str | None:
    """The dotted path of the first list on the way to ``dotted``, if any."""
    keys = dotted.split(".")
    node: Any = tree
    for n, k in enumerate(keys[:-1]):
        node = node.get(k) if isinstance(node, dict) else None
        if isinstance(node, list):
            return ".".join(keys[: n + 1])
        if node is None:
            return None
    return None


def _get(tree: dict[str, Any], dotted: str) -> Any:
    node: Any = tree
    for k in dotted.split("."):
        node = node[k]
    return node


def yaml_value(value: Any) -> str:
    """``value`` as one line of YAML that reads back as the same value."""
    text = yaml.safe_dump(value, default_flow_style=True, width=10**9, sort_keys=False).strip()
    return text[: -len("...")].strip() if text.endswith("...") else text


def config_overrides(base_tree: dict[str, Any], pairs: list[tuple[str, Any]]) -> list[str]:
    """``key=value`` overrides for :func:`slam.config.load_config`. A key
    that goes through a list (which ``load_config`` cannot index) becomes
    one override of the whole list, edited on a copy of ``base_tree``."""
    tree = copy.deepcopy(base_tree)
    rendered: list[tuple[str | None, str, Any]] = []
    for key, value in pairs:
        prefix = _list_prefix(tree, key)
        set_path(tree, key, value)
        rendered.append((prefix, key, value))
    out: list[str] = []
    for prefix, key, value in rendered:
        if prefix is None:
            out.append(f"{key}={yaml_value(value)}")
        else:
            out.append(f"{prefix}={yaml_value(_get(tree, prefix))}")
    return out


# --- sweep points ----------------------------------------------------------------


def sweep_points(sweep: SweepSpec) -> list[dict[str, Any]]:
    """Every point of the sweep, in a fixed order: each grid's product (the
    union over a list of grids, duplicates dropped), each combined with every
    random sample. No sweep gives the one empty point."""
    grid_points: list[dict[str, Any]] = []
    for grid in sweep.grids():
        keys = list(grid)
        for values in itertools.product(*(grid[k] for k in keys)):
            point = dict(zip(keys, values))
            if point not in grid_points:
                grid_points.append(point)
    grid_points = grid_points or [{}]
    if sweep.random is None:
        return grid_points
    samples = random_samples(sweep.random)
    return [{**g, **s} for g in grid_points for s in samples]


def random_samples(sweep: RandomSweep) -> list[dict[str, Any]]:
    """``sweep.samples`` points; the same seed gives the same points."""
    rng = np.random.default_rng(sweep.seed)
    return [{key: _draw(dist, rng) for key, dist in sweep.params.items()} for _ in range(sweep.samples)]


def _draw(dist: Distribution, rng: np.random.Generator) -> Any:
    if dist.uniform is not None:
        return round(float(rng.uniform(*dist.uniform)), 6)
    if dist.log_uniform is not None:
        lo, hi = np.log(dist.log_uniform[0]), np.log(dist.log_uniform[1])
        return float(f"{float(np.exp(rng.uniform(lo, hi))):.6g}")
    if dist.integer is not None:
        return int(rng.integers(dist.integer[0], dist.integer[1] + 1))
    return dist.choice[int(rng.integers(len(dist.choice)))]


# --- jobs ------------------------------------------------------------------------


def _digest(obj: Any, n: int = 8) -> str:
    text = json.dumps(obj, sort_keys=True, default=str)
    return hashlib.sha1(text.encode()).hexdigest()[:n]


def _short(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, (list, dict)):
        return _digest(value, 4)
    return str(value)


def _readable(parts: list[str]) -> str:
    text = "-".join(parts)
    text = re.sub(r"[^A-Za-z0-9._=+-]+", "_", text)
    return text[:120]


def _split(pairs: list[tuple[str, Any]]) -> tuple[list[tuple[str, Any]], list[tuple[str, Any]]]:
    scen = [(k[len(SCENARIO_PREFIX):], v) for k, v in pairs if k.startswith(SCENARIO_PREFIX)]
    conf = [(k, v) for k, v in pairs if not k.startswith(SCENARIO_PREFIX)]
    return scen, conf


def _scenario_tree(path: Path, pairs: list[tuple[str, Any]], where: str) -> dict[str, Any]:
    """The scenario YAML with overrides applied, validated, every default
    spelled out."""
    tree = load_yaml(path, "scenario")
    for key, value in pairs:
        if key == "seed":  # each job's seed replaced it in silence, while summary.md showed the value set
            raise GslamError(f"{where}: scenario.seed: a job's seed is its input's (inputs.scenarios.N.seeds), which "
                             "would replace the value set here in silence; give the seeds there")
        set_path(tree, key, value)
    found = non_finite(tree)
    if found is not None:
        raise GslamError(f"{where}: scenario.{found[0]}: expected a finite number, got {yaml_number(found[1])}")
    try:
        scenario = Scenario.model_validate(tree)
    except ValidationError as e:
        raise GslamError(describe_validation_error(where, e, "scenario", prefix="scenario.", model=Scenario)) from None
    check_bounded(scenario, where)
    return scenario.model_dump(mode="json")


def expand_jobs(spec: AblationSpec, source: str = "spec") -> list[Job]:
    """Every job of ``spec``, each config and scenario validated; ordered by
    input and seed, then variant, then sweep point. ``source`` names the
    spec in error messages."""
    base_tree = load_yaml(spec.config, "config")
    fixed = list(spec.set.items())
    plots = [("output.plots", spec.plots), ("output.progress", False)]
    # A sweep's jobs are read as numbers: their grid and bag follow plots
    # unless the spec sets them.
    viewers = [("output.grid", spec.plots), ("output.mcap", spec.plots)]
    configs: dict[tuple[str, str], tuple[list[str], str, list[tuple[str, Any]]]] = {}

    def config_for(variant: str, point: dict[str, Any]) -> tuple[list[str], str, list[tuple[str, Any]]]:
        key = (variant, json.dumps(point, sort_keys=True, default=str))
        if key not in configs:
            scen, conf = _split(fixed + list(spec.variants[variant].items()) + list(point.items()))
            where = f"{source}: variant '{variant}'" + (f", sweep point {point}" if point else "")
            try:
                strings = config_overrides(base_tree, viewers + conf + plots)
                cfg = load_config(spec.config, strings)
            except InputError as e:
                raise GslamError(f"{where}: {_strip_source(str(e), spec.config)}") from None
            configs[key] = (strings, dump_config(cfg), scen)
        return configs[key]

    jobs: list[Job] = []
    scenario_cache: dict[tuple[str, str], dict[str, Any]] = {}
    for inp in spec.inputs.scenarios:
        points = sweep_points(inp.sweep or spec.sweep)
        for seed in inp.seed_list():
            for variant in spec.variants:
                for point in points:
                    strings, dumped, scen = config_for(variant, point)
                    ck = (str(inp.path), json.dumps(scen, default=str))
                    if ck not in scenario_cache:
                        scenario_cache[ck] = _scenario_tree(inp.path, scen, f"{source}: {inp.path.name}")
                    tree = {**scenario_cache[ck], "seed": seed}
                    name = tree["name"]
                    body = {k: v for k, v in tree.items() if k != "seed"}
                    sim = SimulatedInput(f"{name}-{_digest(body)}-seed{seed}", tree)
                    jobs.append(_job(spec, name, seed, variant, point, strings, dumped, sim, None, body))
    for rec in spec.inputs.recorded:
        for variant in spec.variants:
            for point in sweep_points(rec.sweep or spec.sweep):
                strings, dumped, scen = config_for(variant, point)
                if scen:
                    raise GslamError(f"{source}: recorded input {rec.path}: scenario keys apply to simulated inputs only")
                jobs.append(_job(spec, rec.label(), None, variant, point, strings, dumped, None, str(rec.path), None))
    ids = [j.id for j in jobs]
    if len(set(ids)) != len(ids):
        dup = next(i for i in ids if ids.count(i) > 1)
        raise GslamError(f"{source}: two jobs compute the same thing ({dup}); remove the duplicate variant or sweep value")
    return jobs


def _job(
    spec: AblationSpec,
    label: str,
    seed: int | None,
    variant: str,
    point: dict[str, Any],
    strings: list[str],
    dumped: str,
    sim: SimulatedInput | None,
    input_path: str | None,
    scenario_body: dict[str, Any] | None,
) -> Job:
    identity = {"input": scenario_body if sim is not None else input_path, "seed": seed, "config": dumped,
                "variant": variant, "params": point}
    parts = [label] + ([f"s{seed}"] if seed is not None else []) + [variant]
    parts += [f"{k.split('.')[-1]}={_short(v)}" for k, v in point.items()]
    job_id = f"{_readable(parts)}-{_digest(identity)}"
    return Job(job_id, label, seed, variant, dict(point), str(spec.config), tuple(strings), sim, input_path, spec.plots)


def _strip_source(message: str, config_path: Path) -> str:
    prefix = f"{config_path}: "
    return message[len(prefix):] if message.startswith(prefix) else message
