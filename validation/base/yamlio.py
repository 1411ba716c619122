"""Reading the validation package's YAML files (models, observer configs)
into typed models.

The one loader of the package: a file that is not readable text or not a
YAML mapping is a one-line :class:`ValidationError` naming the file and,
where the parser knows it, the line.
"""

from __future__ import annotations

import os
import stat
import types
from pathlib import Path
from typing import Annotated, Any, TypeVar, Union, get_args, get_origin

import pydantic
import yaml
from pydantic import BaseModel, ConfigDict, model_validator

from validation.base.errors import ValidationError

# libyaml's parser where PyYAML was built with it (ten times faster), the same safe constructor.
SAFE_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)

MAX_TEXT_BYTES = 64 * 2**20
"""Largest text file read whole (a config, a scenario, a sidecar): far
above any real one, far below what would exhaust the memory."""
MAX_YAML_VALUES = 1_000_000
"""Most values a YAML file may expand to: aliases can make a few lines
expand to billions (a "billion laughs" file), which no config needs."""
MAX_INT_DIGITS = 30
"""Most digits of an integer in a YAML file: far above any count or seed a
config holds (a 64-bit number has 20), far below the 4,300 digits beyond
which Python refuses to convert one (a ValueError, not a YAML error)."""
_BOM = b"\xef\xbb\xbf"


