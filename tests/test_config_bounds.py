"""Every number a pipeline config holds has a physical lower and upper
bound, declared on its field: ``Field(ge=, gt=, le=, lt=)`` or a bound of
:mod:`validation.base.bounds` (each with its reason). The test walks the
whole schema, from :class:`PipelineConfig` and the models of its
``validation`` and ``gating`` sections down through every nested model,
list, mapping and union, so a key added without bounds fails here rather
than accepting 1e308 or 0 in silence.

The other schemas users write are walked alike: a scenario
(:class:`slam.sim.scenario.Scenario`), an ablation spec
(:class:`slam.commands.ablate.spec.AblationSpec`) and the faults of
``gslam inject --fault`` (:data:`slam.commands.inject.spec.KINDS`).
"""

from __future__ import annotations

import enum
import math
import types
import typing
from collections.abc import Iterator
from typing import Annotated, Any, Literal, Union

import annotated_types
import pytest
from pydantic import AfterValidator, BaseModel
from pydantic.fields import FieldInfo

from slam.commands.ablate.spec import AblationSpec
from slam.commands.inject.spec import KINDS
from slam.config import PipelineConfig
from slam.sim.scenario import Scenario
from validation.config import ValidationConfig
from validation.gating import GatingConfig

ROOTS: dict[str, type[BaseModel]] = {"": PipelineConfig, "validation.": ValidationConfig, "gating.": GatingConfig}

# Every schema a user writes numbers into: its roots (key prefix -> model)
# and the fewest numbers a walk of it must reach (it reached the nested models).
SCHEMAS: dict[str, tuple[dict[str, type[BaseModel]], int]] = {
    "config": (ROOTS, 150),
    "scenario": ({"": Scenario}, 55),
    "ablation spec": ({"": AblationSpec}, 7),
    "inject --fault": ({f"{kind}@": model for kind, model in KINDS.items()}, 25),
}

# Numbers a bound elsewhere than on the field holds (a model validator
# whose one-line message the users already see): "Model.field": where.
BOUNDED_BY_A_VALIDATOR = {
    "SystemModel.priors": "SystemModel._probabilities: in [1e-9, 1)",
    "SystemModel.false_alarm": "SystemModel._references: in [1e-9, 1)",
    "RobotConfig.waypoints": "RobotConfig._pauses_nonnegative: x, y within 1e6 m, a pause in [0, 4 h], a speed in "
                             "(0, 50] m/s",
    "Distribution.integer": "Distribution._int64: within a 64-bit integer, which numpy draws",
}

# Numbers no physical bound fits. Keep this list short, and say why.
EXEMPT: dict[str, str] = {}


def _bounds(metadata: list[Any]) -> tuple[float | None, float | None]:
    """The tightest finite lower and upper bound ``metadata`` declares."""
    lo: float | None = None
    hi: float | None = None

    def low(v):
        nonlocal lo
        if v is not None and math.isfinite(v):
            lo = v if lo is None else max(lo, v)

    def high(v):
        nonlocal hi
        if v is not None and math.isfinite(v):
            hi = v if hi is None else min(hi, v)

    for m in metadata:
        if isinstance(m, FieldInfo):
            sub = _bounds(list(m.metadata))
            low(sub[0])
            high(sub[1])
        elif isinstance(m, (annotated_types.Gt, annotated_types.Ge)):
            low(getattr(m, "gt", getattr(m, "ge", None)))
        elif isinstance(m, (annotated_types.Lt, annotated_types.Le)):
            high(getattr(m, "lt", getattr(m, "le", None)))
        elif isinstance(m, annotated_types.Interval):
            low(m.gt if m.gt is not None else m.ge)
            high(m.lt if m.lt is not None else m.le)
        elif isinstance(m, AfterValidator) and hasattr(m.func, "bounds"):
            low(m.func.bounds[0])
            high(m.func.bounds[1])
    return lo, hi


