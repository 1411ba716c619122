"""Reading YAML (and other text) files a user gives: one-line errors for
anything that is not what was expected, and the checks every YAML tree
gets before it is used.

* a missing, unreadable, binary or non-UTF-8 file, or one that is not a
  regular file (a named pipe would block the read forever);
* invalid YAML (with the line), a key given twice (both lines), nesting
  too deep, a top level that is not a mapping, or aliases that expand
  beyond :data:`MAX_YAML_VALUES`;

The reading itself is :mod:`validation.yamlio`'s, which the validation
package's own files (models) get too.
* NaN and infinite numbers (:func:`non_finite`), named by their dotted key.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from slam.errors import GslamError
from validation import yamlio
from validation.errors import ValidationError

SAFE_LOADER = yamlio.UniqueKeyLoader
"""The safe loader (libyaml's parser where PyYAML has it), refusing keys given twice."""
MAX_YAML_VALUES = yamlio.MAX_YAML_VALUES


def read_text_file(path: str | Path, what: str = "config", kind: str = "YAML") -> str:
    """The text of a UTF-8 file, with a one-line error for a missing,
    unreadable, special (a named pipe), huge, binary or non-UTF-8 file;
    ``what`` and ``kind`` name what was expected (a YAML config, a JSON
    sidecar)."""
    try:
        return yamlio.read_text(path, what, kind)
    except ValidationError as e:
        raise GslamError(str(e)) from None


def load_yaml(path: str | Path, what: str = "config") -> dict[str, Any]:
    """Read a YAML mapping, with a one-line error for anything else (a key
    given twice names both lines). An empty file is an empty mapping."""
    try:
        return yamlio.load_yaml(path, what)
    except ValidationError as e:
        raise GslamError(str(e)) from None


def parse_yaml(text: str, source: str, what: str = "value") -> Any:
    """A YAML document from ``text`` (a ``--set`` value), the same checks."""
    try:
        return yamlio.parse_yaml(text, source, what)
    except ValidationError as e:
        raise GslamError(str(e)) from None


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


def decode_log(data: bytes, source: str | Path, what: str) -> str:
    """The text of a log whose fields are ASCII numbers and words (CARMEN,
    libRSF): a byte-order mark dropped, a stray byte that is not UTF-8 (a
    Latin-1 host name or comment) kept as U+FFFD, so that only a field that
    is read can fail, at its line. NUL bytes, or mostly undecodable bytes,
    are binary content."""
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    text = data.decode("utf-8", errors="replace")
    if "\0" in text or text.count("\ufffd") > 0.1 * max(len(text), 1):
        raise GslamError(f"{source}: cannot read: not a {what} (binary content)")
    return text


def check_regular(path: str | Path, what: str) -> None:
    """A one-line error unless ``path`` is a regular file (a named pipe
    would block the read forever, a device never end)."""
    try:
        yamlio.check_regular_file(path, what)
    except ValidationError as e:
        raise GslamError(str(e)) from None