def special_file(mode: int) -> str | None:
    """What a file that is neither a regular file nor a folder is (``a
    named pipe``, ``a device``, ``a socket``), else None."""
    for test, name in ((stat.S_ISFIFO, "a named pipe"), (stat.S_ISCHR, "a device"), (stat.S_ISBLK, "a device"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return None


def check_regular_file(path: str | Path, what: str = "file") -> int:
    """The size of ``path`` (bytes) if it is a regular file (or a link to
    one); a one-line :class:`ValidationError` for anything else, before it
    is opened (reading a named pipe would wait forever)."""
    try:
        st = os.stat(path)
    except OSError as e:
        raise ValidationError(f"{path}: cannot read {what} ({e.strerror})") from None
    if stat.S_ISDIR(st.st_mode):
        raise ValidationError(f"{path}: cannot read {what} (a folder; expected a file)")
    special = special_file(st.st_mode)
    if special is not None:
        raise ValidationError(f"{path}: cannot read {what}: it is {special}, not a regular file")
    return st.st_size


def unique_keys(pairs: list[tuple[str, object]]) -> dict:
    """A JSON object from its ``pairs``, as ``json.loads``'s
    ``object_pairs_hook``: a key given twice is a ValueError naming it
    (``json`` keeps the last in silence; YAML here refuses it too)."""
    out: dict = {}
    for key, value in pairs:
        if key in out:
            raise ValueError(f"key {key!r} given twice in one JSON object")
        out[key] = value
    return out


def wide_encoding(data: bytes) -> str | None:
    """``UTF-16`` or ``UTF-32`` if ``data`` is text in one of them, by its
    byte-order mark or, without one, by the zero bytes of ASCII characters
    at every second (fourth) place of its first bytes; else None."""
    if data.startswith((b"\xff\xfe\x00\x00", b"\x00\x00\xfe\xff")):
        return "UTF-32"
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        return "UTF-16"
    head = data[:512]
    if len(head) < 8:
        return None
    for width, name in ((4, "UTF-32"), (2, "UTF-16")):
        head = head[: len(head) // width * width]
        lanes = [head[i::width] for i in range(width)]
        text = [i for i, lane in enumerate(lanes) if lane.count(0) < len(lane) // 2]
        if len(text) == 1 and all(not any(lane) for i, lane in enumerate(lanes) if i != text[0]):
            return name
    return None


def decode_text(data: bytes, source: str, what: str = "file", kind: str = "text") -> str:
    """UTF-8 text (a leading byte-order mark dropped), with a one-line
    error that says what the bytes are: binary, UTF-16 or UTF-32, or text with a byte
    that is not UTF-8 (Latin-1?) at a line."""
    expected = what if what.split(" ")[0] == kind else f"{kind} {what}"  # a 'YAML file' is not a 'YAML YAML file'
    if data.startswith(_BOM):
        data = data[len(_BOM):]
    wide = wide_encoding(data)
    if wide is not None:
        raise ValidationError(f"{source}: {wide} text; expected a {expected} in UTF-8 (save it as UTF-8)")
    if b"\0" in data:
        raise ValidationError(f"{source}: binary content; expected a {expected} (text)")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        line = data.count(b"\n", 0, e.start) + 1
        byte = data[e.start]
        raise ValidationError(f"{source}: line {line}: byte 0x{byte:02X} is not UTF-8 text (a Latin-1 character?); "
                              f"expected a {expected} in UTF-8") from None


def read_text(path: str | Path, what: str = "file", kind: str = "YAML") -> str:
    """The text of a UTF-8 file, with a one-line :class:`ValidationError`
    for a missing, unreadable, special, huge, binary or non-UTF-8 file;
    ``what`` and ``kind`` name what was expected (a YAML config)."""
    size = check_regular_file(path, what)
    if size > MAX_TEXT_BYTES:
        raise ValidationError(f"{path}: {size / 2**20:.0f} MB; a {kind} {what} is text of at most "
                              f"{MAX_TEXT_BYTES // 2**20} MB")
    try:
        data = Path(path).read_bytes()
    except OSError as e:
        raise ValidationError(f"{path}: cannot read {what} ({e.strerror})") from None
    return decode_text(data, str(path), what, kind)


class UniqueKeyLoader(SAFE_LOADER):  # type: ignore[misc, valid-type]
    """The safe loader, refusing a key given twice in one mapping (YAML
    would keep the second silently). A key a merge (``<<``) brings beside
    one given in the mapping itself is YAML's override, as meant; but the
    mappings a merge brings are checked too, which PyYAML flattens without
    constructing them (``{<<: {a: 1, a: 2}}`` kept the second in silence)."""

    def construct_mapping(self, node, deep=False):
        if isinstance(node, yaml.MappingNode):
            self._unique_keys(node)
        return super().construct_mapping(node, deep=deep)

    def _unique_keys(self, node: yaml.MappingNode, merging: tuple[int, ...] = ()) -> None:
        seen: dict[Any, int] = {}
        for key_node, value_node in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                merged = value_node.value if isinstance(value_node, yaml.SequenceNode) else [value_node]
                for m in merged:
                    if isinstance(m, yaml.MappingNode):
                        if id(m) in (*merging, id(node)):
                            raise yaml.constructor.ConstructorError(
                                None, None, "a mapping merges itself (<<: an alias of its own anchor)", key_node.start_mark)
                        self._unique_keys(m, (*merging, id(node)))
                continue
            key = self.construct_object(key_node, deep=True)
            line = key_node.start_mark.line + 1
            try:
                if key in seen:  # on another line, or the same one ({a: 1, a: 2})
                    raise DuplicateKey(key, seen[key], line)
                seen[key] = line
            except TypeError:  # an unhashable key: the constructor says so
                continue


    def construct_yaml_int(self, node):
        digits = sum(c.isdigit() for c in str(node.value))
        if digits > MAX_INT_DIGITS:
            raise yaml.constructor.ConstructorError(
                None, None, f"an integer of {digits:,} digits; no setting needs more than {MAX_INT_DIGITS}",
                node.start_mark)
        value = super().construct_yaml_int(node)
        _refuse_yaml11_only_number(str(node.value), value, node)
        return value

    def construct_yaml_float(self, node):
        value = super().construct_yaml_float(node)
        _refuse_yaml11_only_number(str(node.value), value, node)
        return value


def _refuse_yaml11_only_number(text: str, value: int | float, node: yaml.Node) -> None:
    """Refuse a number PyYAML reads by YAML 1.1's rules as another value than
    the digits written say, to YAML 1.2 and to a reader of the file: a
    leading 0 (``010`` is octal 8, not 10: a zero-padded count) and numbers
    in base 60 (``1:30`` is 90, ``1:30:00`` 5400: a period written as a
    clock time). Both were read in silence, even under ``%YAML 1.2``."""
    plain = text.replace("_", "").lstrip("+-")
    if ":" in plain:
        raise yaml.constructor.ConstructorError(
            None, None, f"{text} is a base-60 number to YAML 1.1 ({value:g}), text to YAML 1.2; write the number "
            f"({value:g}) or quote the text", node.start_mark)
    if isinstance(value, int) and len(plain) > 1 and plain[0] == "0" and plain.isdigit() and int(plain, 10) != abs(value):
        raise yaml.constructor.ConstructorError(
            None, None, f"{text} is octal {value} to YAML 1.1 (a leading 0), {int(text.replace('_', ''), 10)} to YAML "
            "1.2; write it without the leading 0", node.start_mark)


UniqueKeyLoader.add_constructor("tag:yaml.org,2002:int", UniqueKeyLoader.construct_yaml_int)
UniqueKeyLoader.add_constructor("tag:yaml.org,2002:float", UniqueKeyLoader.construct_yaml_float)


class DuplicateKey(yaml.YAMLError):
    def __init__(self, key: Any, first: int, second: int):
        super().__init__(f"key {key!r} given twice")
        self.key, self.first, self.second = key, first, second


def parse_yaml(text: str, source: str, what: str = "file") -> Any:
    """The YAML document in ``text``; one-line :class:`ValidationError` for
    invalid YAML (with the line), a key given twice (both lines), nesting
    too deep or aliases that expand beyond :data:`MAX_YAML_VALUES`."""
    try:
        data = yaml.load(text, Loader=UniqueKeyLoader)
    except DuplicateKey as e:
        first = "earlier on the same line" if e.first == e.second else f"first on line {e.first}"
        raise ValidationError(f"{source}: line {e.second}: key '{e.key}' given twice ({first}); "
                              "the second would silently replace the first") from None
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f" line {mark.line + 1}:" if mark else ""
        problem = getattr(e, "problem", None) or "not YAML"
        raise ValidationError(f"{source}:{where} invalid YAML ({problem})") from None
    except RecursionError:
        raise ValidationError(f"{source}: YAML nested too deeply") from None
    if expanded_size(data, {}) > MAX_YAML_VALUES:
        raise ValidationError(f"{source}: expands to more than {MAX_YAML_VALUES:,} values (YAML aliases); "
                              f"expected a {what}")
    return data


def expanded_size(node: Any, memo: dict[int, int]) -> int:
    """Values in ``node`` with every alias expanded, counted once per
    distinct container (linear time, however often a container is shared)."""
    if not isinstance(node, (dict, list)):
        return 1
    if id(node) not in memo:
        memo[id(node)] = 0  # a cycle counts as small; PyYAML's safe loader makes none
        children = node.values() if isinstance(node, dict) else node
        memo[id(node)] = 1 + sum(expanded_size(c, memo) for c in children)
    return memo[id(node)]


def load_yaml(path: str | Path, what: str = "YAML file") -> dict[str, Any]:
    """Read a YAML mapping from ``path`` (an empty file is an empty
    mapping); see :func:`read_text` and :func:`parse_yaml`."""
    data = parse_yaml(read_text(path, what), str(path), what)
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ValidationError(f"{path}: expected a YAML mapping of keys at the top level, found {yaml_kind(data)}")
    return data


def yaml_kind(value: Any) -> str:
    """What YAML made of an unquoted key that is no text (``yes`` a truth value)."""
    if isinstance(value, bool):
        return "a truth value (as it reads yes, no, on, off, true and false unquoted)"
    if value is None:
        return "null (as it reads ~, null and an empty key)"
    if isinstance(value, (int, float)):
        return "a number"
    if isinstance(value, str):
        return "text"
    return f"a {type(value).__name__}"


class NoTruthValueForANumber(BaseModel):
    """A model whose numbers may not be given as true or false: pydantic
    would take a YAML ``true`` or JSON ``false`` for the number 1 or 0,
    alone or inside a list of numbers (a waypoint ``[1.0, yes]``, seeds
    ``[true]``, a fault interval ``[true, 2]``)."""

    @model_validator(mode="before")
    @classmethod
    def _no_truth_value_for_a_number(cls, data: Any) -> Any:
        if isinstance(data, dict):
            for name, field in cls.model_fields.items():
                where = _truth_value_for_a_number(field.annotation, data.get(field.alias or name))
                if where is not None:
                    path, value = where
                    raise ValueError(f"{'.'.join([name, *path])}: expected a number, not {str(value).lower()}")
        return data


class Strict(NoTruthValueForANumber):
    """The base of every config model of the project: an unknown key is an
    error (a typo in an ablation must not silently run the default), NaN
    and infinity are refused, a truth value is no number, and an
    assignment is validated as a loaded value is."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, validate_assignment=True)


def _numeric(tp: Any) -> bool:
    """``tp`` a number type (int or float, bounded, or None allowed), not bool."""
    origin = get_origin(tp)
    if origin is Annotated:
        return _numeric(get_args(tp)[0])
    if origin in (Union, types.UnionType):
        args = [a for a in get_args(tp) if a is not type(None)]
        return bool(args) and all(_numeric(a) for a in args)
    return tp in (int, float)


def _truth_value_for_a_number(tp: Any, value: Any) -> tuple[list[str], bool] | None:
    """Where in ``value`` a bool stands for a number of type ``tp`` (the
    indices or keys down to it, and the bool), looking into the lists,
    tuples and mappings ``tp`` says hold numbers; None if nowhere. Nested
    models are left to their own check."""
    if isinstance(value, bool):
        return ([], value) if _numeric(tp) else None
    origin, args = get_origin(tp), get_args(tp)
    if origin is Annotated:
        return _truth_value_for_a_number(args[0], value)
    if origin in (Union, types.UnionType):
        for arg in args:
            found = _truth_value_for_a_number(arg, value)
            if found is not None:
                return found
        return None
    if origin in (list, tuple) and isinstance(value, (list, tuple)):
        variadic = origin is list or (len(args) == 2 and args[1] is Ellipsis)
        for i, item in enumerate(value):
            if not variadic and i >= len(args):
                break
            found = _truth_value_for_a_number(args[0] if variadic else args[i], item)
            if found is not None:
                return [str(i), *found[0]], found[1]
    if origin is dict and isinstance(value, dict) and len(args) == 2:
        for key, item in value.items():
            found = _truth_value_for_a_number(args[1], item)
            if found is not None:
                return [str(key), *found[0]], found[1]
    return None


class StrictFrozen(Strict):
    """A :class:`Strict` model that does not change once loaded (and so can
    be hashed): the validation sections, specs and faults."""

    model_config = ConfigDict(frozen=True)


_M = TypeVar("_M", bound=BaseModel)


def validate_mapping(model_type: type[_M], data: Any, source: str, section: bool = False) -> _M:
    """Validate ``data`` as ``model_type``; bad input raises a one-line
    :class:`ValidationError` naming ``source`` and the offending key.
    ``section``: ``source`` is a config section's key path (``gating``), so
    the key is named by its whole path (``gating.holdoff_s``), as the
    pipeline config's other sections name theirs."""
    try:
        return model_type.model_validate(data)
    except pydantic.ValidationError as e:
        first = e.errors()[0]
        loc = ".".join(str(p) for p in first["loc"])
        if first["type"] == "extra_forbidden":
            raise ValidationError(unknown_key(source, tuple(first["loc"]), section, model_type)) from None
        msg = first["msg"].removeprefix("Value error, ")
        if section:
            raise ValidationError(f"{source}.{loc}: {msg}" if loc else f"{source}: {msg}") from None
        where = f"{loc}: " if loc else ""
        raise ValidationError(f"{source}: {where}{msg}") from None


def unknown_key(source: str, loc: tuple, section: bool = False, model: type[BaseModel] | None = None) -> str:
    """The message for key ``loc`` (its path) unknown in ``source`` (a
    file, or with ``section`` a config section's key path), with the
    nearest known key of ``model`` at that place."""
    key = ".".join(str(p) for p in loc)
    hint = did_you_mean(model, loc) if model is not None else ""
    return f"unknown config key '{source}.{key}'{hint}" if section else f"{source}: unknown key '{key}'{hint}"


def did_you_mean(model: type[BaseModel], loc: tuple) -> str:
    """``; did you mean 'x'?`` for the known key of ``model`` nearest the
    unknown one at ``loc``, or nothing when none is near."""
    import difflib
    import typing

    node: Any = model
    for part in loc[:-1]:
        if isinstance(part, int):  # an item of a list: its model is the list's
            continue
        field = node.model_fields.get(part) if isinstance(node, type) and issubclass(node, BaseModel) else None
        if field is None:
            return ""
        kinds = [a for a in (field.annotation, *typing.get_args(field.annotation))
                 if isinstance(a, type) and issubclass(a, BaseModel)]
        if not kinds:
            return ""
        node = kinds[0]
    if not (isinstance(node, type) and issubclass(node, BaseModel)):
        return ""
    known = [f.alias or name for name, f in node.model_fields.items()]
    near = difflib.get_close_matches(str(loc[-1]), known, n=1, cutoff=0.6)
    return f"; did you mean '{near[0]}'?" if near else ""
