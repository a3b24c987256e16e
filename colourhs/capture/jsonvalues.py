"""Reading JSON files and checking their values, every problem a :class:`CaptureFormatError`.

The primitives of rig.json and scene.json validation: :func:`_read_json`
(UTF-8, duplicate keys refused), :func:`_check_schema` (a JSON Schema, Draft
2020-12, whose ``description`` keywords word the messages), the type checks
``_as_object`` and ``_as_str``, and :func:`_frozen` (a read-only float64
copy). Messages name the file and the offending key (its JSON path, such as
``cameras[1].K``), with a short rendering of the value (:func:`_show`).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
from jsonschema import Draft202012Validator, ValidationError
from jsonschema.exceptions import relevance
from jsonschema.validators import extend

from colourhs.capture.base import CaptureFormatError


class _DuplicateKey(Exception):
    pass


def _reject_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    result: dict[str, Any] = {}
    for key, value in pairs:
        if key in result:
            raise _DuplicateKey(key)
        result[key] = value
    return result


def _read_json(path: Path, what: str) -> Any:
    """Decode a JSON file, refusing duplicate keys; errors name ``path``."""
    if not path.is_file():
        raise CaptureFormatError(path, f"{what} not found")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise CaptureFormatError(path, "not valid JSON: not UTF-8 text") from None
    except OSError as err:
        raise CaptureFormatError(path, f"cannot read {what}: {err.strerror}") from None
    try:
        return json.loads(text, object_pairs_hook=_reject_duplicates)
    except json.JSONDecodeError as err:
        raise CaptureFormatError(
            path, f"not valid JSON: {err.msg} (line {err.lineno}, column {err.colno})"
        ) from None
    except _DuplicateKey as err:
        raise CaptureFormatError(path, f"not valid JSON: duplicate key {err.args[0]!r}") from None


def _show(value: Any, limit: int = 60) -> str:
    """Short JSON-like rendering of a value for error messages."""
    text = json.dumps(value, default=repr)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _as_object(value: Any, where: str, path: Path) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise CaptureFormatError(path, f"{where} must be a JSON object, got {_show(value)}")
    return value


def _as_str(value: Any, where: str, path: Path) -> str:
    if not isinstance(value, str):
        raise CaptureFormatError(path, f"{where} must be a string, got {_show(value)}")
    return value


def _is_number(value: Any) -> bool:
    """A finite JSON number: not a bool, NaN or infinity, nor an int beyond float range."""
    if isinstance(value, bool):
        return False
    if isinstance(value, int):
        return abs(value) < 2**1023
    return isinstance(value, float) and math.isfinite(value)


def _frozen(array: np.ndarray) -> np.ndarray:
    array = np.array(array, dtype=np.float64)
    array.flags.writeable = False
    return array


_Validator = extend(
    Draft202012Validator,
    type_checker=Draft202012Validator.TYPE_CHECKER.redefine("number", lambda _, v: _is_number(v)),
)
"""Draft 2020-12 validation where a "number" is finite (:func:`_is_number`). Schemas are
checked by the tests, not on each use (``check_schema`` is too slow to repeat on every read)."""


def _check_schema(data: Any, validator: Draft202012Validator, path: Path) -> None:
    """Raise a :class:`CaptureFormatError` naming the most relevant schema violation.

    Of several violations the shallowest is reported (then the first in
    document order, as :func:`jsonschema.exceptions.relevance` ranks them).
    """
    error = max(validator.iter_errors(data), key=relevance, default=None)
    if error is not None:
        raise CaptureFormatError(path, _problem(error, data, validator.schema))


def _problem(error: ValidationError, data: Any, schema: dict[str, Any]) -> str:
    """One line: the JSON path of the problem, what the schema expects there and what it got.

    A missing key and a wrong constant have fixed wordings; otherwise the
    expectation is the ``description`` of the failing subschema, or of the
    innermost described subschema on the way to it (so a string inside K
    reports K's shape).
    """
    keys = list(error.absolute_path)
    kind, expected = error.validator, error.validator_value
    if kind == "required":
        missing = next(key for key in expected if key not in error.instance)
        return f"missing required key {_where([*keys, missing])}"
    if kind in ("const", "enum"):
        options = [expected] if kind == "const" else expected
        listed = ", ".join(map(_literal, options[:-1]))
        listed = f"{listed} or {_literal(options[-1])}" if listed else _literal(options[-1])
        return f"{_where(keys)} is {_literal(error.instance)}, expected {listed}"
    described = error.schema.get("description") if isinstance(error.schema, dict) else None
    if "propertyNames" in error.absolute_schema_path and described:
        return f"{_where(keys)} key {error.instance!r} must be {described}"
    if described is None:
        keys, described = _described(keys, schema)
    if described is None:
        return f"{_where(keys)}: {error.message}"
    value = data
    for key in keys:
        value = value[key]
    got = f"a list of {len(value)}: {_show(value)}" if isinstance(value, list) else _show(value)
    return f"{_where(keys)} must be {described}, got {got}"


def _described(keys: list[str | int], schema: dict[str, Any]) -> tuple[list, str | None]:
    """The innermost subschema with a ``description`` on the instance path ``keys``.

    Follows ``properties``, ``additionalProperties``, ``items`` and local
    ``$ref`` (not ``prefixItems``: their per-position rules describe
    themselves). Returns the path prefix it applies to and the description.
    """
    found: tuple[list, str | None] = ([], schema.get("description"))
    node: Any = schema
    for depth, key in enumerate(keys, 1):
        node = _member_schema(node, key, schema)
        if not isinstance(node, dict):
            break
        if "description" in node:
            found = (keys[:depth], node["description"])
    return found


def _member_schema(node: Any, key: str | int, schema: dict[str, Any]) -> Any:
    """The subschema that ``node`` applies to its member ``key`` (None if none)."""
    while isinstance(node, dict):
        if isinstance(key, int):
            child = node.get("items")
        else:
            child = node.get("properties", {}).get(key, node.get("additionalProperties"))
        if child is not None:
            return child
        ref = node.get("$ref", "")
        node = _pointer(schema, ref) if ref.startswith("#/") else None
    return None


def _pointer(schema: dict[str, Any], ref: str) -> Any:
    """The subschema a local ``$ref`` such as ``#/$defs/camera`` names."""
    for part in ref[2:].split("/"):
        schema = schema[part.replace("~1", "/").replace("~0", "~")]
    return schema


def _where(keys: list[str | int]) -> str:
    """A JSON path for messages: ``cameras[1].light.colour``; [] is the top level."""
    text = "".join(f"[{key}]" if isinstance(key, int) else f".{key}" for key in keys)
    return text.removeprefix(".") or "the top level"


def _literal(value: Any) -> str:
    """A value as a message quotes it: strings as Python literals, the rest as JSON."""
    return repr(value) if isinstance(value, str) else _show(value)