def _numbers(tp: Any, metadata: list[Any], where: str) -> Iterator[tuple[str, Any, list[Any]]]:
    """Every int or float place in type ``tp`` (with the bounds around it),
    and every model below it (metadata None): ``(where, type, metadata)``."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin is Annotated:
        yield from _numbers(args[0], metadata + list(tp.__metadata__), where)
    elif origin in (Union, types.UnionType):
        for arg in args:  # a bound on an optional field holds for its number
            yield from _numbers(arg, metadata, where)
    elif origin in (list, tuple, set, frozenset):
        for arg in args:
            if arg is not Ellipsis:
                yield from _numbers(arg, [], f"{where}[]")
    elif origin is dict:
        yield from _numbers(args[1], [], f"{where}.*")
    elif origin is Literal or tp is type(None) or tp in (bool, str, Any):
        return
    elif isinstance(tp, type) and issubclass(tp, BaseModel):
        yield where, tp, None
    elif isinstance(tp, type) and issubclass(tp, enum.Enum):
        return
    elif tp in (int, float):
        yield where, tp, metadata


def schema_numbers(roots: dict[str, type[BaseModel]] = ROOTS) -> list[tuple[str, str, float | None, float | None]]:
    """``(key, Model.field, lower, upper)`` for every number of the schema
    of ``roots`` (the pipeline config's by default)."""
    found = []
    seen: set[type[BaseModel]] = set()
    todo = [(prefix, model) for prefix, model in roots.items()]
    while todo:
        prefix, model = todo.pop()
        if model in seen:
            continue
        seen.add(model)
        for name, field in model.model_fields.items():
            key = f"{prefix}{field.alias or name}"
            for where, tp, metadata in _numbers(field.annotation, list(field.metadata), key):
                if metadata is None:
                    todo.append((where + ".", tp))
                else:
                    owner = next(c for c in model.__mro__ if name in getattr(c, "__annotations__", {}))
                    found.append((where, f"{owner.__name__}.{name}", *_bounds(metadata)))
    return sorted(set(found))


@pytest.mark.parametrize("schema", list(SCHEMAS))
def test_every_number_of_the_config_has_a_lower_and_an_upper_bound(schema: str):
    roots, least = SCHEMAS[schema]
    numbers = schema_numbers(roots)
    assert len(numbers) > least  # the walk reached the nested sections
    unbounded = [f"{key} ({field}): {'no lower' if lo is None else ''}{' and ' if lo is None and hi is None else ''}"
                 f"{'no upper' if hi is None else ''} bound"
                 for key, field, lo, hi in numbers
                 if (lo is None or hi is None) and field not in EXEMPT and field not in BOUNDED_BY_A_VALIDATOR]
    assert not unbounded, f"{len(unbounded)} numbers without bounds:\n" + "\n".join(unbounded)


def test_the_lists_name_fields_that_exist():
    fields = {field for roots, _ in SCHEMAS.values() for _, field, _, _ in schema_numbers(roots)}
    assert set(EXEMPT) <= fields and set(BOUNDED_BY_A_VALIDATOR) <= fields


# --- the bounds as a user meets them: `gslam map --set KEY=VALUE` -----------------

# Keys that took any number before they were bounded, with a value below
# their lower bound (0 where 0 is refused, else a negative one).
NEWLY_BOUNDED = [
    ("loops.local_map_m", "-1"), ("loops.min_separation_m", "-1"), ("loops.search_radius_m", "-1"),
    ("loops.search_radius_per_m", "-1"), ("loops.max_search_yaw_deg", "-1"), ("loops.voxel_m", "0"),
    ("loops.descriptor.max_radius_m", "0"), ("loops.correlative.resolution_m", "0"),
    ("loops.acceptance.max_rms_m", "0"), ("loops.file.min_weight", "-1"), ("loops.observer.support_path_m", "0"),
    ("loops.observer.max_clique_steps", "0"), ("loops.observer.min_support", "-1"),
    ("submaps.length_m", "0"), ("submaps.node_spacing_m", "-1"), ("submaps.node_turn_deg", "-1"),
    ("submaps.voxel_m", "0"), ("submaps.tie_tolerance", "-1"), ("submaps.constraints.max_distance_m", "0"),
    ("submaps.constraints.loop_separation_m", "-1"), ("submaps.refine.max_shift_m", "0"),
    ("submaps.recognition.min_path_m", "-1"), ("submaps.recognition.max_drift_per_m", "-1"),
    ("submaps.ambiguity.exclude_deg", "0"),
    ("frontend.voxel_size_m", "0"), ("frontend.min_range_m", "-1"),
    ("validation.rate_hz", "0"), ("validation.observers.gap_periods", "0"), ("gating.baseline_m", "0"),
]
INTEGERS = {"loops.observer.max_clique_steps", "loops.observer.min_support"}


def _named(key: str) -> tuple[str, ...]:
    """How an error may name ``key``: dotted, or as the validation package
    writes its sections' keys, the section then the key within it
    (``validation.rate_hz``, ``validation.observers.gap_periods``)."""
    dots = [i for i, c in enumerate(key) if c == "."]
    return (key, *(f"{key[:i]}: {key[i + 1:]}" for i in dots))


def _refusal(key: str, value: str) -> str:
    from slam.config import check_given_once, load_config
    from slam.errors import GslamError
    from tests.conftest import TELEMAX_CONFIG

    overrides = [f"{key}={value}"]
    with pytest.raises(GslamError) as e:
        check_given_once(overrides)  # as gslam map reads its --set
        load_config(TELEMAX_CONFIG, overrides)
    message = str(e.value)
    assert "\n" not in message and "Traceback" not in message, message
    assert message.startswith(f"--set {key}={value}: "), message
    assert any(f"{name}:" in message for name in _named(key)), message
    return message


@pytest.mark.parametrize("key", [k for k, _ in NEWLY_BOUNDED])
def test_a_newly_bounded_key_refuses_a_huge_value_naming_the_key(key: str):
    huge = "100000000000000000000" if key in INTEGERS else "1e308"
    message = _refusal(key, huge)
    assert " is above " in message, message


@pytest.mark.parametrize("key, low", NEWLY_BOUNDED)
def test_a_newly_bounded_key_refuses_a_value_below_its_bound_naming_the_key(key: str, low: str):
    message = _refusal(key, low)
    assert "greater than" in message or " is below " in message, message
