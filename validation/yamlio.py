"""Reading the validation package's YAML files (models, observer configs)
into typed models.

The one loader of the package: a file that is not readable text or not a
YAML mapping is a one-line :class:`ValidationError` naming the file and,
where the parser knows it, the line.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, TypeVar

import pydantic
import yaml
from pydantic import BaseModel, ConfigDict

from validation.errors import ValidationError

# libyaml's parser where PyYAML was built with it (ten times faster), the same safe constructor.
SAFE_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


def load_yaml(path: str | Path) -> dict[str, Any]:
    """Read a YAML mapping from ``path`` (an empty file is an empty mapping)."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise ValidationError(f"{path}: cannot read ({e.strerror})") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise ValidationError(f"{path}: not a text file (expected UTF-8 YAML)") from None
    try:
        data = yaml.load(text, Loader=SAFE_LOADER)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f" line {mark.line + 1}:" if mark else ""
        raise ValidationError(f"{path}:{where} invalid YAML") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ValidationError(f"{path}: expected a mapping at the top level")
    return data


class Strict(BaseModel):
    """The base of every config model of the project: an unknown key is an
    error (a typo in an ablation must not silently run the default), NaN
    and infinity are refused, and an assignment is validated as a loaded
    value is."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, validate_assignment=True)


class StrictFrozen(Strict):
    """A :class:`Strict` model that does not change once loaded (and so can
    be hashed): the validation sections, specs and faults."""

    model_config = ConfigDict(frozen=True)


_M = TypeVar("_M", bound=BaseModel)


def validate_mapping(model_type: type[_M], data: Any, source: str) -> _M:
    """Validate ``data`` as ``model_type``; bad input raises a one-line
    :class:`ValidationError` naming ``source`` and the offending key."""
    try:
        return model_type.model_validate(data)
    except pydantic.ValidationError as e:
        first = e.errors()[0]
        loc = ".".join(str(p) for p in first["loc"])
        if first["type"] == "extra_forbidden":
            raise ValidationError(f"{source}: unknown key '{loc}'") from None
        msg = first["msg"].removeprefix("Value error, ")
        where = f"{loc}: " if loc else ""
        raise ValidationError(f"{source}: {where}{msg}") from None
