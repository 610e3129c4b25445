"""The value types of the frame records: finite numbers, coefficients and directions.

A coefficient is a number or the name of a model parameter; a joint's connection may also be
written as a table ``{k = ...}``. The validators raise :class:`~analysis.settings.SettingError`
so that a problem is located at the field that holds it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Annotated, Any

from pydantic import PlainValidator

from ..settings import KeyPath, SettingError

__all__ = ["DIRECTIONS", "Coefficient", "Connection", "Direction", "Finite", "finite"]

DIRECTIONS = ("x", "y", "rz")


def finite(value: Any, path: KeyPath = ()) -> float:
    """``value`` as a float; a :class:`SettingError` at ``path`` unless a finite number."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise SettingError(path, f"expected a number, got {value!r}")
    if not math.isfinite(value):
        raise SettingError(path, f"expected a finite number, got {value!r}")
    return float(value)


def _coefficient(value: Any) -> float | str:
    return value if isinstance(value, str) else finite(value)


def _connection(value: Any) -> float | str:
    if isinstance(value, Mapping):  # the file's {k = ...}
        if unknown := sorted(set(value) - {"k"}):
            raise SettingError((unknown[0],), "unknown key; expected one of ['k']")
        if "k" not in value:
            raise SettingError(("k",), "missing")
        return _coefficient(value["k"])
    return _coefficient(value)


def _direction(value: Any) -> str:
    if value not in DIRECTIONS:
        raise SettingError((), f"bad direction {value!r}; expected one of {DIRECTIONS}")
    return str(value)


#: A finite number (TOML's ``nan`` and ``inf`` are refused).
Finite = Annotated[float, PlainValidator(finite)]
#: A number or the name of a model parameter.
Coefficient = Annotated[float | str, PlainValidator(_coefficient)]
#: A joint's connection in one direction: ``"rigid"``, ``"free"``, a stiffness or a parameter.
Connection = Annotated[float | str, PlainValidator(_connection)]
#: A frame direction.
Direction = Annotated[str, PlainValidator(_direction)]
