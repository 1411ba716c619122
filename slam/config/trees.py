"""The checks every YAML tree of a config, scenario or spec gets before it
is used: NaN and infinite numbers (:func:`non_finite`), named by their
dotted key. Reading the files themselves (one-line errors for a missing,
binary or invalid file, a key given twice...) is :mod:`validation.base.yamlio`'s."""

from __future__ import annotations

import math
from typing import Any

from slam.errors import GslamError


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
