"""Reading the validation package's YAML files (models, observer configs).

The one loader of the package: a file that is not readable text or not a
YAML mapping is a one-line :class:`ValidationError` naming the file and,
where the parser knows it, the line.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

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
