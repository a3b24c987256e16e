"""Reading JSON files and checking their values, every problem a :class:`CaptureFormatError`.

The primitives of rig.json and scene.json validation: :func:`_read_json`
(UTF-8, duplicate keys refused), :func:`_field` (a required key), the type
checks ``_as_object``, ``_as_str``, ``_as_number``, ``_as_int``,
:func:`_float_array` (a nested list of finite numbers of a given shape) and
:func:`_frozen` (a read-only float64 copy). Messages name the file and the
offending key, with a short rendering of the value (:func:`_show`).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

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


def _field(obj: dict[str, Any], key: str, where: str, path: Path) -> Any:
    """``obj[key]``, or a "missing required key" error naming ``where.key``."""
    if key not in obj:
        full = f"{where}.{key}" if where else key
        raise CaptureFormatError(path, f"missing required key {full}")
    return obj[key]


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
    if isinstance(value, bool):
        return False
    if isinstance(value, int):
        return abs(value) < 2**1023
    return isinstance(value, float) and math.isfinite(value)


def _as_number(value: Any, where: str, path: Path) -> float:
    if not _is_number(value):
        raise CaptureFormatError(path, f"{where} must be a finite number, got {_show(value)}")
    return float(value)


def _as_int(value: Any, where: str, path: Path) -> int:
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int):
        raise CaptureFormatError(path, f"{where} must be an integer, got {_show(value)}")
    return value


def _all_numbers(value: Any) -> bool:
    if isinstance(value, list):
        return all(_all_numbers(v) for v in value)
    return _is_number(value)


def _float_array(value: Any, shape: tuple[int | None, ...], where: str, path: Path) -> np.ndarray:
    """A nested JSON list of finite numbers as a float64 array of ``shape`` (None: any length)."""
    dims = "x".join("n" if n is None else str(n) for n in shape)
    wanted = f"a list of {dims} numbers" if len(shape) == 1 else f"a {dims} array of numbers"
    problem = f"{where} must be {wanted}, got {_show(value)}"
    if not isinstance(value, list) or not _all_numbers(value):
        raise CaptureFormatError(path, problem)
    try:
        array = np.array(value, dtype=np.float64)
    except (ValueError, TypeError, OverflowError):
        raise CaptureFormatError(path, problem) from None
    if array.ndim != len(shape) or any(
        n is not None and n != m for n, m in zip(shape, array.shape, strict=True)
    ):
        raise CaptureFormatError(path, problem)
    return array


def _frozen(array: np.ndarray) -> np.ndarray:
    array = np.array(array, dtype=np.float64)
    array.flags.writeable = False
    return array
