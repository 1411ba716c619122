"""Every number a pipeline config holds has a physical lower and upper
bound, declared on its field: ``Field(ge=, gt=, le=, lt=)`` or a bound of
:mod:`validation.base.bounds` (each with its reason). The test walks the
whole schema, from :class:`PipelineConfig` and the models of its
``validation`` and ``gating`` sections down through every nested model,
list, mapping and union, so a key added without bounds fails here rather
than accepting 1e308 or 0 in silence.
"""

from __future__ import annotations

import enum
import math
import types
import typing
from collections.abc import Iterator
from typing import Annotated, Any, Literal, Union

import annotated_types
from pydantic import AfterValidator, BaseModel
from pydantic.fields import FieldInfo

from slam.config import PipelineConfig
from validation.config import ValidationConfig
from validation.gating import GatingConfig

ROOTS: dict[str, type[BaseModel]] = {"": PipelineConfig, "validation.": ValidationConfig, "gating.": GatingConfig}

# Numbers a bound elsewhere than on the field holds (a model validator
# whose one-line message the users already see): "Model.field": where.
BOUNDED_BY_A_VALIDATOR = {
    "SystemModel.priors": "SystemModel._probabilities: in [1e-9, 1)",
    "SystemModel.false_alarm": "SystemModel._references: in [1e-9, 1)",
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


def schema_numbers() -> list[tuple[str, str, float | None, float | None]]:
    """``(key, Model.field, lower, upper)`` for every number of the schema."""
    found = []
    seen: set[type[BaseModel]] = set()
    todo = [(prefix, model) for prefix, model in ROOTS.items()]
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


def test_every_number_of_the_config_has_a_lower_and_an_upper_bound():
    numbers = schema_numbers()
    assert len(numbers) > 150  # the walk reached the nested sections
    unbounded = [f"{key} ({field}): {'no lower' if lo is None else ''}{' and ' if lo is None and hi is None else ''}"
                 f"{'no upper' if hi is None else ''} bound"
                 for key, field, lo, hi in numbers
                 if (lo is None or hi is None) and field not in EXEMPT and field not in BOUNDED_BY_A_VALIDATOR]
    assert not unbounded, f"{len(unbounded)} numbers without bounds:\n" + "\n".join(unbounded)


def test_the_lists_name_fields_that_exist():
    fields = {field for _, field, _, _ in schema_numbers()}
    assert set(EXEMPT) <= fields and set(BOUNDED_BY_A_VALIDATOR) <= fields

