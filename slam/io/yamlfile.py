"""Reading YAML (and other text) files a user gives: one-line errors for
anything that is not what was expected, and the checks every YAML tree
gets before it is used.

* a missing, unreadable, binary or non-UTF-8 file;
* invalid YAML (with the line), nesting too deep, a top level that is not
  a mapping, or aliases that expand beyond :data:`MAX_YAML_VALUES`;
* NaN and infinite numbers (:func:`non_finite`), named by their dotted key.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import yaml

from slam.errors import GslamError

# libyaml's parser where PyYAML was built with it (ten times faster), the same safe constructor.
SAFE_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


def read_text_file(path: str | Path, what: str = "config", kind: str = "YAML") -> str:
    """The text of a UTF-8 file, with a one-line error for a missing,
    unreadable or binary file; ``what`` and ``kind`` name what was expected
    (a YAML config, a JSON sidecar)."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as e:
        raise GslamError(f"{path}: cannot read {what} ({e.strerror})") from None
    if b"\0" in data:
        raise GslamError(f"{path}: binary content; expected a {kind} {what} (text)")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise GslamError(f"{path}: byte {e.start} is not UTF-8 text; expected a {kind} {what}") from None


def load_yaml(path: str | Path, what: str = "config") -> dict[str, Any]:
    """Read a YAML mapping, with a one-line error for anything else. An
    empty file is an empty mapping."""
    path = Path(path)
    text = read_text_file(path, what)
    try:
        data = yaml.load(text, Loader=SAFE_LOADER)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f" line {mark.line + 1}:" if mark else ""
        problem = getattr(e, "problem", None) or "not YAML"
        raise GslamError(f"{path}:{where} invalid YAML ({problem})") from None
    except RecursionError:
        raise GslamError(f"{path}: YAML nested too deeply") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise GslamError(f"{path}: expected a YAML mapping of keys at the top level, found a {type(data).__name__}")
    if _expanded_size(data, {}) > MAX_YAML_VALUES:
        raise GslamError(f"{path}: expands to more than {MAX_YAML_VALUES:,} values (YAML aliases); expected a config")
    return data


MAX_YAML_VALUES = 1_000_000
"""Most values a YAML file may expand to: aliases can make a few lines
expand to billions (a "billion laughs" file), which no config needs."""


def _expanded_size(node: Any, memo: dict[int, int]) -> int:
    """Values in ``node`` with every alias expanded, counted once per
    distinct container (linear time, however often a container is shared)."""
    if not isinstance(node, (dict, list)):
        return 1
    if id(node) not in memo:
        memo[id(node)] = 0  # a cycle counts as small; PyYAML's safe loader makes none
        children = node.values() if isinstance(node, dict) else node
        memo[id(node)] = 1 + sum(_expanded_size(c, memo) for c in children)
    return memo[id(node)]


def non_finite(tree: Any, prefix: str = "", seen: set[int] | None = None) -> tuple[str, float] | None:
    """The dotted path and value of the first NaN or infinite number in a
    YAML tree, or None. A container shared by aliases is looked at once."""
    if isinstance(tree, float) and not math.isfinite(tree):
        return prefix or "value", tree
    if isinstance(tree, dict):
        items = tree.items()
    elif isinstance(tree, (list, tuple)):
        items = enumerate(tree)
    else:
        return None
    seen = set() if seen is None else seen
    if id(tree) in seen:
        return None
    seen.add(id(tree))
    for key, value in items:
        found = non_finite(value, f"{prefix}.{key}" if prefix else str(key), seen)
        if found is not None:
            return found
    return None


def check_finite(tree: Any, source: str) -> None:
    """Refuse NaN and infinite numbers, naming the key."""
    found = non_finite(tree)
    if found is not None:
        key, value = found
        raise GslamError(f"{source}: {key}: expected a finite number, got {yaml_number(value)}")


def yaml_number(value: float) -> str:
    return ".nan" if math.isnan(value) else (".inf" if value > 0 else "-.inf")
